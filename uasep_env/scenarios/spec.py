"""One episode's initial conditions (:class:`ScenarioSpec`) and how they start the world."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.obstacles import DUBINS_CLASS, ObstacleState

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = ["N_WAYPOINTS", "ScenarioSpec", "place_obstacles"]

#: Way-points of every planned trajectory (shorter plans are padded with their end point).
N_WAYPOINTS = 4


@dataclass
class ScenarioSpec:
    """Initial conditions of one episode (NED, SI units).

    The ``obs_*`` names of the obstacle fields (``obs_pos``, ...) still read, with a
    ``DeprecationWarning``, for one version.

    Attributes:
        family: Name of the family that generated it.
        waypoints: ``(N_WAYPOINTS, 3)`` planned trajectory of the formation centre (m).
        cruise_speed: Speed along it (m/s).
        slots: ``(n_uavs, 3)`` formation pattern (m, formation frame).
        uav_pos: ``(n_uavs, 3)`` initial positions (m).
        uav_vel: ``(n_uavs, 3)`` initial velocities (m/s).
        obstacle_pos: ``(M, 3)`` obstacle positions (m).
        obstacle_heading: ``(M,)`` headings (rad from north towards east).
        obstacle_speed: ``(M,)`` horizontal airspeeds (m/s).
        obstacle_turn_rate: ``(M,)`` initial turn commands (rad/s).
        obstacle_climb_rate: ``(M,)`` initial climb commands, positive up (m/s).
        obstacle_max_turn_rate: ``(M,)`` ``w_max`` (rad/s).
        obstacle_max_climb_rate: ``(M,)`` ``vz_max`` (m/s).
        obstacle_radius: ``(M,)`` safety radii (m).
        obstacle_alt_band: ``(M, 2)`` altitude bands (m, positive up).
        obstacle_active: ``(M,)`` slots in use.
        obstacle_hold_until: ``(M,)`` time before which the pilot keeps the initial
            commands (s).
        wind: ``(3,)`` steady wind (m/s, NED).
    """

    family: str
    waypoints: np.ndarray
    cruise_speed: float
    slots: np.ndarray
    uav_pos: np.ndarray
    uav_vel: np.ndarray
    obstacle_pos: np.ndarray
    obstacle_heading: np.ndarray
    obstacle_speed: np.ndarray
    obstacle_turn_rate: np.ndarray
    obstacle_climb_rate: np.ndarray
    obstacle_max_turn_rate: np.ndarray
    obstacle_max_climb_rate: np.ndarray
    obstacle_radius: np.ndarray
    obstacle_alt_band: np.ndarray
    obstacle_active: np.ndarray
    obstacle_hold_until: np.ndarray
    wind: np.ndarray

    def __getattr__(self, name: str) -> Any:
        # Only called for names that are not attributes: the deprecated obs_* aliases.
        if name.startswith("obs_") and "obstacle_" + name[4:] in _FIELD_NAMES:
            warnings.warn(
                f"ScenarioSpec.{name} is deprecated; use obstacle_{name[4:]}",
                DeprecationWarning,
                stacklevel=2,
            )
            return getattr(self, "obstacle_" + name[4:])
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")


_FIELD_NAMES = frozenset(f.name for f in fields(ScenarioSpec))

#: The obstacle state's per-obstacle fields that a :class:`ScenarioSpec` gives
#: (``obstacle_*``).
_OBSTACLE_FIELDS = (
    "pos",
    "heading",
    "speed",
    "turn_rate",
    "climb_rate",
    "max_turn_rate",
    "max_climb_rate",
    "radius",
    "alt_band",
    "active",
    "hold_until",
)


def place_obstacles(
    obstacles: ObstacleState, mask: np.ndarray, specs: Sequence[ScenarioSpec], config: EnvConfig
) -> None:
    """Start the obstacles of ``specs`` in the environments selected by ``mask``.

    Args:
        obstacles: The batch's obstacle state, written in place.
        mask: ``(E,)`` bool, or an index array: the environments starting an episode.
        specs: One spec per selected environment, in order.
        config: The configuration (the pilots' command changes, the ground).
    """
    for name in _OBSTACLE_FIELDS:
        getattr(obstacles, name)[mask] = np.stack([getattr(s, "obstacle_" + name) for s in specs])
    obstacles.switch_prob[mask] = min(1.0, config.dt / config.obstacle.mean_switch_time)
    obstacles.straight_prob[mask] = config.obstacle.straight_probability
    obstacles.wind[mask] = np.stack([s.wind for s in specs])
    obstacles.ground[mask] = config.airspace.ground_altitude
    # Synthetic obstacles fly the Dubins model; a replayed track's class is set by the replay.
    obstacles.aircraft_class[mask] = DUBINS_CLASS
