"""Deprecated names kept for one version: a warning that names the new one, then the value.

Obstacle quantities were renamed ``obs_*`` -> ``obstacle_*`` (``obs`` also means
observation) after 0.1.0; the old public names still work, with a warning, until the
next version.
"""

from __future__ import annotations

import warnings
from typing import Any, ClassVar

__all__ = ["RENAMED_WORLD_ATTRIBUTES", "RenamedAttributes", "warn_renamed"]

#: :class:`uasep_env.world.World` attributes renamed after 0.1.0: old name -> new name.
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
