"""The project's own files agree with the package: its version and its license."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import sensorimotor

ROOT = Path(__file__).resolve().parents[1]


def test_the_citation_names_this_version_and_the_papers_authors():
    text = (ROOT / "CITATION.cff").read_text()
    assert re.search(r"^version: (\S+)$", text, re.M)[1] == sensorimotor.__version__
    assert "Kulak" in text
    assert "Garcia Ortiz" in text


def test_the_license_file_is_the_one_the_package_declares():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["license"]
    assert (ROOT / "LICENSE").read_text().startswith(f"{declared} License")


def test_the_readmes_table_one_is_the_published_runs():
    """README quotes Table I of docs/results (trained on Square): every mean and sd, to the
    digits shown, is the one `reproduce` wrote to docs/results/table1.json."""
    table = (ROOT / "docs" / "results" / "table1.json").read_text()
    rows = json.loads(table)["tables"]["square"]
    readme = (ROOT / "README.md").read_text()
    for row in rows:
        line = re.search(rf"^\| {re.escape(row['name'])} \|(.*)$", readme, re.M)
        assert line, f"README has no Table I row for {row['name']}"
        quoted = re.findall(r"([0-9.]+) ± ([0-9.]+)", line[1])
        cells = [row["cells"][w] for w in ("square", "rooms1", "rooms2")]
        assert len(quoted) == len(cells)
        for (mean, sd), cell in zip(quoted, cells, strict=True):
            assert float(mean) == round(cell["mean"], 5), (row["name"], mean, cell["mean"])
            assert float(sd) == round(cell["sd"], 5), (row["name"], sd, cell["sd"])
