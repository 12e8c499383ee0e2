"""The documentation's examples run: the docstrings' doctests and the pages' Python blocks.

Every fenced ``python`` block of ``README.md`` and ``docs/*.md`` is executed, the blocks of
a page in order in one namespace (as a reader would paste them). Examples that should not
run (long training, a cluster) are ``bash`` blocks or MyST ``{code-block}`` directives.
The site itself is built by ``make docs`` (Sphinx, warnings as errors).
"""

from __future__ import annotations

import doctest
import importlib
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
        "uasep_env.geometry.uav_distances",
        "uasep_env.tables.render_table",
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
