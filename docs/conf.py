"""Sphinx configuration of the uasep-env documentation (``make docs``)."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # document this checkout's uasep_env, not an installed copy

project = "uasep-env"
author = "uasep-env developers"
copyright = "uasep-env developers, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
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

# API reference: one page per public module, generated from the docstrings (Google style).
autosummary_generate = True
autosummary_imported_members = False
# Each name is documented once, where it is defined (packages re-export names in __all__).
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True  # "Attributes:" as fields: properties keep their own entries


html_theme = "furo"
html_title = "uasep-env"
html_static_path: list[str] = []
