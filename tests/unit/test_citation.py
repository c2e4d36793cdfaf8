"""CITATION.cff describes the tool (Citation File Format 1.2.0) and names the source paper of
its method; the README and the docs cite it, not the shadow paper, as the method's source."""

from __future__ import annotations

import re
import tomllib

import pytest
import yaml

from conftest import ROOT

SOURCE_TITLE = "Characterizing Lidar Point-Cloud Adversities Using a Vector Field Visualization"
SHADOW_TITLE = "Mitigating Shadows in Lidar Scan Matching using Spherical Voxels"
# CFF 1.2.0's reference types that these references can take (the schema lists 47).
REFERENCE_TYPES = {"article", "conference-paper", "thesis", "software", "book", "report", "generic"}


@pytest.fixture(scope="module")
def citation() -> dict:
    return yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))


def test_the_citation_file_is_cff_1_2_0_of_this_version(citation):
    assert citation["cff-version"] == "1.2.0" and citation["type"] == "software"
    assert {"cff-version", "message", "title", "authors"} <= citation.keys()
    assert citation["authors"] and all("name" in a or "family-names" in a for a in citation["authors"])
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert str(citation["version"]) == project["version"]
    assert citation["license"] == project["license"]["text"]


def test_every_reference_has_a_type_a_title_and_named_authors(citation):
    references = citation["references"]
    assert len(references) >= 8
    for reference in references:
        assert reference["type"] in REFERENCE_TYPES and reference["title"], reference
        assert all(a["family-names"] and a["given-names"] for a in reference["authors"]), reference["title"]
        assert 1990 <= reference["year"] <= 2026, reference["title"]
        if "doi" in reference:
            assert re.fullmatch(r"10\.\d{4,9}/\S+", reference["doi"]), reference["doi"]


def test_the_source_paper_comes_first_under_references(citation):
    source, shadow = citation["references"][:2]
    assert source["title"] == SOURCE_TITLE and source["doi"] == "10.33012/2024.19864"
    assert [(a["given-names"], a["family-names"]) for a in source["authors"]] == [
        ("Daniel", "Choate"),
        ("Jason H.", "Rife"),
    ]
    assert {a["affiliation"] for a in source["authors"]} == {"Tufts University"}
    assert shadow["title"] == SHADOW_TITLE and shadow["year"] == 2022
    assert [a["family-names"] for a in shadow["authors"]] == ["McDermott", "Rife"]


def _words(path) -> str:
    """A page's text on one line, without quote marks: a title may wrap."""
    return " ".join(" ".join(line.lstrip("> ") for line in path.read_text(encoding="utf-8").splitlines()).split())


def test_the_readme_and_the_docs_name_the_source_paper_as_the_method():
    for page in ("README.md", "docs/references.md"):
        text = _words(ROOT / page)
        assert SOURCE_TITLE in text and "Choate" in text and SHADOW_TITLE in text, page
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "config").glob("*.yaml"))]
    for path in pages:  # McDermott & Rife is the shadow paper, never the method's source
        text = _words(path)
        assert not re.search(r"method is that of McDermott|(Figure|Section) \w+ of McDermott", text), path
        assert "McDermott & Rife 2022, Section" not in text, path
