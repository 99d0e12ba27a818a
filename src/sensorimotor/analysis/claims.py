"""The paper's claims as numbers: what each model's representation shows, and a verdict on each.

Numbers come from the analysis (``metrics.json`` of each run) and from Table I; ``paper_claims``
takes those numbers (not the reproduction) and gives one ``stats.Verdict`` per claim: supported
(True), not supported (False) or not judged (None: a number is missing or NaN). Thresholds are
stated in each claim's wording, so the report says exactly what was tested, and each verdict
says where its threshold was set and whether before the data or on them.
"""

from __future__ import annotations

import math

from sensorimotor.analysis.analyze import short_name
from sensorimotor.learn.models import KINDS, REC_S, REC_SM, SM, S
from sensorimotor.learn.runs import run_name
from sensorimotor.stats import (
    BEFORE,
    CHOSEN,
    Verdict,
    mean_sd,
    present,
    se_of_difference,
    unless_missing,
)

# where the thresholds were set (the commits are this repository's)
SET_BEFORE = (
    "analysis/claims.py, commits d9848fc and 2f8a662, before the first published "
    "reproduction (beedac8)"
)
ORDERING_WHERE = "the paper's Table I (analysis/tables.py, paper_ordering_holds, d9848fc)"
GAP_WHERE = (
    "analysis/claims.py, CLEAR_GAP_SE, commit 92c0a27, after the first published "
    "reproduction (beedac8)"
)
TRANSFER_WHERE = (
    "analysis/claims.py: 'at least half' since d9848fc, before the first published "
    "reproduction (beedac8); the 'grew' gate since 92c0a27, after it"
)
MEANS = "means over seeds compared; no test of significance"


def fmt_ms(values: list[float], digits: int = 2) -> str:
    """Mean ± sd of the numbers that are there (``stats.present``), "n/a" if none is."""
    there = present(values)
    if not there:
        return "n/a"
    mean, sd = mean_sd(there)
    return f"{mean:.{digits}f}" + (
        f" ± {sd:.{digits}f}" if len([v for v in values if v is not None]) > 1 else ""
    )


def claim_numbers(analyses: dict[str, dict], runs: list[tuple[str, str, int]], worlds) -> dict:
    """Per training world and model (and raw): the lists over seeds of each claim number."""
    out: dict[str, dict[str, dict[str, list]]] = {}
    for world in worlds:
        out[world] = {}
        names = {"raw": [f"raw__{world}"]}
        present = {m for _, m, _ in runs}
        for kind in (k for k in KINDS if k in present or KINDS[k].paper):
            names[kind] = [run_name(w, m, s) for w, m, s in runs if w == world and m == kind]
        for kind, keys in names.items():
            vals: dict[str, list] = {
                k: []
                for k in (
                    "corner_f1",
                    "corner_auc",
                    "wall_end_f1",
                    "nothing_clusters",
                    "behind_r2",
                    "r2_x",
                    "r2_y",
                    "r2_cos",
                    "knn_mse",
                    "knn_chance",
                )
            }
            for key in keys:
                a = analyses[key]["analysis"]
                ev = a["events"]
                vals["corner_f1"].append(ev.get("corner", {}).get("f1"))
                vals["corner_auc"].append(ev.get("corner", {}).get("probe_auc"))
                vals["wall_end_f1"].append(ev.get("wall_end", {}).get("f1"))
                vals["nothing_clusters"].append(a["memory"]["nothing_clusters"])
                vals["behind_r2"].append(a["memory"]["distance_behind_r2"])
                pos = a["position"]
                vals["r2_x"].append(pos["r2_x"])
                vals["r2_y"].append(pos["r2_y"])
                vals["r2_cos"].append(pos["r2_cos_heading"])
                vals["knn_mse"].append(pos["knn_mse"])
                vals["knn_chance"].append(pos["knn_mse_chance"])
            out[world][kind] = vals
    return out


def _m(values: list) -> float:
    """The mean of the numbers that are there (``stats.present``); NaN if none is."""
    there = present(values)
    return mean_sd(there)[0] if there else math.nan


CLEAR_GAP_SE = 2.0
"""A Table I mean is clearly below another when the gap exceeds this many standard errors."""


def _se_of_gap(a: dict, b: dict) -> float | None:
    """Standard error of the gap between two Table I cells' means, seeds independent (Welch,
    ``stats.se_of_difference``); None unless both have two seeds or more."""
    return se_of_difference(a["sd"], a["n"], b["sd"], b["n"])


def _clearly_below(a: dict, b: dict) -> bool:
    """Cell ``a``'s mean is below ``b``'s by more than CLEAR_GAP_SE standard errors (by any
    amount with one seed, where no error can be estimated)."""
    se = _se_of_gap(a, b)
    gap = b["mean"] - a["mean"]
    return gap > 0 if se is None else gap > CLEAR_GAP_SE * se


def _gap_in_se(a: dict, b: dict) -> str:
    se = _se_of_gap(a, b)
    return "one seed" if se is None else f"gap {(b['mean'] - a['mean']) / se:.1f} SE"


def cluster_f1(metrics: dict, cluster: int, event: str) -> float:
    """F1 of one given cluster as a detector of ``event`` in an analysis' metrics."""
    ev = metrics["events"].get(event)
    if ev is None or not ev.get("count"):
        return math.nan
    c = next(c for c in metrics["clusters"] if c["id"] == cluster)
    precision = c["precision"][event]
    recall = precision * c["size"] / ev["count"]
    return 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)


def _table_claims(t: dict) -> list[Verdict]:
    """The claims on Table I: the ordering per training world, Rec-S below S."""
    claims = []
    for trained_on, orders in t["paper_ordering_holds"].items():
        known = {w: v for w, v in orders.items() if v is not None}
        wording = (
            "Table I ordering (trained on Square): Rec-SM < SM < both Rec-S and S, in every test world"
            if trained_on == "square"
            else f"The ordering is the same when trained on {trained_on} (paper: 'comparatively the same')"
        )
        claims.append(
            Verdict(
                claim=wording,
                threshold="test error Rec-SM < SM < both Rec-S and S, in every test world",
                test="Table I means over seeds compared per test world; no test of significance",
                numbers=", ".join(f"{w}: {'holds' if v else 'fails'}" for w, v in known.items()),
                holds=all(known.values()) if known else None,
                provenance=BEFORE,
                where=ORDERING_WHERE,
            )
        )
    rows = {r["model"]: r["cells"] for r in t["tables"].get("square", [])}
    if all(k in rows for k in (S, REC_S)):
        pairs = {w: (rows[REC_S][w], rows[S][w]) for w in t["worlds"]}
        claims.append(
            Verdict(
                claim="Memory lowers the error without motors too: Rec-S below S in every test "
                f"world, by more than {CLEAR_GAP_SE:g} standard errors of the difference over "
                "seeds (trained on Square)",
                threshold=f"S's mean test error minus Rec-S's above {CLEAR_GAP_SE:g} standard "
                "errors, in every test world (above 0 with one seed)",
                test="Welch standard error of the gap between two Table I means over "
                "independent seeds",
                numbers=", ".join(
                    f"{w}: Rec-S {a['mean']:.5f} vs S {b['mean']:.5f} ({_gap_in_se(a, b)})"
                    for w, (a, b) in pairs.items()
                ),
                holds=all(_clearly_below(a, b) for a, b in pairs.values()),
                provenance=CHOSEN,
                where=GAP_WHERE,
            )
        )
    return claims


def _square_claims(n: dict) -> list[Verdict]:
    """The claims on the analyses of the models trained on Square."""
    claims = []

    def claim(wording: str, threshold: str, numbers: str, holds: bool | None) -> None:
        claims.append(Verdict(wording, threshold, MEANS, numbers, holds, BEFORE, SET_BEFORE))

    corner = {k: _m(n[k]["corner_f1"]) for k in ("raw", S, SM, REC_S, REC_SM)}
    claim(
        "Motors grow a corner cluster: the best cluster's corner F1 of SM and of Rec-SM exceeds "
        "that of S and of the raw readings by at least 0.1 (Square)",
        "min(SM, Rec-SM) >= max(S, raw) + 0.1 (corner F1)",
        ", ".join(f"{short_name(k)} {v:.2f}" for k, v in corner.items()),
        unless_missing(
            corner.values(),
            min(corner[SM], corner[REC_SM]) >= max(corner[S], corner["raw"]) + 0.1,
        ),
    )
    claim(
        "No corner cluster without motors: Rec-S's corner F1 stays at least 0.1 below SM's and "
        "Rec-SM's (Square)",
        "Rec-S + 0.1 <= min(SM, Rec-SM) (corner F1)",
        f"Rec-S {corner[REC_S]:.2f}, SM {corner[SM]:.2f}, Rec-SM {corner[REC_SM]:.2f}",
        unless_missing(corner.values(), corner[REC_S] + 0.1 <= min(corner[SM], corner[REC_SM])),
    )
    mem = {k: (_m(n[k]["nothing_clusters"]), _m(n[k]["behind_r2"])) for k in (S, SM, REC_S, REC_SM)}
    flat = [v for pair in mem.values() for v in pair]
    claim(
        "Memory: Rec-SM splits the 'nothing in view' states (more than one such cluster; distance to "
        "the wall behind decodable, R² at least 0.1 above S's) where S cannot (Square)",
        "Rec-SM: more than one 'nothing in view' cluster and distance-behind R² >= S's + 0.1",
        ", ".join(f"{short_name(k)}: {c:.1f} clusters, R² {r:.2f}" for k, (c, r) in mem.items()),
        unless_missing(flat, mem[REC_SM][0] > 1 and mem[REC_SM][1] >= mem[S][1] + 0.1),
    )
    claim(
        "Motors sharpen memory: Rec-SM tells 'nothing in view' states apart better than Rec-S "
        "(distance-behind R² higher, Square)",
        "distance-behind R² of Rec-SM > Rec-S's",
        f"Rec-SM {mem[REC_SM][1]:.2f}, Rec-S {mem[REC_S][1]:.2f}",
        unless_missing(flat, mem[REC_SM][1] > mem[REC_S][1]),
    )
    pos = {k: max(_m(n[k]["r2_x"]), _m(n[k]["r2_y"])) for k in (S, SM, REC_S, REC_SM)}
    claim(
        "No global notion of position: linear probes recover neither x nor y from any model (R² < 0.1, Square)",
        "R² of x and of y < 0.1 for every model",
        ", ".join(f"{short_name(k)} {v:.2f}" for k, v in pos.items()),
        unless_missing(pos.values(), max(pos.values()) < 0.1),
    )
    return claims


def _transfer_claims(transfers: dict[str, dict], numbers: dict) -> list[Verdict]:
    """A grown cluster applied unchanged in the other worlds."""
    claims = []
    for source, event, targets in (
        ("square", "corner", ("rooms1", "rooms2")),
        ("rooms1", "wall_end", ("rooms2",)),
    ):
        key = run_name(source, REC_SM, 0)
        if not all(f"{key}__to__{w}" in transfers for w in targets):
            continue
        fit = transfers[f"{key}__to__{targets[0]}"]["fit_analysis"]
        cluster = fit["events"][event]["cluster"]
        fit_f1 = fit["events"][event]["f1"]
        raw_f1 = _m(numbers.get(source, {}).get("raw", {}).get(f"{event}_f1", [math.nan]))
        to = {
            w: cluster_f1(transfers[f"{key}__to__{w}"]["analysis"], cluster, event) for w in targets
        }
        label = event.replace("_", " ")
        grew = fit_f1 >= raw_f1 + 0.1  # the test of a cluster growing, as in the claims above
        claims.append(
            Verdict(
                claim=f"Transfer: {source}'s {label} cluster (#{cluster}), applied unchanged, "
                f"still finds {label}s in {' and '.join(targets)} (its F1 there at least half of "
                f"that on {source}; no verdict unless it grew there, F1 at least 0.1 above the "
                "raw readings')",
                threshold=f"F1 in each of {', '.join(targets)} >= 0.5 x F1 on {source}; judged "
                f"only where the F1 on {source} >= raw's + 0.1",
                test="the cluster of Rec-SM seed 0 fitted on the training world, its F1 in the "
                "others; no test of significance",
                numbers=f"{source} {fit_f1:.2f} (raw {raw_f1:.2f}), "
                + ", ".join(f"{w} {v:.2f}" for w, v in to.items()),
                holds=unless_missing(
                    [fit_f1, raw_f1, *to.values()], min(to.values()) >= 0.5 * fit_f1
                )
                if grew
                else None,
                provenance=CHOSEN,
                where=TRANSFER_WHERE,
            )
        )
    return claims


def paper_claims(table: dict, transfers: dict[str, dict], numbers: dict) -> list[Verdict]:
    """A verdict on each of the paper's claims, from numbers only: Table I
    (``tables.table_from_results``), the transfer analyses by name and the claim numbers of each
    training world (``claim_numbers``)."""
    claims = _table_claims(table)
    if "square" in numbers:  # trained on Square (reproduce --worlds may leave it out)
        claims += _square_claims(numbers["square"])
    if "rooms1" in numbers and "rooms2" in numbers:
        e1 = _m(numbers["rooms1"][REC_SM]["wall_end_f1"])
        e2 = _m(numbers["rooms2"][REC_SM]["wall_end_f1"])
        raw1 = _m(numbers["rooms1"]["raw"]["wall_end_f1"])
        claims.append(
            Verdict(
                claim="A wall-end cluster grows when Rec-SM is trained on Rooms1 (F1 at least 0.1 "
                "above the raw readings') but not on Rooms2 (F1 lower than on Rooms1)",
                threshold="wall-end F1 of Rec-SM on Rooms1 >= raw's + 0.1, and on Rooms2 below "
                "that on Rooms1",
                test=MEANS,
                numbers=f"Rooms1 {e1:.2f} (raw {raw1:.2f}), Rooms2 {e2:.2f}",
                holds=unless_missing([e1, e2, raw1], e1 >= raw1 + 0.1 and e2 < e1),
                provenance=BEFORE,
                where=SET_BEFORE,
            )
        )
    return claims + _transfer_claims(transfers, numbers)


__all__ = ["claim_numbers", "cluster_f1", "fmt_ms", "paper_claims", "run_name"]
