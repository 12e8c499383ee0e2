"""Deprecated names kept for one version: a warning that names the new one, then the value.

Obstacle quantities were renamed ``obs_*`` -> ``obstacle_*`` (``obs`` also means
observation) after 0.1.0; the old public names still work, with a warning, until the
next version.

Modules moved into the layer folders after 0.4.0 (``uasep_env.world`` ->
``uasep_env.sim.world``, ...; :data:`MOVED_MODULES`) still import by their old paths, with
a warning, until the next version: :func:`install_moved_modules` puts a finder on
``sys.meta_path`` that answers an old path with the module at its new one (the same module
object, so patching either name patches both).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType
from typing import Any, ClassVar

__all__ = [
    "MOVED_MODULES",
    "RENAMED_WORLD_ATTRIBUTES",
    "RenamedAttributes",
    "install_moved_modules",
    "warn_renamed",
]

#: :class:`uasep_env.sim.world.World` attributes renamed after 0.1.0: old name -> new name.
RENAMED_WORLD_ATTRIBUTES = {
    "obs_est_pos": "obstacle_est_pos",
    "obs_est_vel": "obstacle_est_vel",
    "min_obs_dist": "min_obstacle_dist",
}


def warn_renamed(old: str, new: str, stacklevel: int = 3) -> None:
    """Emit the :class:`DeprecationWarning` for ``old``, naming ``new``."""
    warnings.warn(
        f"{old} is deprecated and will be removed in the next version; use {new}",
        DeprecationWarning,
        stacklevel=stacklevel,
    )


class RenamedAttributes:
    """Mixin: reading an old attribute name (a key of ``_RENAMED``) warns and reads the new."""

    _RENAMED: ClassVar[dict[str, str]] = {}

    def __getattr__(self, name: str) -> Any:
        # Only called when normal lookup fails, so current names cost nothing.
        new = type(self)._RENAMED.get(name)
        if new is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        warn_renamed(f"{type(self).__name__}.{name}", f"{type(self).__name__}.{new}")
        return getattr(self, new)


def _moved(folder: str, names: str) -> dict[str, str]:
    return {f"uasep_env.{n}": f"uasep_env.{folder}.{n}" for n in names.split()}


#: Modules moved after 0.4.0: old dotted path -> new one (one row a module).
MOVED_MODULES: dict[str, str] = {
    **_moved(
        "sim",
        "world physics_step formation obstacles dynamics noise estimation geometry replay",
    ),
    **_moved("interface", "observation observation_layout actions rewards costs outcome"),
    **_moved("training", "lagrangian sb3_lagrangian"),
    **_moved("runtime", "atomic jsonio boundedzip runlock tables cores capacity"),
}


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Answers an old module path of :data:`MOVED_MODULES` with the module at its new one."""

    def find_spec(
        self, fullname: str, path: Any = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = MOVED_MODULES.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, self, origin=new)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = MOVED_MODULES[spec.name]
        warn_renamed(f"module {spec.name}", new, stacklevel=3)
        module = importlib.import_module(new)
        # The import system stamps the alias's spec on the module it gets; keep the real one
        # to put back (exec_module), so the module still knows its own name and file.
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        alias = module.__spec__.name if module.__spec__ is not None else None
        real = self._specs.pop(alias, None) if alias is not None else None
        if real is not None:
            module.__spec__ = real

    def __init__(self) -> None:
        self._specs: dict[str, Any] = {}


def install_moved_modules() -> None:
    """Put the finder of the moved modules on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedModuleFinder())
