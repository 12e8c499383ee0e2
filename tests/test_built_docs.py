"""tools/check_built_docs.py, the check ``make docs`` runs on the built site, can fail."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location(
        "check_built_docs", ROOT / "tools/check_built_docs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PAGE = """<html><head>{style}</head><body><article>
<h1 id="top">Card</h1>
<a href="../environment.html#scenarios">Scenarios</a>
<a href="{repo}">repository file</a>
{table}
</article></body></html>"""


def _site(tmp_path: Path, *, anchor="scenarios", repo="uasep_env/sim/world.py",
          style='<link rel="stylesheet" href="../_static/tables.css" />',
          table='<table class="docutils"><tr><td>1</td></tr></table>') -> Path:  # fmt: skip
    check = _checker()
    site = tmp_path / "html"
    (site / "envs").mkdir(parents=True)
    (site / "environment.html").write_text(f'<html><body><h2 id="{anchor}">S</h2></body></html>')
    (site / "envs" / "Formation.html").write_text(
        PAGE.format(style=style, repo=check.REPOSITORY_FILES + repo, table=table)
    )
    return site


def test_a_good_site_passes(tmp_path):
    assert _checker().check(_site(tmp_path)) == []


def test_a_broken_anchor_a_missing_repository_file_and_a_bare_table_each_fail(tmp_path):
    check = _checker()
    assert any("no #scenarios" in p for p in check.check(_site(tmp_path / "a", anchor="x")))
    # The env cards' old defect: docs/environment.md linked as a repository path without docs/.
    bad = check.check(_site(tmp_path / "b", repo="environment.md#scenarios"))
    assert any("names no file of the repository" in p for p in bad)
    assert any(
        "does not link tables.css" in p for p in check.check(_site(tmp_path / "c", style=""))
    )
    bare = check.check(_site(tmp_path / "d", table="<table><tr><td>1</td></tr></table>"))
    assert any("not one the stylesheet makes scroll" in p for p in bare)


def test_the_checker_and_the_site_name_the_same_repository_and_stylesheet():
    conf = (ROOT / "docs" / "conf.py").read_text()
    check = _checker()
    assert f'REPOSITORY_FILES = "{check.REPOSITORY_FILES}"' in conf
    assert re.search(rf'html_css_files = \[[^]]*"{check.STYLESHEET}"', conf)
    css = (ROOT / "docs" / "_static" / check.STYLESHEET).read_text()
    assert "table.docutils" in css and "overflow-x: auto" in css


def test_make_docs_runs_the_check_on_the_built_site():
    make = (ROOT / "Makefile").read_text()
    docs = make[make.index("\ndocs:") :].split("\n\n")[0]
    assert "tools/check_built_docs.py docs/_build/html" in docs
