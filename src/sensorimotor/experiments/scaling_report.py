"""The scaling experiment's verdicts and report section (``experiments.scaling`` runs it).

Each paper finding gets a verdict per condition, with the threshold ``analysis.claims`` states
for it on Square: the ordering of the test errors (``tables.paper_ordering_holds``: Rec-SM <
SM < both Rec-S and S), the corner cluster (the best cluster's corner F1 of SM and of Rec-SM at
least 0.1 above S's and the raw readings') and the memory (Rec-SM has more than one 'nothing in
view' cluster and decodes the distance to the wall behind with an R² at least 0.1 above S's).
"""

from __future__ import annotations

from pathlib import Path

from sensorimotor.analysis.analyze import short_name, with_raw
from sensorimotor.analysis.probes import PROBE_FIT_MAX
from sensorimotor.analysis.tables import paper_ordering_holds
from sensorimotor.learn.models import REC_SM, SM, S, paper_kinds
from sensorimotor.learn.runs import count
from sensorimotor.report.blocks import Block, h, image, p, table
from sensorimotor.stats import BEFORE, Verdict, is_missing, word

GAP = 0.1  # the corner and memory thresholds of analysis.claims
WHERE = (
    "analysis/claims.py's thresholds for Square (commits d9848fc and 2f8a662, before the first "
    "published reproduction), taken over in 833b62f before docs/results/scaling"
)
TEST = "means over seeds and test databases compared; no test of significance"


def finite(v) -> float | None:
    """``v`` as a float, or None where it is missing or NaN (strict JSON has no NaN)."""
    return None if is_missing(v) else float(v)


def verdicts(errors: dict[str, float], claims: dict[str, dict]) -> list[Verdict]:
    """A verdict on each paper finding (its ``claim``: "ordering", "corner cluster",
    "memory"), with its threshold (``analysis.claims``' own): the ordering of the test errors,
    the corner cluster and the memory. Not judged (None) where a number is missing (no corner in
    the test worlds, a model not trained)."""

    def verdict(finding: str, threshold: str, numbers: str, holds: bool | None) -> Verdict:
        return Verdict(finding, threshold, TEST, numbers, holds, BEFORE, WHERE)

    have = {k: v for k, v in errors.items() if finite(v) is not None}
    out = [
        verdict(
            "ordering",
            "test error Rec-SM < SM < both Rec-S and S",
            ", ".join(f"{k} {v:.5f}" for k, v in have.items()),
            paper_ordering_holds(have),
        )
    ]
    corner = {k: finite(claims.get(k, {}).get("corner_f1")) for k in with_raw()}
    ok = None
    if None not in corner.values():
        ok = min(corner[SM], corner[REC_SM]) >= max(corner[S], corner["raw"]) + GAP
    out.append(
        verdict(
            "corner cluster",
            f"corner F1 of SM and of Rec-SM at least {GAP:g} above S's and the raw readings'",
            ", ".join(f"{k} {'n/a' if v is None else f'{v:.2f}'}" for k, v in corner.items()),
            ok,
        )
    )
    mem = {
        k: (
            finite(claims.get(k, {}).get("nothing_clusters")),
            finite(claims.get(k, {}).get("behind_r2")),
        )
        for k in paper_kinds()
    }
    ok = None
    if None not in (mem[REC_SM][0], mem[REC_SM][1], mem[S][1]):
        ok = mem[REC_SM][0] > 1 and mem[REC_SM][1] >= mem[S][1] + GAP
    out.append(
        verdict(
            "memory",
            "Rec-SM has more than one 'nothing in view' cluster and its distance-"
            f"behind R² is at least {GAP:g} above S's",
            ", ".join(
                f"{k} {'n/a' if c is None else f'{c:.1f}'} clusters, R² {'n/a' if r is None else f'{r:.2f}'}"
                for k, (c, r) in mem.items()
            ),
            ok,
        )
    )
    return out


def _word(holds: bool | None) -> str:
    return word(holds, "holds", "fails")


def plot_errors(conds: dict, path: Path) -> Path:
    """A bar chart of each model's test error as a share of the previous-reading baseline's,
    per condition (log scale: the models differ by factors); written atomically to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from sensorimotor.sim.plots import save_figure

    fig = Figure(figsize=(7.5, 3.2), layout="constrained")
    ax = fig.add_subplot()
    width = 0.8 / len(paper_kinds())
    for k, kind in enumerate(paper_kinds()):
        ratios = [c["errors"][kind]["mean"] / c["copy_last"] for c in conds.values()]
        xs = [i + (k - (len(paper_kinds()) - 1) / 2) * width for i in range(len(conds))]
        ax.bar(xs, ratios, width, label=short_name(kind))
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_yscale("log")
    ax.set_xticks(range(len(conds)), list(conds))
    ax.set_ylabel("test error / previous reading's")
    ax.set_ylim(top=3.0)  # room for the legend above the baseline
    ax.legend(ncols=4, fontsize=8, loc="upper center")
    save_figure(fig, path)
    return path


def _caps(caps: dict) -> str:
    caps = {k: v for k, v in caps.items() if v is not None}
    return ", ".join(f"{short_name(k)} {v}" for k, v in caps.items()) or "none"


def _f(v, digits: int = 2) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def _error_cell(e: dict) -> str:
    return f"{e['mean']:.5f}" + (f" ± {e['sd']:.5f}" if e["n"] > 1 else "")


def condition_table(c: dict) -> Block:
    """One condition's table: each model's test error (per ray, and as a share of the
    previous-reading baseline's), its corner F1 and its memory numbers."""
    rays = c["condition"]["rays"]
    seen = c.get("errors_on_training_plans")
    header = ["Model", "test error", "per ray", "/ previous reading"]
    header += ["on its training plans"] if seen else []
    header += ["corner F1", "corner AUC (linear probe)", "'nothing' clusters", "distance-behind R²"]
    rows = []
    for kind in with_raw():
        claims = c["claims"][kind]
        if kind == "raw":
            cells = [
                f"{c['copy_last']:.5f} (previous reading)",
                f"{c['copy_last'] / rays:.5f}",
                "1",
            ]
            cells += [""] if seen else []
        else:
            e = c["errors"][kind]
            cells = [_error_cell(e), f"{e['mean'] / rays:.5f}", f"{e['mean'] / c['copy_last']:.2f}"]
            cells += [f"{seen[kind]:.5f}"] if seen else []
        cells += [
            _f(claims["corner_f1"]),
            _f(claims.get("corner_auc")),
            _f(claims["nothing_clusters"], 1),
            _f(claims["behind_r2"]),
        ]
        rows.append([short_name(kind), *cells])
    return table(header, rows)


def section(rep, found: dict) -> list[Block]:
    """The report's section: how the experiment was run, a table per condition, a verdict per
    finding and condition, and where the findings do not hold."""
    size = found["size"]
    conds = found["conditions"]
    blocks = [
        h(2, "Does it scale? More rays, noise, unseen floor plans"),
        p(
            f"S, SM, Rec-S and Rec-SM trained in each condition below ({size['steps']:,}-step "
            f"databases, {count(size['seeds'], 'seed')}, patience "
            f"{size['patience']}, epoch caps {_caps(size['max_epochs'])}; the plans condition "
            "trains on "
            "the train splits of 10 generated plans together and is tested on 10 others). "
            "Errors are Table I's (squared error summed over the rays, readings scaled to "
            "[0, 1]) on the test splits, averaged over the test databases; 'per ray' divides by "
            "the rays, '/ previous reading' by the error of predicting the last reading again. "
            "Corner F1 (the best of k = 20 k-means clusters) and the memory numbers are "
            "`analysis.claims`', on the test splits, averaged over seeds and test databases. "
            "Corner AUC: a linear probe for 'a corner in view' beside the cluster F1, which "
            "cannot credit a representation that encodes the corner among more than 20 "
            "clusters' worth of other things: a class-balanced logistic regression on the "
            "standardised representation, fitted on each test database's training split (its "
            f"first {PROBE_FIT_MAX:,} steps), its ROC AUC on the test split (0.5: chance, 1: linearly "
            "separable); n/a where a split has no corner. `docs/DESIGN.md` gives the choices."
        ),
    ]
    for name, c in conds.items():
        blocks += [h(3, f"{name}: {c['label']}"), condition_table(c)]
        picture = Path(rep.out) / "scaling" / "analysis"
        picture = (
            picture / f"{name}__rec-sm__s0__on__{Path(c['test_worlds'][0]).name}" / "clusters.png"
        )
        if name == "plans" and picture.exists():
            blocks.append(
                image(picture, f"Rec-SM's clusters on the unseen plan {c['test_worlds'][0]}")
            )
    chart = Path(rep.out) / "scaling" / "errors.png"
    if chart.exists():
        blocks.append(
            image(chart, "Test error as a share of the previous-reading baseline's (dashed: 1)")
        )
    findings = [v["claim"] for v in next(iter(conds.values()))["verdicts"]]
    rows = []
    for f in findings:
        row = [f]
        for c in conds.values():
            v = next(v for v in c["verdicts"] if v["claim"] == f)
            row.append(f"{_word(v['holds'])} ({v['numbers']})")
        rows.append(row)
    blocks.append(h(3, "Verdicts"))
    first = next(iter(conds.values()))["verdicts"]
    thresholds = "; ".join(f"**{v['claim']}**: {v['threshold']}" for v in first)
    blocks.append(
        p(
            f"Each finding holds when its threshold is met: {thresholds}. The thresholds are "
            "`analysis.claims`' for Square; they compare means over seeds (and test databases), "
            "with no test of significance: the ± columns give the spread over seeds. "
            f"Thresholds {first[0]['provenance']}: {first[0]['where']}."
        )
    )
    blocks.append(table(["Finding", *conds], rows))
    failed = [
        f"{v['claim']} in {name}"
        for name, c in conds.items()
        for v in c["verdicts"]
        if v["holds"] is False
    ]
    missing = [
        f"{v['claim']} in {name}"
        for name, c in conds.items()
        for v in c["verdicts"]
        if v["holds"] is None
    ]
    blocks.append(
        p(
            (
                "Does not hold: " + "; ".join(failed) + "."
                if failed
                else "Every finding holds in every condition."
            )
            + (" No verdict (a number missing): " + "; ".join(missing) + "." if missing else "")
        )
    )
    return blocks
