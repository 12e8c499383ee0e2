"""docs/design.md is the map of the package: it names every module, and its layers hold.

The layers table and its exceptions are read from the page itself, so the page and the code
cannot drift apart: a module the page does not name, or an import that runs up a layer
without being listed there, fails here.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import uasep_env
from tests.test_imports import _graph

ROOT = Path(uasep_env.__file__).parent
PAGE = ROOT.parent / "docs" / "design.md"


def _section(title: str) -> str:
    text = PAGE.read_text()
    start = text.index(f"## {title}\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end >= 0 else len(text)]


def _modules() -> list[str]:
    """Every module of the package, as its path under ``uasep_env/`` (``sim/world.py``)."""
    return sorted(p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.py"))


def _folders() -> list[str]:
    return sorted(
        p.relative_to(ROOT).as_posix() + "/"
        for p in ROOT.iterdir()
        if p.is_dir() and (p / "__init__.py").exists()
    )


def _named(section: str) -> set[str]:
    return set(re.findall(r"`([a-z_0-9/]+(?:\.py|/))`", section))


def test_every_module_and_folder_of_the_package_is_on_the_map() -> None:
    named = _named(_section("Every module"))
    missing = [m for m in _modules() if m not in named and not m.endswith("/__init__.py")]
    assert not missing, f"docs/design.md does not name {missing}"
    assert not [f for f in _folders() if f not in named], "a folder is missing from the map"
    stale = [n for n in named if not (ROOT / n).exists()]
    assert not stale, f"docs/design.md names {stale}, which do not exist"


def _layers() -> dict[str, int]:
    """Folder or root module (``sim/``, ``rollout.py``) -> its layer, from the page's table."""
    layers: dict[str, int] = {}
    for row in _section("The layers").splitlines():
        match = re.match(r"\|\s*(\d+)\.", row)
        if match:
            cells = row.split("|")
            for place in re.findall(r"`([a-z_0-9/.]+)`", cells[2]):
                layers[place] = int(match.group(1))
    return layers


def _exceptions() -> set[tuple[str, str]]:
    """The imports the page lists as running up a layer: (importer, imported) places."""
    pairs: set[tuple[str, str]] = set()
    for item in _section("The layers").split("\n* ")[1:]:
        head, _, tail = item.partition("->")
        tail = tail.split(":")[0]
        for a in re.findall(r"`([a-z_0-9/.]+)`", head):
            for b in re.findall(r"`([a-z_0-9/.]+)`", tail):
                pairs.add((a, b))
    return pairs


def _place(module: str) -> str:
    """``uasep_env.sim.world`` -> ``sim/world.py``."""
    rel = module.split(".")[1:]
    if not rel:
        return "__init__.py"
    path = ROOT.joinpath(*rel)
    return "/".join(rel) + ("/" if path.is_dir() else ".py")


def _layer_of(place: str, layers: dict[str, int]) -> int:
    top = place.split("/")[0] + ("/" if "/" in place else "")
    if place in layers:
        return layers[place]
    if top in layers:
        return layers[top]
    raise AssertionError(f"docs/design.md's layers table does not place {place}")


def _excepted(a: str, b: str, exceptions: set[tuple[str, str]]) -> bool:
    def covers(pattern: str, place: str) -> bool:
        return place == pattern or (pattern.endswith("/") and place.startswith(pattern))

    return any(covers(x, a) and covers(y, b) for x, y in exceptions)


def test_every_import_runs_down_the_layers_or_is_a_listed_exception() -> None:
    layers, exceptions = _layers(), _exceptions()
    assert layers and exceptions
    up = []
    for importer, imported in _graph().items():
        a = _place(importer)
        if a == "__init__.py":
            continue  # the package's front door re-exports from every layer
        for target in imported:
            b = _place(target)
            if b == "__init__.py":
                continue
            if _layer_of(b, layers) > _layer_of(a, layers) and not _excepted(a, b, exceptions):
                up.append(f"{a} -> {b}")
    assert not up, f"imports that run up a layer, not listed in docs/design.md: {sorted(up)}"


def test_every_listed_exception_is_a_real_import() -> None:
    """A stale exception would let a future import run up unseen."""
    graph = {_place(k): {_place(m) for m in v} for k, v in _graph().items()}
    for a, b in _exceptions():
        assert any(
            (x == a or (a.endswith("/") and x.startswith(a)))
            and any(y == b or (b.endswith("/") and y.startswith(b)) for y in targets)
            for x, targets in graph.items()
        ), f"docs/design.md lists {a} -> {b}, which no module imports"


@pytest.mark.parametrize("place", ["sim/", "interface/", "runtime/", "training/"])
def test_the_layer_folders_exist(place: str) -> None:
    assert (ROOT / place / "__init__.py").exists()
