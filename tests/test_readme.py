"""The result tables of the README and the docs pages are the results files'.

(``tools/sync_readme.py`` writes them.)
"""

from __future__ import annotations

import runpy

import pytest
from conftest import ROOT

SYNC = runpy.run_path(str(ROOT / "tools" / "sync_readme.py"))


def test_readme_tables_match_the_results_files():
    readme = (ROOT / "README.md").read_text()
    assert readme.count("<!-- results ") == 5  # every marked table is checked below
    # The headline results lead with the leaderboard's verdict.
    first = readme.index("<!-- results ")
    assert readme[first:].startswith('<!-- results baselines/results/bench/bench.md "Verdict" list')
    assert SYNC["render_readme"](readme) == readme, "run: python tools/sync_readme.py"


def test_docs_pages_tables_match_the_results_files():
    pages = SYNC["pages"]()
    assert ROOT / "README.md" in pages and ROOT / "docs" / "results.md" in pages
    marked = {p.name: p.read_text().count("<!-- results ") for p in pages}
    # The results page holds every method's held-out tables, the paper experiment's, the
    # trade-off tables, the CBF shield's and the set policy's zero-shot table.
    assert marked["results.md"] == 19 and marked["training.md"] == 3, marked
    results = (ROOT / "docs" / "results.md").read_text()
    assert '<!-- results learned_vs_apf.md "Held-out bank" -->' in results
    # The Results page opens with the leaderboard's verdict, then its tables.
    first = results.index("<!-- results ")
    assert results[first:].startswith('<!-- results baselines/results/bench/bench.md "Verdict"')
    assert marked["real_traffic.md"] == 3, marked  # every controller, both predictions
    # The families' table, written from the scenario registry.
    assert (ROOT / "docs" / "environment.md").read_text().count("<!-- scenarios -->") == 1
    for page in pages:
        text = page.read_text()
        assert SYNC["render_readme"](text) == text, f"{page.name}: run python tools/sync_readme.py"


def test_sync_check_names_a_stale_page(tmp_path, monkeypatch, capsys):
    page = tmp_path / "page.md"
    marker = '<!-- results summary.md "Paper scenario" pretty -->'
    page.write_text(f"{marker}\n| old |\n<!-- /results -->\n")
    monkeypatch.setitem(SYNC["main"].__globals__, "pages", lambda: [page])
    monkeypatch.setitem(SYNC["main"].__globals__, "ROOT", tmp_path)
    assert SYNC["main"](["--check"]) == 1
    assert "page.md" in capsys.readouterr().err
    assert SYNC["main"]([]) == 0 and "| old |" not in page.read_text()
    assert SYNC["main"](["--check"]) == 0


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


def test_sync_writes_a_verdict_list_from_its_results_file(tmp_path):
    (tmp_path / "b.md").write_text(
        "# Board\n\n## Verdict\n\n* **orca** is safest.\n  second line.\n* APF beaten.\n\n## X\n"
    )
    stale = '<!-- results b.md "Verdict" list -->\n* old\n<!-- /results -->\n'
    new = SYNC["render_readme"](stale, tmp_path)
    assert new.splitlines()[1:4] == ["* **orca** is safest.", "  second line.", "* APF beaten."]
    with pytest.raises(ValueError, match="no list after the heading 'Board'"):
        SYNC["render_readme"]('<!-- results b.md "Board" list -->\n<!-- /results -->\n', tmp_path)
