"""The project's own files agree with the package: its version and its license."""

from __future__ import annotations

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
