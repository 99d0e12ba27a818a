"""The report's numbers: a cluster's F1 from metrics, agreement with the paper, verdicts, and
the two renderings saying the same thing."""

from __future__ import annotations

import math

import pytest

from sensorimotor.analysis import analyze_representation
from sensorimotor.analysis.claims import _verdict, cluster_f1, paper_claims
from sensorimotor.analysis.clusters import cluster_event_table
from sensorimotor.report.document import h, image, p, paper_agreement, table, to_html, to_markdown
from sensorimotor.sim.database import generate
from sensorimotor.sim.world import load_world


@pytest.fixture(scope="module")
def analysed():
    db = generate(load_world("rooms1"), 6000, seed=2)
    z = db.sensors / 10.0
    return analyze_representation(z, db.sensors, db.poses, db.world, seed=0)


def test_cluster_f1_from_metrics_equals_the_table_of_labels(analysed):
    m = analysed.metrics
    for event in ("corner", "wall_end", "nothing"):
        truth = cluster_event_table(analysed.labels, analysed.events[event], m["k"])
        for c in range(m["k"]):
            assert cluster_f1(m, c, event) == pytest.approx(truth["f1"][c], abs=1e-9)
        best = m["events"][event]["cluster"]
        assert cluster_f1(m, best, event) == pytest.approx(m["events"][event]["f1"])


def test_cluster_f1_of_an_absent_event_is_nan(analysed):
    m = dict(analysed.metrics, events={"corner": {"count": 0}})
    assert math.isnan(cluster_f1(m, 0, "corner"))
    assert math.isnan(cluster_f1(m, 0, "wall_end"))


def test_verdict_is_none_when_a_number_is_missing():
    assert _verdict([0.5, 0.2], 0.5 > 0.2) is True
    assert _verdict([0.1, 0.2], 0.1 > 0.2) is False
    assert _verdict([math.nan, 0.2], False) is None
    assert _verdict([None, 0.2], False) is None


def fake_report(
    rec_s_rooms1: tuple[float, float] = (0.057, 0.0002),
    fit_f1: float = 0.29,
    to_f1: float = 0.33,
    square: dict[str, dict[str, float]] | None = None,
):
    """A report of 5 seeds a cell, Rec-S on Rooms1 at (mean, sd), and a Rooms1 wall-end cluster
    of F1 ``fit_f1`` transferred to Rooms2 at F1 ``to_f1`` (precision = recall = F1). Every
    analysis number is 0.5 but those ``square`` gives: {model: {number: value}}."""
    means = {"s": 0.058, "sm": 0.013, "rec-s": 0.057, "rec-sm": 0.009}
    cells = {
        m: {w: {"mean": v, "sd": 0.0002, "n": 5} for w in ("square", "rooms1")}
        for m, v in means.items()
    }
    cells["rec-s"]["rooms1"] = {"mean": rec_s_rooms1[0], "sd": rec_s_rooms1[1], "n": 5}
    table = {
        "worlds": ["square", "rooms1"],
        "tables": {"square": [{"model": m, "cells": c} for m, c in cells.items()]},
        "paper_ordering_holds": {"square": {"square": True, "rooms1": True}},
    }

    def wall_end_metrics(f1):
        return {
            "events": {"wall_end": {"cluster": 3, "f1": f1, "count": 100}},
            "clusters": [{"id": 3, "size": 100, "precision": {"wall_end": f1}}],
        }

    transfers = {
        "rooms1__rec-sm__s0__to__rooms2": {
            "fit_analysis": wall_end_metrics(fit_f1),
            "analysis": wall_end_metrics(to_f1),
        }
    }
    names = ("corner_f1", "wall_end_f1", "nothing_clusters", "behind_r2", "r2_x", "r2_y")
    per_seed = {name: [0.5] for name in names}
    numbers = {w: {m: per_seed for m in ("raw", *means)} for w in ("square", "rooms1")}
    numbers["rooms1"]["raw"] = {**per_seed, "wall_end_f1": [0.10]}
    for model, values in (square or {}).items():
        numbers["square"][model] = {**per_seed, **{k: [v] for k, v in values.items()}}
    claims = paper_claims(table, transfers, numbers)
    return {text.split(":")[0]: (evidence, verdict) for text, evidence, verdict in claims}


def test_memory_without_motors_needs_a_gap_beyond_the_seeds_spread():
    # the published Rooms1 cells: Rec-S 0.05794 +- 0.00084 against S 0.058 +- 0.0002
    evidence, verdict = fake_report((0.05794, 0.00084), 0.29, 0.33)[
        "Memory lowers the error without motors too"
    ]
    assert verdict is False
    assert "rooms1: Rec-S 0.05794 vs S 0.05800 (gap 0.2 SE)" in evidence
    evidence, verdict = fake_report((0.0574, 0.0002), 0.29, 0.33)[
        "Memory lowers the error without motors too"
    ]
    assert verdict is True
    assert "gap 4.7 SE" in evidence


def test_a_transfer_is_judged_only_where_the_cluster_grew():
    assert fake_report((0.057, 0.0002), 0.29, 0.33)["Transfer"] == (
        "rooms1 0.29 (raw 0.10), rooms2 0.33",
        True,
    )
    assert fake_report((0.057, 0.0002), 0.29, 0.10)["Transfer"][1] is False  # below half
    assert fake_report((0.057, 0.0002), 0.15, 0.33)["Transfer"][1] is None  # never grew


def test_paper_agreement_counts_cells_within_a_quarter():
    rows = [
        {
            "model": "s",
            "name": "S-encoder",
            "cells": {"square": {"mean": 0.03735 * 1.2}, "rooms1": {"mean": 0.04299 * 1.3}},
        },
        {"model": "sm", "name": "SM-encoder", "cells": {"square": {"mean": 0.005576 * 0.8}}},
    ]
    text = paper_agreement(rows, ["square", "rooms1"])
    assert text.startswith("Cells within 25% of the paper: 2 of 3")
    assert "S-encoder on rooms1 (+30%)" in text


def test_paper_agreement_counts_a_cell_far_below_the_paper_as_outside():
    rows = [{"model": "s", "name": "S-encoder", "cells": {"square": {"mean": 0.03735 * 0.7}}}]
    text = paper_agreement(rows, ["square"])
    assert text == "Cells within 25% of the paper: 0 of 1; outside: S-encoder on square (-30%)."


def test_markdown_and_html_carry_the_same_blocks(tmp_path):
    png = tmp_path / "a.png"
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1))
    fig.add_subplot().plot([0, 1])
    fig.savefig(png)
    blocks = [
        h(1, "Title"),
        p("a **bold** `code` <b>"),
        table(["x", "y"], [["1", "2"]]),
        image(png, "a figure"),
    ]
    md = to_markdown(blocks, tmp_path)
    html = to_html(blocks, "t")
    assert "# Title" in md
    assert "| x | y |" in md
    assert "![a figure](a.png)" in md
    assert "<b>bold</b>" in html
    assert "<code>code</code>" in html
    assert "&lt;b&gt;" in html  # text is escaped
    assert html.count("data:image/png;base64,") == 1
    assert html.count("<td>") == 2
    assert html.count("<th>") == 2


def verdict(claim: str, **square) -> bool | None:
    return fake_report(square=square)[claim][1]


def test_the_corner_claim_needs_both_motor_models_above_s_and_raw():
    claim = "Motors grow a corner cluster"
    f1 = {m: {"corner_f1": 0.2} for m in ("raw", "s", "rec-s")}
    assert verdict(claim, **f1, sm=dict(corner_f1=0.6), **{"rec-sm": dict(corner_f1=0.6)})
    assert not verdict(claim, **f1, sm=dict(corner_f1=0.25), **{"rec-sm": dict(corner_f1=0.6)})
    assert not verdict(claim, **f1, sm=dict(corner_f1=0.6), **{"rec-sm": dict(corner_f1=0.25)})
    no_corner = "No corner cluster without motors"
    assert verdict(no_corner, **f1, sm=dict(corner_f1=0.6), **{"rec-sm": dict(corner_f1=0.6)})
    f1["rec-s"] = {"corner_f1": 0.55}
    assert not verdict(no_corner, **f1, sm=dict(corner_f1=0.6), **{"rec-sm": dict(corner_f1=0.9)})


def test_the_position_claim_fails_if_any_model_decodes_x_or_y():
    claim = "No global notion of position"
    blind = {m: {"r2_x": 0.0, "r2_y": 0.02} for m in ("s", "sm", "rec-s", "rec-sm")}
    assert verdict(claim, **blind)
    assert not verdict(claim, **{**blind, "s": {"r2_x": 0.5, "r2_y": 0.0}})
    assert not verdict(claim, **{**blind, "rec-sm": {"r2_x": 0.0, "r2_y": 0.1}})


def test_the_memory_claims_need_their_clusters_and_r2_margins():
    claim, sharper = "Memory", "Motors sharpen memory"
    base = {"s": {"behind_r2": 0.1}, "rec-s": {"behind_r2": 0.5}}
    assert verdict(claim, **base, **{"rec-sm": dict(nothing_clusters=2, behind_r2=0.6)})
    assert not verdict(claim, **base, **{"rec-sm": dict(nothing_clusters=1, behind_r2=0.6)})
    assert not verdict(claim, **base, **{"rec-sm": dict(nothing_clusters=3, behind_r2=0.15)})
    assert verdict(sharper, **base, **{"rec-sm": dict(behind_r2=0.6)})
    assert not verdict(sharper, **base, **{"rec-sm": dict(behind_r2=0.45)})
