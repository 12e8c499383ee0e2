"""The package is citable: ``CITATION.cff`` follows CFF 1.2.0 and names this version.

The full schema check is ``cffconvert --validate`` (not a dependency); here the keys CFF
1.2.0 requires and allows, and the facts that must agree with the package.
"""

from __future__ import annotations

import re

import pytest
from conftest import ROOT

import uasep_env

CFF = ROOT / "CITATION.cff"
CITING = ROOT / "docs" / "citing.md"

#: Every top-level key of CFF 1.2.0 (its schema's properties).
CFF_KEYS = {
    "abstract", "authors", "cff-version", "commit", "contact", "date-released", "doi",
    "identifiers", "keywords", "license", "license-url", "message", "preferred-citation",
    "references", "repository", "repository-artifact", "repository-code", "title", "type",
    "url", "version",
}  # fmt: skip
CFF_REQUIRED = {"authors", "cff-version", "message", "title"}


def cff_version_field(text: str) -> str:
    """The ``version:`` of a CITATION.cff's text (no YAML parser needed)."""
    m = re.search(r"^version:\s*[\"']?([^\"'\s#]+)", text, re.MULTILINE)
    assert m, "CITATION.cff has no version"
    return m[1]


def bibtex_version(text: str) -> str:
    """The ``version = {...}`` of the package's BibTeX entry on docs/citing.md."""
    m = re.search(r"@software\{uasep_env,.*?version\s*=\s*\{([^}]*)\}", text, re.DOTALL)
    assert m, "docs/citing.md has no @software{uasep_env, ...} entry with a version"
    return m[1]


def test_citation_names_the_package_version():
    # A release bumps uasep_env.__version__, CITATION.cff and the BibTeX together.
    version = uasep_env.__version__
    assert cff_version_field(CFF.read_text()) == version, (
        f"CITATION.cff's version differs from uasep_env.__version__ {version}"
    )
    assert bibtex_version(CITING.read_text()) == version, (
        f"docs/citing.md's BibTeX version differs from uasep_env.__version__ {version}"
    )


def test_version_readers_see_a_wrong_version():
    assert cff_version_field("cff-version: 1.2.0\nversion: 0.3.1 # x\n") == "0.3.1"
    assert cff_version_field('version: "1.0.0"\n') == "1.0.0"
    assert bibtex_version("@software{uasep_env,\n  version = {9.9},\n}") == "9.9"


def test_citation_file_follows_cff_1_2_0():
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load(CFF.read_text())
    assert set(cff) >= CFF_REQUIRED, f"missing {CFF_REQUIRED - set(cff)}"
    assert set(cff) <= CFF_KEYS, f"not CFF 1.2.0 keys: {set(cff) - CFF_KEYS}"
    assert cff["cff-version"] == "1.2.0"
    assert cff["type"] in ("software", "dataset")
    assert cff["authors"] and all("name" in a or "family-names" in a for a in cff["authors"])
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", str(cff["date-released"]))
    # The same licence and home as the package's metadata.
    tomllib = pytest.importorskip("tomllib", reason="Python >= 3.11")
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cff["license"] == project["license"]
    assert cff["repository-code"] == project["urls"]["Homepage"]
