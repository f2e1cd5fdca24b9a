"""docs/findings.md names every kind of health finding the code can raise, and the contract's
list of kinds is the same set."""

from __future__ import annotations

import re

from tests.paths import ROOT


def _kinds_in_code() -> set[str]:
    kinds = set()
    for path in (ROOT / "src" / "bodyfusion").rglob("*.py"):
        kinds |= set(re.findall(r'Finding\(\s*"([a-z_]+)"', path.read_text()))
    return kinds


def test_the_findings_page_names_every_kind_the_code_raises():
    kinds = _kinds_in_code()
    assert len(kinds) >= 20
    page = (ROOT / "docs" / "findings.md").read_text()
    assert {k for k in kinds if f"`{k}`" not in page} == set()


def test_the_contract_lists_every_kind_the_code_raises():
    contract = (ROOT / "docs" / "contract.md").read_text()
    listed = contract[contract.index("`kind` (a stable key:"):contract.index("`severity` (`warning`")]
    assert {k for k in _kinds_in_code() if f"`{k}`" not in listed} == set()
