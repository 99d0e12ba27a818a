"""The report's numbers: a cluster's F1 from metrics, agreement with the paper, verdicts, and
the two renderings saying the same thing."""

from __future__ import annotations

import math

import pytest

from sensorimotor.analysis import analyze_representation
from sensorimotor.analysis.clusters import cluster_event_table
from sensorimotor.claims import _verdict, cluster_f1
from sensorimotor.data import generate
from sensorimotor.report import h, image, p, paper_agreement, table, to_html, to_markdown
from sensorimotor.world import load_world


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
