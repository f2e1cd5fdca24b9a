"""The project's metadata files agree with the package: licence, citation, changelog."""

from __future__ import annotations

import tomllib

import yaml

import bodyfusion
from tests.paths import ROOT


def test_the_licence_file_is_the_licence_the_package_declares():
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["license"]
    assert declared in ("MIT", {"text": "MIT"})
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")


def test_the_citation_file_cites_this_version_and_the_source_papers():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0"
    assert cff["version"] == bodyfusion.__version__
    assert cff["license"] == "MIT"
    references = (ROOT / "docs" / "references.md").read_text(encoding="utf-8")
    dois = [ref["doi"] for ref in cff["references"]]
    assert len(dois) == 4 and all(f"doi:{doi}" in references for doi in dois)


def test_the_changelog_has_an_entry_for_this_version():
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert f"## [{bodyfusion.__version__}] - " in changelog
