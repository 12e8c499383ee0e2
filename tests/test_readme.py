"""The README's result tables are the results files' (``tools/sync_readme.py``)."""

from __future__ import annotations

import runpy

import pytest
from conftest import ROOT

SYNC = runpy.run_path(str(ROOT / "tools" / "sync_readme.py"))


def test_readme_tables_match_the_results_files():
    readme = (ROOT / "README.md").read_text()
    assert readme.count("<!-- results ") == 12  # every marked table is checked below
    assert SYNC["render_readme"](readme) == readme, "run: python tools/sync_readme.py"


def test_sync_rewrites_a_stale_table_and_names_a_missing_section(tmp_path):
    (tmp_path / "r.md").write_text("## Bank\n\n| metric | apf |\n|---|---|\n| x (m/s^2) | 1.0 |\n")
    stale = 'a\n<!-- results r.md "Bank" pretty -->\n| old |\n<!-- /results -->\nb\n'
    new = SYNC["render_readme"](stale, tmp_path)
    assert new.splitlines()[2:5] == [
        "| metric   | APF (proposed)   |",
        "|----------|------------------|",
        "| x (m/s²) | 1.0              |",
    ]
    assert new.startswith("a\n<!-- results") and new.endswith("<!-- /results -->\nb\n")
    with pytest.raises(ValueError, match="Nope"):
        SYNC["render_readme"]('<!-- results r.md "Nope" -->\n<!-- /results -->', tmp_path)
