"""One episode's random draws, before any geometry, and the layout of their columns.

:func:`uasep_env.scenarios.batched.draw_encounters` (or its compiled twin) makes them;
:mod:`uasep_env.scenarios.batch_geometry` builds a batch of episodes from them. Both read
the columns by the names here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uasep_env.scenarios.spec import N_WAYPOINTS

__all__ = ["EpisodeDraws"]

_TURNS = N_WAYPOINTS - 2
# The layout's uniform draws, in order: the plan's heading, its turns, whether each turn is
# taken (random() < 0.5), the turns' places along the plan; then per UAV the start scatter
# of the position, and of the velocity.
_PLAN_LOW = [-math.pi] + [-math.pi / 4] * _TURNS + [0.0] * _TURNS + [0.2] * _TURNS
_PLAN_HIGH = [math.pi] + [math.pi / 4] * _TURNS + [1.0] * _TURNS + [0.8] * _TURNS
_N_PLAN = len(_PLAN_LOW)
#: Columns of one obstacle's draws (:meth:`EpisodeDraws.obstacles`).
_MEET, _WHO, _W_MAX, _VZ_MAX, _SPEED, _OFFSET, _TURN, _ALT, _CLIMB, _CLIMBS, _LEAD = range(11)
_N_COLS = 11


@dataclass
class EpisodeDraws:
    """One episode's random draws, before any geometry.

    Attributes:
        family: The family's name.
        pattern: The formation pattern (``None``: the config's).
        layout: The layout's uniform draws (plan, then the UAVs' start scatter).
        obstacles: ``(M, 11)`` per obstacle: meeting time, UAV aimed at, ``w_max``,
            ``vz_max``, speed, heading offset and turn (the heading is
            ``(plan_heading + offset) + turn``), altitude offset, climb (``nan`` if level),
            whether it climbs, reaction lead.
    """

    family: str
    pattern: str | tuple | None
    layout: np.ndarray
    obstacles: np.ndarray
