"""The documentation's examples run: the docstrings' doctests and the pages' Python blocks.

Every fenced ``python`` block of ``README.md`` and ``docs/*.md`` is executed, the blocks of
a page in order in one namespace (as a reader would paste them). Examples that should not
run (long training, a cluster) are ``bash`` blocks or MyST ``{code-block}`` directives.
The site itself is built by ``make docs`` (Sphinx, warnings as errors).
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import re

import pytest
from conftest import ROOT

import uasep_env

_FENCE = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def python_blocks(text: str) -> list[str]:
    """The fenced ``python`` blocks of a Markdown page, in order."""
    return [m[1] for m in _FENCE.finditer(text)]


def public_modules() -> list[str]:
    """Every module of ``uasep_env`` without a private (``_``) part in its name."""
    names = [uasep_env.__name__]
    for info in pkgutil.walk_packages(uasep_env.__path__, prefix="uasep_env."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return names


#: Optional dependencies (extras) some modules import at the top.
OPTIONAL = {"torch", "stable_baselines3", "matplotlib", "mpl_toolkits", "ray", "numba"}


def import_or_skip(name: str):
    """The module, or a skip when it needs an optional dependency that is not installed."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as e:
        if (e.name or "").split(".")[0] in OPTIONAL:
            pytest.skip(f"{name} needs {e.name} (an optional extra)")
        raise


@pytest.mark.parametrize("module", public_modules())
def test_doctests_of_every_public_module_pass(module):
    result = doctest.testmod(import_or_skip(module), verbose=False, report=True)
    assert result.failed == 0, f"{result.failed} doctest(s) of {module} failed (output above)"


def test_key_public_functions_have_doctests():
    finder = doctest.DocTestFinder()
    have = set()
    for name in public_modules():
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError:
            continue  # an optional extra's module (none of the names below)
        for test in finder.find(module):
            if test.examples:
                have.add(test.name)
    for name in (
        "uasep_env.envs.parallel.parallel_env",
        "uasep_env.config.env.make_config",
        "uasep_env.policies.check_policy_name",
        "uasep_env.reachable.distance.distance_to_ellipsoid",
        "uasep_env.sim.geometry.uav_distances",
        "uasep_env.runtime.tables.render_table",
    ):
        assert name in have, f"{name} lost its doctest"


def test_python_blocks_are_found():
    text = "a\n```python\nx = 1\n```\n```bash\nls\n```\n```{code-block} python\ny\n```\n"
    assert python_blocks(text) == ["x = 1\n"]
    assert python_blocks((ROOT / "README.md").read_text()), "the README shows no example"


@pytest.mark.parametrize(
    "page",
    [p for p in PAGES if python_blocks(p.read_text())],
    ids=lambda p: str(p.relative_to(ROOT)),
)
def test_the_pages_python_examples_run(page, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # an example that writes files writes them here
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {"__name__": "__docs__"}
    for i, block in enumerate(python_blocks(page.read_text())):
        code = compile(block, f"{page.name} (python block {i + 1})", "exec")
        exec(code, namespace)


_MARKDOWN_HEADING = re.compile(r"^\s*#{1,6}\s+\S")


def documented_objects(module) -> list[tuple[str, object]]:
    """The module and every class, function and method it defines: what autodoc shows."""
    found: list[tuple[str, object]] = [(module.__name__, module)]
    for name, obj in vars(module).items():
        if getattr(obj, "__module__", None) != module.__name__ or name.startswith("_"):
            continue
        if inspect.isclass(obj):
            found.append((f"{module.__name__}.{name}", obj))
            for attr, member in vars(obj).items():
                if not attr.startswith("_") or attr == "__init__":
                    target = getattr(member, "fget", member)  # a property's getter
                    if inspect.isfunction(target):
                        found.append((f"{module.__name__}.{name}.{attr}", target))
        elif inspect.isfunction(obj):
            found.append((f"{module.__name__}.{name}", obj))
    return found


def markdown_headings(doc: str) -> list[str]:
    """The lines of a docstring that read as Markdown headings (``## Action space``)."""
    return [ln.strip() for ln in doc.splitlines() if _MARKDOWN_HEADING.match(ln)]


def split_table_rows(doc: str) -> list[str]:
    """Rows of a reST simple table whose first column wrapped onto a row of its own.

    In a simple table a line with text in the first column starts a new row, so a first
    cell too long for its column splits the row: the new row has blank middle columns
    (``(K_o)`` under ``per nearest obstacle``). Such rows are returned.
    """
    lines = doc.splitlines()
    bad: list[str] = []
    border = re.compile(r"^\s*=+( +=+)+\s*$")
    borders = [i for i, ln in enumerate(lines) if border.match(ln)]
    # A table: border, header, border, rows..., border (three borders in a row of the list).
    for top, head, bottom in zip(borders, borders[1:], borders[2:], strict=False):
        if head != top + 2:
            continue
        spans = [m.span() for m in re.finditer(r"=+", lines[top])]
        for ln in lines[head + 1 : bottom]:
            cells = [
                ln[a:b].strip() if len(spans) - 1 > k else ln[a:].strip()
                for k, (a, b) in enumerate(spans)
            ]
            if cells[0] and any(not c for c in cells[1:-1]):
                bad.append(ln.strip())
    return bad


def test_the_checks_of_docstrings_see_their_defects():
    assert markdown_headings("Summary.\n\n    ## Action space\n    Box.\n") == ["## Action space"]
    assert markdown_headings("Summary.\n\n    Action space:\n        Box.\n") == []
    table = (
        "====  ====  ====\nA     B     C\n====  ====  ====\nx     1     one\n"
        "      also  two\nlong  2     wraps\n(y)         three\n====  ====  ====\n"
    )
    assert split_table_rows(table) == ["(y)         three"]


@pytest.mark.parametrize("module", public_modules())
def test_api_docstrings_are_google_style_not_markdown(module):
    # Napoleon renders Google-style sections ("Action space:" + indented text); a
    # Markdown heading would show literally on the API pages, and a first table cell too
    # long for its column splits the row.
    for name, obj in documented_objects(import_or_skip(module)):
        doc = inspect.getdoc(obj) or ""
        assert not markdown_headings(doc), f"{name}: Markdown headings {markdown_headings(doc)}"
        assert not split_table_rows(doc), f"{name}: split table rows {split_table_rows(doc)}"


def broken_table_rows(text: str) -> list[str]:
    """Rows of a Markdown table that do not have their table's cells, or run onto a new line.

    A table is a run of lines starting with ``|``; each must end with ``|`` and have the
    header's number of cells (``|`` inside code spans and ``\\|`` are not separators).
    """
    bad, width = [], None
    for line in text.splitlines():
        row = line.strip()
        if not row.startswith("|"):
            width = None
            continue
        cells = re.sub(r"`[^`]*`", "", row).replace("\\|", "").count("|")
        width = cells if width is None else width  # the header sets it
        if not row.endswith("|") or cells != width:
            bad.append(row[:80])
    return bad


def test_the_table_check_sees_a_row_broken_over_lines():
    ok = "| a | b |\n|---|---|\n| `x|y` | 2 |\n\ntext\n| c |\n|---|\n"
    assert broken_table_rows(ok) == []
    assert broken_table_rows("| a | b |\n|---|---|\n| 1 | two\nthree |\n") == ["| 1 | two"]
    assert broken_table_rows("| a | b |\n|---|---|\n| 1 | 2 | 3 |\n") == ["| 1 | 2 | 3 |"]


@pytest.mark.parametrize("page", [*PAGES, ROOT / "train" / "README.md"], ids=lambda p: p.name)
def test_the_pages_tables_have_every_row_on_one_line(page):
    assert broken_table_rows(page.read_text()) == []
