"""Check the built documentation site: links that resolve, tables that scroll.

    python tools/check_built_docs.py docs/_build/html

Run by ``make docs`` after Sphinx (so CI checks the site a reader gets, not its sources):

* every relative link of every page (``href`` without a scheme) names a file of the site,
  and its ``#anchor``, if any, an ``id`` on that page: the env cards' links to Scenarios,
  Observations, Rewards, Costs, Action modes and Versions stay on the site;
* every link into the repository (``docs/conf.py``'s ``REPOSITORY_FILES``) names a file
  or folder of this checkout (a page's link to ``docs/x.md`` that left the site for a
  repository path without ``docs/`` is caught here);
* every page with a table links ``_static/tables.css`` and holds each table inside its
  ``<article>`` with the class the stylesheet's rule selects (``docutils``, or inside a
  ``table-wrapper``), so a wide table scrolls sideways instead of overflowing at 1280 px.

Exits 1 with one line per problem.
"""

from __future__ import annotations

import ast
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

ROOT = Path(__file__).resolve().parents[1]


def _conf_value(name: str) -> str:
    """A string constant of docs/conf.py, read without running it (it imports Sphinx)."""
    for node in ast.parse((ROOT / "docs" / "conf.py").read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == name for t in node.targets):
            return ast.literal_eval(node.value)
    raise LookupError(f"docs/conf.py defines no {name}")


#: Links into the repository's files (docs/conf.py's REPOSITORY_FILES, read from there),
#: checked against this checkout.
REPOSITORY_FILES = _conf_value("REPOSITORY_FILES")
#: What the stylesheet's rule selects (docs/_static/tables.css).
TABLE_CLASSES = ("docutils",)
WRAPPER_CLASS = "table-wrapper"
STYLESHEET = "tables.css"
#: Generated pages whose links are Sphinx's own machinery (search, index), not content.
SKIPPED = (
    "_static/",
    "_sources/",
    "_modules/",
    "_downloads/",
    "_images/",
    "search.html",
    "genindex.html",
    "py-modindex.html",
)


class _Page(HTMLParser):
    """One page's ids, relative links, stylesheets and tables (with their context)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[str] = []
        self.styles: list[str] = []
        self.tables: list[tuple[bool, bool]] = []  # (inside <article>, styled)
        self._stack: list[tuple[str, set[str]]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        classes = set(a.get("class", "").split())
        if "id" in a:
            self.ids.add(a["id"])
        if "name" in a and tag == "a":
            self.ids.add(a["name"])
        if tag == "a" and "href" in a:
            self.links.append(a["href"])
        if tag == "link" and "stylesheet" in a.get("rel", ""):
            self.styles.append(a.get("href", ""))
        if tag == "table":
            inside = any(t == "article" for t, _ in self._stack)
            wrapped = any(WRAPPER_CLASS in c for _, c in self._stack)
            self.tables.append((inside, wrapped or bool(classes & set(TABLE_CLASSES))))
        if tag not in ("br", "img", "meta", "link", "input", "hr", "col", "source", "wbr"):
            self._stack.append((tag, classes))

    def handle_endtag(self, tag: str) -> None:
        for k in range(len(self._stack) - 1, -1, -1):
            if self._stack[k][0] == tag:
                del self._stack[k:]
                return


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8", errors="replace"))
    return page


def check(site: Path) -> list[str]:
    """Every problem of the built site ``site``, one line each (empty: none)."""
    pages = {
        p.relative_to(site).as_posix(): p
        for p in sorted(site.rglob("*.html"))
        if not p.relative_to(site).as_posix().startswith(SKIPPED)
    }
    if not pages:
        return [f"{site}: no HTML pages (build the site first)"]
    parsed: dict[str, _Page] = {}

    def page_of(rel: str) -> _Page:
        if rel not in parsed:
            parsed[rel] = _parse(site / rel)
        return parsed[rel]

    problems = []
    for rel in pages:
        page = page_of(rel)
        for href in page.links:
            if href.startswith(REPOSITORY_FILES):
                path = unquote(urlsplit(href).path.split("/blob/main/", 1)[1])
                if not (ROOT / path).exists():
                    problems.append(f"{rel}: link {href!r} names no file of the repository")
                continue
            parts = urlsplit(href)
            if parts.scheme or parts.netloc or href.startswith(("mailto:", "javascript:")):
                continue
            target = (Path(rel).parent / unquote(parts.path)).as_posix() if parts.path else rel
            target = Path(target).as_posix()
            resolved = (site / target).resolve()
            if resolved.is_dir():
                resolved = resolved / "index.html"
            if not resolved.is_file():
                problems.append(f"{rel}: link {href!r} names no file of the site")
                continue
            if parts.fragment and resolved.suffix == ".html":
                other = page_of(resolved.relative_to(site.resolve()).as_posix())
                if unquote(parts.fragment) not in other.ids:
                    problems.append(f"{rel}: link {href!r}: no #{parts.fragment} on that page")
        if page.tables:
            if not any(s.split("?")[0].endswith(STYLESHEET) for s in page.styles):
                problems.append(f"{rel}: has tables but does not link {STYLESHEET}")
            for k, (inside, styled) in enumerate(page.tables, start=1):
                if not (inside and styled):
                    problems.append(
                        f"{rel}: table {k} is not one the stylesheet makes scroll "
                        f"(inside <article>: {inside}, class or wrapper: {styled})"
                    )
    return problems


def main(argv: list[str] | None = None) -> int:
    """Check the site named by the one argument; print the problems; 1 if any."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python tools/check_built_docs.py SITE_DIR", file=sys.stderr)
        return 2
    problems = check(Path(args[0]))
    for line in problems:
        print(line, file=sys.stderr)
    if not problems:
        print(f"{args[0]}: every relative link resolves; every table scrolls")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
