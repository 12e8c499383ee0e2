"""Sphinx configuration of the uasep-env documentation (``make docs``)."""

from __future__ import annotations

import posixpath
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # document this checkout's uasep_env, not an installed copy

import uasep_env  # noqa: E402 (after the path insert above)

project = "uasep-env"
release = version = uasep_env.__version__
author = "uasep-env developers"
copyright = "uasep-env developers, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
templates_path = ["_templates"]
# figures/*.md are results files (tables the pages include), not pages.
exclude_patterns = ["_build", "figures"]

# Pages: Markdown (MyST). Headings get anchors so pages can link to sections.
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

# The client modules' trainers are not installed for the docs (OmniSafe has a venv of its own).
autodoc_mock_imports = ["omnisafe"]

# API reference: one page per public module (written by _write_api_pages below), generated
# from the docstrings (Google style).
# Each name is documented once, where it is defined (packages re-export names in __all__).
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True  # "Attributes:" as fields: properties keep their own entries
# The env classes' sections (Google style, as Gymnasium's env pages have them): each renders
# as a rubric with its text. Not "Arguments": napoleon reads that as "Args" (a field list).
ENV_SECTIONS = (
    "Action space",
    "Observation space",
    "Rewards",
    "Cost",
    "Episode end",
    "Info",
    "Configuration",
    "Reset options",
)
napoleon_custom_sections = list(ENV_SECTIONS)


#: Where links to repository files outside docs/ point on the site.
REPOSITORY_FILES = "https://github.com/uasep/uasep-env/blob/main/"

html_theme = "furo"
html_title = "uasep-env"
html_static_path = ["_static"]
# Wide tables scroll sideways in the content column (docs/_static/tables.css).
html_css_files = ["tables.css"]


def _canonical(target: str, module: str | None) -> str | None:
    """The defining ``module.qualname`` of a name a package re-exports, or None."""
    import importlib
    import inspect

    def lookup(path: str) -> object | None:
        parts = path.split(".")
        for i in range(len(parts), 0, -1):
            try:
                obj: object = importlib.import_module(".".join(parts[:i]))
            except ImportError:
                continue
            try:
                for part in parts[i:]:
                    obj = getattr(obj, part)
            except AttributeError:
                return None
            return obj
        return None

    for path in (f"{module}.{target}" if module else None, target):
        obj = lookup(path) if path else None
        if inspect.ismodule(obj):
            return obj.__name__
        name = getattr(obj, "__qualname__", None)
        if name and getattr(obj, "__module__", "").startswith("uasep_env"):
            return f"{obj.__module__}.{name}"
    return None


def _resolve_reexports(app, env, node, contnode):  # noqa: ANN001, ANN202 (Sphinx's hook)
    """Let a re-exported (``uasep_env.config.EnvConfig``) or short name link to its entry."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip("~.")
    domain = env.get_domain("py")
    canonical = _canonical(target, node.get("py:module"))
    if canonical is None or canonical == target:
        # A short or re-exported name: the one documented object of that name, if unique.
        last = "." + target.rsplit(".", 1)[-1]
        found = [name for name in domain.objects if name.endswith(last)]
        if len(found) != 1:
            return None
        canonical = found[0]
    return domain.resolve_xref(
        env, node["refdoc"], app.builder, node["reftype"], canonical, node, contnode
    )


def _restore_attribute_prose(app, what, name, obj, options, lines):  # noqa: ANN001, ANN202
    """Undo napoleon reading ``#: The registry: ...`` as the type ``The registry``.

    Napoleon takes the text before a first-line colon of a data/attribute docstring as its
    type; the project's annotations give the types, so prose before a colon is put back.
    """
    if what not in ("data", "attribute"):
        return
    for i, line in enumerate(lines):
        if line.startswith(":type: ") and " " in line[7:].strip():
            prose = line[7:].strip()
            del lines[i]
            first = next(j for j, ln in enumerate(lines) if ln.strip())
            lines[first] = f"{prose}: {lines[first].lstrip()}"
            return


def _public_modules() -> list[str]:
    """``uasep_env`` and its modules, without private (``_``) parts, in import order."""
    import pkgutil

    import uasep_env

    walk = pkgutil.walk_packages(uasep_env.__path__, prefix="uasep_env.")
    names = [info.name for info in walk]
    return ["uasep_env", *(n for n in names if not any(p.startswith("_") for p in n.split(".")))]


def _module_doc(name: str) -> str:
    """A module's docstring, read from its source.

    A client module (``uasep_env.clients``) need not import here: its trainer is not
    installed for the docs.
    """
    import ast
    import importlib.util

    source = Path(importlib.util.find_spec(name).origin).read_text()
    return ast.get_docstring(ast.parse(source)) or ""


def _write_api_pages(app) -> None:  # noqa: ANN001 (Sphinx's hook)
    """One ``api/<module>.rst`` per public module (written only when it changes).

    Not autosummary's recursive mode: it resolves ``uasep_env.metrics.aggregate`` to the
    function the package re-exports under the module's name, not to the module.
    """
    out = Path(app.srcdir) / "api"
    out.mkdir(exist_ok=True)
    modules = _public_modules()
    for name in modules:
        children = [m for m in modules if m.rpartition(".")[0] == name]
        title = name.replace("_", r"\_")
        text = f"{title}\n{'=' * len(title)}\n\n.. automodule:: {name}\n"
        if children:
            text += "\nModules\n-------\n\n"
            for child in children:
                doc = _module_doc(child).strip().split("\n\n")[0]
                doc = " ".join(doc.split())  # the first paragraph, on one line
                text += f"* :doc:`{child}` -- {doc}\n"
            text += "\n.. toctree::\n   :hidden:\n\n"
            text += "".join(f"   {child}\n" for child in children)
        page = out / f"{name}.rst"
        if not page.exists() or page.read_text() != text:
            page.write_text(text)
    for page in out.glob("*.rst"):
        if page.stem not in modules:
            page.unlink()  # a module that was removed or renamed


_RELATIVE_UP = re.compile(r"\]\((\.\./[^)\s]+)\)")


def repository_link(docname: str, target: str) -> str | None:
    """Where a page's ``../`` link points on the site: a repository URL, or None (a page).

    The target is resolved against the page's own folder (``envs/Formation`` links to
    ``../environment.md``, a page of the site, which MyST resolves and which must stay on
    the site); only a path that leaves docs/ (``../tests/a.py`` from ``speed``) becomes
    the repository's file.

    >>> repository_link("envs/Formation", "../environment.md#scenarios") is None
    True
    >>> repository_link("speed", "../benchmarks/bench_peers.py")
    'https://github.com/uasep/uasep-env/blob/main/benchmarks/bench_peers.py'
    """
    path = posixpath.normpath(posixpath.join(posixpath.dirname(docname), target))
    if not path.startswith("../"):
        return None
    return REPOSITORY_FILES + path.removeprefix("../")


def _link_outside_docs(app, docname, source):  # noqa: ANN001, ANN202 (Sphinx's hook)
    """``[x](../tests/a.py)`` (right on GitHub's view of a page) -> the repository's file.

    The site holds only docs/: a page's relative link to a repository file outside docs/
    becomes a link to that file in the repository, so pages keep plain relative links
    (which also work on GitHub). Links between pages stay on the site.
    """

    def replace(m: re.Match) -> str:
        link = repository_link(docname, m[1])
        return m[0] if link is None else f"]({link})"

    source[0] = _RELATIVE_UP.sub(replace, source[0])


def setup(app):  # noqa: ANN001, ANN201 (Sphinx's entry point)
    """Write the API pages, link outside docs/, resolve re-exported names, keep prose."""
    app.connect("source-read", _link_outside_docs)
    app.connect("builder-inited", _write_api_pages)
    app.connect("missing-reference", _resolve_reexports)
    app.connect("autodoc-process-docstring", _restore_attribute_prose, priority=600)
