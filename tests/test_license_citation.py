"""The licence and the citation are files a tool can read: ``LICENSE`` holds the MIT terms that
``pyproject.toml`` names, and ``CITATION.cff`` (Citation File Format 1.2.0) cites the project and,
as its preferred citation, the paper of the method — the same paper as the README's BibTeX.

Pure file reading: no torch import.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
# What the Citation File Format 1.2.0 requires of a file, and of a reference.
CFF_REQUIRED = {"cff-version", "message", "title", "authors"}
REFERENCE_REQUIRED = {"type", "title", "authors"}


def _citation() -> dict[str, object]:
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert isinstance(citation, dict)
    return citation


def test_the_licence_is_mit_as_the_package_metadata_says() -> None:
    licence = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert licence.startswith("MIT License\n")
    assert re.search(r"^Copyright \(c\) \d{4} brdfgan contributors$", licence, re.M)
    assert "WITHOUT WARRANTY OF ANY KIND" in licence
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["license"] == {"text": "MIT"}
    assert _citation()["license"] == "MIT"


def test_the_citation_file_cites_the_project_and_the_paper() -> None:
    citation = _citation()
    assert citation.keys() >= CFF_REQUIRED, CFF_REQUIRED - citation.keys()
    assert citation["cff-version"] == "1.2.0" and citation["type"] == "software"
    assert citation["authors"] == [{"name": "brdfgan contributors"}]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert str(citation["version"]) == project["version"]
    paper = citation["preferred-citation"]
    assert isinstance(paper, dict) and paper.keys() >= REFERENCE_REQUIRED
    assert paper["type"] == "article" and paper["year"] == 2019
    assert paper["title"] == "Single Image BRDF Parameter Estimation with a Conditional Adversarial Network"
    assert [(a["family-names"], a["given-names"]) for a in paper["authors"]] == [
        ("Boss", "Mark"),
        ("Lensch", "Hendrik P. A."),
    ]
    assert "1910.05148" in paper["journal"] and paper["url"] == "https://arxiv.org/abs/1910.05148"


def test_the_readme_bibtex_cites_the_same_paper() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    paper = _citation()["preferred-citation"]
    assert isinstance(paper, dict)
    for entry in re.findall(r"^@\w+\{.*?^\}", readme, re.S | re.M):
        fields = dict(re.findall(r"^\s*(\w+)\s*=\s*\{(.*)\},?\s*$", entry, re.M))
        assert fields["title"] == paper["title"]
        assert fields["journal"] == paper["journal"] and int(fields["year"]) == paper["year"]
