"""Episodes' initial conditions and how they start the world.

One episode's is a :class:`ScenarioSpec`; several episodes starting in one call (the
environments that end in a step) are a :class:`ScenarioBatch`, the same fields stacked.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.sim.obstacles import DUBINS_CLASS, ObstacleState

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig
    from uasep_env.sim.formation import PlannedTrajectory

__all__ = ["N_WAYPOINTS", "ScenarioBatch", "ScenarioSpec", "place_obstacles"]

#: Way-points of every planned trajectory (shorter plans are padded with their end point).
N_WAYPOINTS = 4


@dataclass(kw_only=True)
class _InitialConditions:
    """The arrays of an episode's initial conditions (NED, SI units), by keyword.

    The fields :class:`ScenarioSpec` (one episode's) and :class:`ScenarioBatch` (several
    episodes', each with a leading axis of one row per episode) share; the shapes are one
    episode's.

    Attributes:
        waypoints: ``(N_WAYPOINTS, 3)`` planned trajectory of the formation centre (m).
        cruise_speed: Speed along it (m/s): a float in a spec, ``(B,)`` in a batch.
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

    waypoints: np.ndarray
    cruise_speed: float | np.ndarray
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


#: The array fields of a spec, stacked in a :class:`ScenarioBatch` (all but ``family``).
_ARRAY_FIELDS = tuple(f.name for f in fields(_InitialConditions))


@dataclass
class ScenarioSpec(_InitialConditions):
    """Initial conditions of one episode (NED, SI units).

    The arrays (given by keyword) are :class:`_InitialConditions`'. The ``obs_*`` names of
    the obstacle fields (``obs_pos``, ...) still read, with a ``DeprecationWarning``, for
    one version.

    Attributes:
        family: Name of the family that generated it.
    """

    family: str

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


@dataclass
class ScenarioBatch(_InitialConditions):
    """The initial conditions of several episodes: :class:`ScenarioSpec`'s fields stacked.

    Every array field of :class:`ScenarioSpec` (:class:`_InitialConditions`, by keyword)
    with a leading axis of one row per episode (``cruise_speed`` is ``(B,)``), plus:

    Attributes:
        families: Each episode's family name.
        specs: The per-episode specs it was stacked from, if it was (a family without a
            batched form; their extra fields, such as a replayed track, stay on them).
        plan: The plans of ``waypoints`` and ``cruise_speed``, if made already.
        plan_offsets: ``(B, W - 1, N, 3)`` the slots rotated along each segment
            (:func:`~uasep_env.sim.formation.segment_offsets`), if made already.
    """

    families: list[str]
    specs: list[ScenarioSpec] | None = None
    plan: PlannedTrajectory | None = None
    plan_offsets: np.ndarray | None = None

    @classmethod
    def from_specs(cls, specs: Sequence[ScenarioSpec]) -> ScenarioBatch:
        """The specs stacked (at least one)."""
        arrays = {n: np.stack([np.asarray(getattr(s, n)) for s in specs]) for n in _ARRAY_FIELDS}
        return cls(families=[s.family for s in specs], specs=list(specs), **arrays)

    def __len__(self) -> int:
        return len(self.families)

    def spec(self, k: int) -> ScenarioSpec:
        """Episode ``k``'s :class:`ScenarioSpec` (the one it was stacked from, if any)."""
        if self.specs is not None:
            return self.specs[k]
        values = {name: getattr(self, name)[k] for name in _ARRAY_FIELDS}
        values["cruise_speed"] = float(values["cruise_speed"])
        return ScenarioSpec(family=self.families[k], **values)


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
    obstacles: ObstacleState,
    mask: np.ndarray,
    specs: Sequence[ScenarioSpec] | ScenarioBatch,
    config: EnvConfig,
) -> None:
    """Start the obstacles of ``specs`` in the environments selected by ``mask``.

    Args:
        obstacles: The batch's obstacle state, written in place.
        mask: ``(E,)`` bool, or an index array: the environments starting an episode.
        specs: One spec per selected environment, in order, or their :class:`ScenarioBatch`.
        config: The configuration (the pilots' command changes, the ground).
    """
    if not isinstance(specs, ScenarioBatch):
        specs = ScenarioBatch.from_specs(specs)
    for name in _OBSTACLE_FIELDS:
        getattr(obstacles, name)[mask] = getattr(specs, "obstacle_" + name)
    obstacles.switch_prob[mask] = min(1.0, config.dt / config.obstacle.mean_switch_time)
    obstacles.straight_prob[mask] = config.obstacle.straight_probability
    obstacles.wind[mask] = specs.wind
    obstacles.ground[mask] = config.airspace.ground_altitude
    # Synthetic obstacles fly the Dubins model; a replayed track's class is set by the replay.
    obstacles.aircraft_class[mask] = DUBINS_CLASS
