"""Typed, frozen and validated configuration.

Every setting of the simulator and the environments lives in one of the frozen dataclasses
of this package: the groups (:mod:`uasep_env.config.groups`) and :class:`EnvConfig`, which
holds one of each (:mod:`uasep_env.config.env`). :func:`make_config` builds an
:class:`EnvConfig` from keyword arguments or a (nested) dict; unknown keys raise a
:class:`TypeError` (Python's convention for an unexpected keyword) and invalid or
out-of-range values a :class:`ValueError`, each naming the dotted field. Every numeric field
is bounded to a physically meaningful range (:mod:`uasep_env.config.checks`), so that a
config that validates also simulates (no overflow, no infinite reward, no clipped sensing).

Units are SI throughout: metres (m), seconds (s), radians (rad), m/s, m/s^2.
"""

from __future__ import annotations

from uasep_env.config import groups
from uasep_env.config.env import (
    AS_PUBLISHED,
    FORMATION_PATTERNS,
    VERSION_DEFAULTS,
    EnvConfig,
    make_config,
)
from uasep_env.config.groups import *  # noqa: F403 (the groups' public names, groups.__all__)


def __getattr__(name: str) -> object:
    # SCENARIOS is read from the scenario registry when asked for (see config.env).
    if name == "SCENARIOS":
        from uasep_env.config import env

        return env.SCENARIOS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    *groups.__all__,
    "AS_PUBLISHED",
    "FORMATION_PATTERNS",
    "SCENARIOS",  # noqa: F405 (read by __getattr__ above)
    "VERSION_DEFAULTS",
    "EnvConfig",
    "make_config",
]
