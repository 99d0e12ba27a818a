"""The paper's claims as numbers: what each model's representation shows, and a verdict on each.

Numbers come from the analysis (``metrics.json`` of each run) and from Table I; a verdict is True
(supported), False (not supported) or None (a number is missing or NaN). Thresholds are stated
in each claim's wording, so the report says exactly what was tested.
"""

from __future__ import annotations

import math

from sensorimotor.analysis.analyze import short_name
from sensorimotor.learn.evaluate import mean_sd
from sensorimotor.learn.models import KINDS, REC_S, REC_SM, SM, S
from sensorimotor.learn.runs import run_name


def _mean_sd(values: list[float]) -> tuple[float, float]:
    """Mean and sample sd of the numbers that are there (NaN, NaN if none is)."""
    values = [v for v in values if v is not None and not math.isnan(v)]
    return mean_sd(values) if values else (math.nan, math.nan)


def fmt_ms(values: list[float], digits: int = 2) -> str:
    mean, sd = _mean_sd(values)
    if math.isnan(mean):
        return "n/a"
    return f"{mean:.{digits}f}" + (
        f" ± {sd:.{digits}f}" if len([v for v in values if v is not None]) > 1 else ""
    )


def claim_numbers(analyses: dict[str, dict], runs: list[tuple[str, str, int]], worlds) -> dict:
    """Per training world and model (and raw): the lists over seeds of each claim number."""
    out: dict[str, dict[str, dict[str, list]]] = {}
    for world in worlds:
        out[world] = {}
        names = {"raw": [f"raw__{world}"]}
        for kind in KINDS:
            names[kind] = [run_name(w, m, s) for w, m, s in runs if w == world and m == kind]
        for kind, keys in names.items():
            vals: dict[str, list] = {
                k: []
                for k in (
                    "corner_f1",
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
    return _mean_sd(values)[0]


def _verdict(values: list[float], holds: bool) -> bool | None:
    """``holds``, unless a number it was computed from is missing or NaN."""
    if any(v is None or (isinstance(v, float) and math.isnan(v)) for v in values):
        return None
    return bool(holds)


CLEAR_GAP_SE = 2.0
"""A Table I mean is clearly below another when the gap exceeds this many standard errors."""


def _se_of_gap(a: dict, b: dict) -> float:
    """Standard error of the gap between two Table I cells' means, seeds independent (Welch);
    NaN unless both have two seeds or more."""
    if min(a["n"], b["n"]) < 2:
        return math.nan
    return math.sqrt(a["sd"] ** 2 / a["n"] + b["sd"] ** 2 / b["n"])


def _clearly_below(a: dict, b: dict) -> bool:
    """Cell ``a``'s mean is below ``b``'s by more than CLEAR_GAP_SE standard errors (by any
    amount with one seed, where no error can be estimated)."""
    se = _se_of_gap(a, b)
    gap = b["mean"] - a["mean"]
    return gap > 0 if math.isnan(se) else gap > CLEAR_GAP_SE * se


def _gap_in_se(a: dict, b: dict) -> str:
    se = _se_of_gap(a, b)
    return "one seed" if math.isnan(se) else f"gap {(b['mean'] - a['mean']) / se:.1f} SE"


def cluster_f1(metrics: dict, cluster: int, event: str) -> float:
    """F1 of one given cluster as a detector of ``event`` in an analysis' metrics."""
    ev = metrics["events"].get(event)
    if ev is None or not ev.get("count"):
        return math.nan
    c = next(c for c in metrics["clusters"] if c["id"] == cluster)
    precision = c["precision"][event]
    recall = precision * c["size"] / ev["count"]
    return 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)


def paper_claims(
    table: dict, transfers: dict[str, dict], numbers: dict
) -> list[tuple[str, str, bool | None]]:
    """Each of the paper's claims, the numbers that test it, and whether they support it:
    from Table I (``tables.table_from_results``), the transfer analyses by name and the claim
    numbers of each training world (``claim_numbers``)."""
    claims = []
    t = table
    for trained_on, orders in t["paper_ordering_holds"].items():
        known = {w: v for w, v in orders.items() if v is not None}
        wording = (
            "Table I ordering (trained on Square): Rec-SM < SM < both Rec-S and S, in every test world"
            if trained_on == "square"
            else f"The ordering is the same when trained on {trained_on} (paper: 'comparatively the same')"
        )
        claims.append(
            (
                wording,
                ", ".join(f"{w}: {'holds' if v else 'fails'}" for w, v in known.items()),
                all(known.values()) if known else None,
            )
        )
    rows = {r["model"]: r["cells"] for r in t["tables"].get("square", [])}
    if all(k in rows for k in KINDS):
        pairs = {w: (rows[REC_S][w], rows[S][w]) for w in t["worlds"]}
        claims.append(
            (
                "Memory lowers the error without motors too: Rec-S below S in every test world, by "
                f"more than {CLEAR_GAP_SE:g} standard errors of the difference over seeds (trained on Square)",
                ", ".join(
                    f"{w}: Rec-S {a['mean']:.5f} vs S {b['mean']:.5f} ({_gap_in_se(a, b)})"
                    for w, (a, b) in pairs.items()
                ),
                all(_clearly_below(a, b) for a, b in pairs.values()),
            )
        )
    if "square" in numbers:  # trained on Square (reproduce --worlds may leave it out)
        n = numbers["square"]
        corner = {k: _m(n[k]["corner_f1"]) for k in ("raw", S, SM, REC_S, REC_SM)}
        claims.append(
            (
                "Motors grow a corner cluster: the best cluster's corner F1 of SM and of Rec-SM exceeds "
                "that of S and of the raw readings by at least 0.1 (Square)",
                ", ".join(f"{short_name(k)} {v:.2f}" for k, v in corner.items()),
                _verdict(
                    list(corner.values()),
                    min(corner[SM], corner[REC_SM]) >= max(corner[S], corner["raw"]) + 0.1,
                ),
            )
        )
        claims.append(
            (
                "No corner cluster without motors: Rec-S's corner F1 stays at least 0.1 below SM's and "
                "Rec-SM's (Square)",
                f"Rec-S {corner[REC_S]:.2f}, SM {corner[SM]:.2f}, Rec-SM {corner[REC_SM]:.2f}",
                _verdict(
                    list(corner.values()),
                    corner[REC_S] + 0.1 <= min(corner[SM], corner[REC_SM]),
                ),
            )
        )
        mem = {
            k: (_m(n[k]["nothing_clusters"]), _m(n[k]["behind_r2"]))
            for k in (S, SM, REC_S, REC_SM)
        }
        flat = [v for pair in mem.values() for v in pair]
        claims.append(
            (
                "Memory: Rec-SM splits the 'nothing in view' states (more than one such cluster; distance to "
                "the wall behind decodable, R² at least 0.1 above S's) where S cannot (Square)",
                ", ".join(f"{short_name(k)}: {c:.1f} clusters, R² {r:.2f}" for k, (c, r) in mem.items()),
                _verdict(flat, mem[REC_SM][0] > 1 and mem[REC_SM][1] >= mem[S][1] + 0.1),
            )
        )
        claims.append(
            (
                "Motors sharpen memory: Rec-SM tells 'nothing in view' states apart better than Rec-S "
                "(distance-behind R² higher, Square)",
                f"Rec-SM {mem[REC_SM][1]:.2f}, Rec-S {mem[REC_S][1]:.2f}",
                _verdict(flat, mem[REC_SM][1] > mem[REC_S][1]),
            )
        )
        pos = {k: max(_m(n[k]["r2_x"]), _m(n[k]["r2_y"])) for k in (S, SM, REC_S, REC_SM)}
        claims.append(
            (
                "No global notion of position: linear probes recover neither x nor y from any model (R² < 0.1, Square)",
                ", ".join(f"{short_name(k)} {v:.2f}" for k, v in pos.items()),
                _verdict(list(pos.values()), max(pos.values()) < 0.1),
            )
        )
    if "rooms1" in numbers and "rooms2" in numbers:
        e1 = _m(numbers["rooms1"][REC_SM]["wall_end_f1"])
        e2 = _m(numbers["rooms2"][REC_SM]["wall_end_f1"])
        raw1 = _m(numbers["rooms1"]["raw"]["wall_end_f1"])
        claims.append(
            (
                "A wall-end cluster grows when Rec-SM is trained on Rooms1 (F1 at least 0.1 above the raw "
                "readings') but not on Rooms2 (F1 lower than on Rooms1)",
                f"Rooms1 {e1:.2f} (raw {raw1:.2f}), Rooms2 {e2:.2f}",
                _verdict([e1, e2, raw1], e1 >= raw1 + 0.1 and e2 < e1),
            )
        )
    for source, event, targets in (
        ("square", "corner", ("rooms1", "rooms2")),
        ("rooms1", "wall_end", ("rooms2",)),
    ):
        key = run_name(source, REC_SM, 0)
        found = [f"{key}__to__{w}" in transfers for w in targets]
        if not all(found):
            continue
        fit = transfers[f"{key}__to__{targets[0]}"]["fit_analysis"]
        cluster = fit["events"][event]["cluster"]
        fit_f1 = fit["events"][event]["f1"]
        raw_f1 = _m(numbers.get(source, {}).get("raw", {}).get(f"{event}_f1", [math.nan]))
        to = {
            w: cluster_f1(transfers[f"{key}__to__{w}"]["analysis"], cluster, event)
            for w in targets
        }
        label = event.replace("_", " ")
        grew = fit_f1 >= raw_f1 + 0.1  # the test of a cluster growing, as in the claims above
        claims.append(
            (
                f"Transfer: {source}'s {label} cluster (#{cluster}), applied unchanged, still finds "
                f"{label}s in {' and '.join(targets)} (its F1 there at least half of that on {source}; "
                f"no verdict unless it grew there, F1 at least 0.1 above the raw readings')",
                f"{source} {fit_f1:.2f} (raw {raw_f1:.2f}), "
                + ", ".join(f"{w} {v:.2f}" for w, v in to.items()),
                _verdict([fit_f1, raw_f1, *to.values()], min(to.values()) >= 0.5 * fit_f1)
                if grew
                else None,
            )
        )
    return claims


__all__ = ["claim_numbers", "cluster_f1", "fmt_ms", "paper_claims", "run_name"]
