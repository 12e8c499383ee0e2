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
import runpy

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
OPTIONAL = {"torch", "stable_baselines3", "matplotlib", "mpl_toolkits", "ray", "numba", "omnisafe"}


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


# --- Links between pages, and to the repository's files --------------------------------------

DOCS = ROOT / "docs"
#: docs/conf.py as Sphinx reads it: its link hook's rule, the static files it registers.
CONF = runpy.run_path(str(DOCS / "conf.py"))
#: The site's Markdown pages (figures/*.md are results files the pages include).
SITE_PAGES = sorted(
    p for p in DOCS.rglob("*.md") if not {"_build", "figures"} & set(p.relative_to(DOCS).parts)
)
ENV_CARDS = sorted((DOCS / "envs").glob("*.md"))
_FENCED = re.compile(r"^(`{3,}|~{3,}).*?^\1", re.DOTALL | re.MULTILINE)
_LINK_TARGET = re.compile(r"\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^(#{1,6})\s+(.+?)\s*#*\s*$", re.MULTILINE)


def markdown_links(text: str) -> list[str]:
    """The targets of a page's Markdown links and images, outside code."""
    text = re.sub(r"`[^`\n]*`", "", _FENCED.sub("", text))
    return _LINK_TARGET.findall(text)


_INCLUDE = re.compile(r"^```\{include\} (\S+)\n((?::[\w-]+:.*\n)*)```", re.MULTILINE)


def page_headings(page) -> list[tuple[int, str]]:
    """A page's headings (level, text) in order, those of the files it includes among them."""
    text, found = page.read_text(), []
    pieces = re.split(_INCLUDE, text)  # text, (path, options, text)...
    for i in range(0, len(pieces), 3):
        found += [(len(h), t) for h, t in _HEADING.findall(_FENCED.sub("", pieces[i]))]
        if i + 1 < len(pieces):
            offset = re.search(r":heading-offset: (\d+)", pieces[i + 1] + pieces[i + 2])
            shift = int(offset[1]) if offset else 0
            found += [(level + shift, t) for level, t in page_headings(page.parent / pieces[i + 1])]
    return found


def heading_anchors(page) -> set[str]:
    """The anchors MyST gives a page's headings (``myst_heading_anchors`` levels deep).

    MyST's slug (``default_slugify``, GitHub's): the heading's text, lower case, spaces to
    ``-``, everything but word characters and ``-`` dropped; a repeated slug gets ``-1``...
    """
    depth = CONF["myst_heading_anchors"]
    found: set[str] = set()
    for level, title in page_headings(page):
        if level > depth:
            continue
        text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title).replace("`", "")
        slug = re.sub(r"[^\w\u4e00-\u9fff\- ]", "", text.lower().replace(" ", "-"))
        unique, n = slug, 0
        while unique in found:
            n += 1
            unique = f"{slug}-{n}"
        found.add(unique)
    return found


def broken_links(page) -> list[str]:
    """A page's relative links that do not resolve where the built site puts them.

    The rule is the site's (``docs/conf.py``'s ``repository_link``, the hook Sphinx runs):
    a link that stays inside docs/ must name an existing page (and one of its headings'
    anchors) or file of the site; one that leaves docs/ becomes a repository link, whose
    file must exist. A repository URL written out must name an existing file too.
    """
    docname = page.relative_to(DOCS).with_suffix("").as_posix()
    bad = []
    for target in markdown_links(page.read_text()):
        path, _, anchor = target.partition("#")
        if target.startswith(CONF["REPOSITORY_FILES"]) or "/uasep-env/tree/main/" in target:
            repo_path = re.sub(r"^https://github\.com/uasep/uasep-env/(blob|tree)/main/", "", path)
            if not (ROOT / repo_path).exists():
                bad.append(f"{target} (no such repository file)")
            continue
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # another site, mailto:
            continue
        if not path:  # an anchor of the page itself
            if anchor not in heading_anchors(page):
                bad.append(f"{target} (no such heading)")
            continue
        link = CONF["repository_link"](docname, path)
        if link is not None:
            repo_path = link.removeprefix(CONF["REPOSITORY_FILES"])
            if not (ROOT / repo_path).exists():
                bad.append(f"{target} -> {link} (no such repository file)")
            continue
        site_file = (page.parent / path).resolve()
        if not site_file.is_relative_to(DOCS) or not site_file.exists():
            bad.append(f"{target} (no such page on the site)")
        elif anchor and site_file.suffix == ".md" and anchor not in heading_anchors(site_file):
            bad.append(f"{target} (no heading #{anchor} in {site_file.name})")
    return bad


def test_the_link_check_applies_the_sites_rule():
    # From an env card, ../environment.md is a page of the site: it must stay on the site.
    assert CONF["repository_link"]("envs/Formation", "../environment.md#scenarios") is None
    assert CONF["repository_link"]("speed", "../benchmarks/bench_peers.py") == (
        CONF["REPOSITORY_FILES"] + "benchmarks/bench_peers.py"
    )
    assert CONF["repository_link"]("envs/Formation", "../../tests/conftest.py") == (
        CONF["REPOSITORY_FILES"] + "tests/conftest.py"
    )
    source = ["[S](../environment.md#scenarios) [t](../../tests/conftest.py)"]
    CONF["_link_outside_docs"](None, "envs/Formation", source)
    assert source[0] == (
        f"[S](../environment.md#scenarios) [t]({CONF['REPOSITORY_FILES']}tests/conftest.py)"
    )
    assert "scenarios" in heading_anchors(DOCS / "environment.md")
    assert "the-lean-loop---trainer-lean" in heading_anchors(DOCS / "training.md")
    assert markdown_links("[a](x.md) `[b](y.md)`\n```\n[c](z.md)\n```\n") == ["x.md"]


@pytest.mark.parametrize("page", ENV_CARDS, ids=lambda p: p.name)
def test_env_cards_links_resolve_on_the_site(page):
    assert ENV_CARDS, "no env cards found"
    links = markdown_links(page.read_text())
    if page.name != "index.md":
        # The card's links to the environment page's sections must be among those checked.
        assert any(link.startswith("../environment.md#") for link in links), links
    assert broken_links(page) == []


@pytest.mark.parametrize("page", SITE_PAGES, ids=lambda p: p.relative_to(DOCS).as_posix())
def test_every_pages_links_resolve_on_the_site(page):
    assert broken_links(page) == []


# --- Wide tables ---------------------------------------------------------------------------


def css_rules(css: str) -> dict[str, dict[str, str]]:
    """A stylesheet's rules: each selector of a rule -> its declarations (comments dropped)."""
    css = re.sub(r"/\*.*?\*/", "", css, flags=re.DOTALL)
    rules: dict[str, dict[str, str]] = {}
    for selectors, body in re.findall(r"([^{}]+)\{([^{}]*)\}", css):
        declarations = dict(
            (k.strip(), v.strip())
            for k, _, v in (d.partition(":") for d in body.split(";"))
            if k.strip()
        )
        for selector in selectors.split(","):
            rules.setdefault(" ".join(selector.split()), {}).update(declarations)
    return rules


def test_wide_tables_scroll_sideways_on_the_site():
    # The results tables have a dozen columns: at 1280 px they must scroll inside the
    # content column, not run past it and hide their last columns.
    registered = [
        DOCS / folder / name
        for folder in CONF["html_static_path"]
        for name in CONF.get("html_css_files", [])
        if (DOCS / folder / name).is_file()
    ]
    assert registered, "docs/conf.py registers no stylesheet of docs/_static (html_css_files)"
    rules: dict[str, dict[str, str]] = {}
    for sheet in registered:
        rules.update(css_rules(sheet.read_text()))
    tables = {s: d for s, d in rules.items() if re.search(r"\btable\b", s)}
    assert any(
        d.get("overflow-x") in ("auto", "scroll")
        and d.get("display") == "block"
        and d.get("max-width") == "100%"
        for d in tables.values()
    ), f"no rule makes the pages' tables scroll sideways: {tables}"


def test_css_rules_are_read():
    css = "/* a { x: y } */\narticle table.docutils,\n.w { display: block; overflow-x: auto }"
    assert css_rules(css) == {
        "article table.docutils": {"display": "block", "overflow-x": "auto"},
        ".w": {"display": "block", "overflow-x": "auto"},
    }


# --- The user pages hold today's figures; their history is benchmarks/RESULTS_LOG.md ---------

#: What marks lab notes: a machine letter, a round's name, a commit hash, an issue
#: number, a scratch folder.
_LAB_NOTES = re.compile(
    r"machine [A-C]\b|\bthe [\w-]+ round\b|`[0-9a-f]{7,40}`|\bissue \d+|\(#\d+\)|/tmp/"
)


@pytest.mark.parametrize("name", ["speed.md", "training.md"])
def test_the_speed_and_training_pages_carry_no_lab_notes(name):
    text = (DOCS / name).read_text()
    assert _LAB_NOTES.findall(text) == [], f"docs/{name}: move history to RESULTS_LOG.md"
    assert "../benchmarks/RESULTS_LOG.md" in (DOCS / "speed.md").read_text()
    assert (ROOT / "benchmarks" / "RESULTS_LOG.md").is_file()
    if name == "speed.md":
        assert len(text.splitlines()) < 250, "docs/speed.md: a page read in five minutes"


def test_the_lab_notes_check_sees_them():
    found = _LAB_NOTES.findall(
        "on machine B (the boundary round, `e80e694`, issue 30) in /tmp/s8/x; a machine"
    )
    assert found == ["machine B", "the boundary round", "`e80e694`", "issue 30", "/tmp/"]


# ------------------------------------------------ commands that need the repository
#: A fenced block of any language (```` ```bash ````, ```` ```{code-block} ````, ...).
_ANY_FENCE = re.compile(r"^(`{3,}|~{3,})([^\n]*)\n(.*?)^\1[ \t]*$", re.DOTALL | re.MULTILINE)
#: A call of a script that is not in the wheel (benchmarks/, train/, baselines/, tools/), or
#: of one of the repository's make targets.
_REPO_COMMAND = re.compile(
    r"(?<![\w/.-])(?:\./)?(?:benchmarks|train|baselines|tools)/[\w/.-]+\.(?:py|sh)\b"
    r"|^\s*(?:\$\s*)?make\b",
    re.MULTILINE,
)
#: The quick start's convention: a block that needs a clone has this mark on the line above.
REPO_MARK = "*(repository)*"
DOC_PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def unmarked_repository_blocks(text: str, skip_first: bool = False) -> list[str]:
    """The code blocks that call a repository script or ``make`` without the mark above.

    ``skip_first``: the README's opening block (``make eval`` / ``make test``), which the
    project keeps exactly as it is, is exempt (the section after it states the convention).
    """
    bad = []
    for k, m in enumerate(_ANY_FENCE.finditer(text)):
        if (skip_first and k == 0) or not _REPO_COMMAND.search(m[3]):
            continue
        above = [ln for ln in text[: m.start()].splitlines() if ln.strip()]
        if not above or REPO_MARK not in above[-1]:
            line = text[: m.start()].count("\n") + 1
            bad.append(f"line {line}: {_REPO_COMMAND.search(m[3])[0].strip()}")
    return bad


def test_repository_blocks_are_found():
    marked = f"a {REPO_MARK}:\n\n```bash\npython train/seeds.py --x\n```\n"
    assert unmarked_repository_blocks(marked) == []
    for body in ("python train/seeds.py", "make docs", "bash benchmarks/a.sh", "tools/x.py"):
        assert unmarked_repository_blocks(f"text\n\n```bash\n{body}\n```\n"), body
    wheel = "```bash\nuasep-eval --json baselines/results/x.json\nuasep-train ppo_shared\n```\n"
    assert unmarked_repository_blocks(wheel) == []


@pytest.mark.parametrize("page", DOC_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_commands_that_need_the_repository_are_marked(page):
    bad = unmarked_repository_blocks(page.read_text(), skip_first=page.name == "README.md")
    assert bad == [], (
        f"{page.relative_to(ROOT)}: blocks that need a clone, without {REPO_MARK} on the line "
        f"above (the quick start's convention): {bad}"
    )
    quickstart = (ROOT / "docs" / "quickstart.md").read_text()
    assert f"Commands marked {REPO_MARK} need a clone" in quickstart
