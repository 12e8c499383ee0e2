"""Building blocks the scenario families share: plans, starts, aimed obstacles, assembly.

A family's generator (:mod:`uasep_env.scenarios.families`) lays out the formation
(:func:`random_layout` or its own), starts its obstacles (:func:`aimed_obstacle` aims one at
a UAV's planned position at a meeting time; :func:`obstacle_slots` fills the slots beyond
the first with background traffic) and assembles the :class:`ScenarioSpec`
(:func:`assemble`). Each draws from the generator in a fixed order, so a seed fixes the
episode.

Every random encounter: a random plan (heading; up to two turns of at most 45 degrees), the
UAVs' start scattered by up to 8 m and 1 m/s; each obstacle aimed at a UAV's planned position
at 60-140 s, with ``w_max`` 0.01-0.15 rad/s and ``vz_max`` 0.2-2 m/s, holding its course
until 10-40 s before the meeting.

Encounters are laid out on a fixed timeline, whatever the episode's length: a shorter
episode is the first part of the same encounter, a longer one flies on along the last leg.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from uasep_env.config.groups import FLIGHT_ALTITUDE
from uasep_env.scenarios.spec import N_WAYPOINTS, ScenarioSpec
from uasep_env.sim.formation import PlannedTrajectory, pattern_slots, segment_offsets

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = [
    "Encounter",
    "EncounterDraws",
    "Layout",
    "ObstacleStart",
    "aimed_obstacle",
    "airspace",
    "assemble",
    "obstacle_slots",
    "planned_position",
    "random_layout",
]

# Ranges of the random encounters (units in the names).
SPEED_RANGE_MPS = (3.0, 12.0)
TURN_RATE_RANGE_RADPS = (0.01, 0.15)
CLIMB_RATE_RANGE_MPS = (0.2, 2.0)
TIMELINE_S = 200.0  # the default episode_duration: encounters are laid out on it
MEET_TIME_RANGE = (0.3, 0.7)  # fraction of the timeline
REACTION_LEAD_RANGE_S = (10.0, 40.0)  # the pilot starts manoeuvring this long before
ALTITUDE_OFFSET_RANGE_M = (-8.0, 8.0)  # an obstacle's altitude about its target's
_ALT_BAND_HALF_WIDTH_M = 60.0
_START_SCATTER_M = 8.0
_START_SPEED_SCATTER_MPS = 1.0


def airspace(config: EnvConfig) -> tuple[float, float]:
    """The altitudes obstacles start between (m, positive up): ground + margin, ceiling."""
    air = config.airspace
    return air.ground_altitude + air.obstacle_margin, air.ceiling_altitude


@dataclass
class Layout:
    """The formation's side of an episode: plan, slots and initial UAV states.

    Attributes:
        waypoints: ``(N_WAYPOINTS, 3)`` planned trajectory of the formation centre (m).
        slots: ``(n_uavs, 3)`` formation pattern (m, formation frame).
        plan: The planned trajectory built from them.
        uav_pos: ``(n_uavs, 3)`` initial positions (m).
        uav_vel: ``(n_uavs, 3)`` initial velocities (m/s).
    """

    waypoints: np.ndarray
    slots: np.ndarray
    plan: PlannedTrajectory
    uav_pos: np.ndarray
    uav_vel: np.ndarray
    offsets: np.ndarray | None = None

    def planned_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Planned UAV positions ``(n_uavs, 3)`` (m) and the plan's unit direction at ``t``.

        The numbers of :func:`planned_position` and ``plan.heading_velocity``, bit for bit
        (the slots rotated once per segment, :func:`~uasep_env.sim.formation.segment_offsets`,
        as the world does): a scenario asks this several times per episode.
        """
        return _planned_at(self.plan, self.slots, t, self.offsets)


def _planned_at(
    plan: PlannedTrajectory, slots: np.ndarray, t: float, offsets: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Layout.planned_at` of ``plan`` with ``slots`` (their ``offsets``, if known)."""
    if offsets is None:
        offsets = segment_offsets(plan.direction, slots[None])
    tt = np.array([t])
    located = plan.locate(tt)
    center, _, direction = plan.center_and_direction(tt, located)
    return center[0] + offsets[0, located[1][0]], direction[0]


@dataclass
class ObstacleStart:
    """One obstacle's initial state (SI, NED; climb positive up)."""

    pos: np.ndarray
    heading: float
    speed: float
    max_turn_rate: float
    max_climb_rate: float
    climb_rate: float
    hold_until: float


@dataclass(frozen=True, kw_only=True)
class EncounterDraws:
    """What an :class:`Encounter` draws, declared for the batched scenarios.

    :func:`aimed_obstacle` draws, after the meeting time and the UAV: ``w_max``, ``vz_max``,
    then ``horizontal``'s speed (uniform in :attr:`speed`, plus the cruise speed if
    :attr:`above_cruise`), its side (a ``random() < 0.5`` sign, if :attr:`either_side`) and
    its turn from the plan's heading (uniform in :attr:`turn`; the heading is
    ``(plan_heading + heading_offset) + side * turn``), the altitude offset, ``vertical``'s
    climb sign (a ``random() < 0.5`` sign times ``vz_max``, if :attr:`climbs`; level
    otherwise) and the reaction lead. :mod:`uasep_env.scenarios.batched` draws the same
    numbers in the same order from this description; its tests hold it to the callables.
    """

    speed: tuple[float, float]
    above_cruise: bool = False
    heading_offset: float = 0.0
    either_side: bool = False
    turn: tuple[float, float]
    climbs: bool = False


@dataclass(frozen=True, kw_only=True)
class Encounter:
    """A kind of encounter: how an obstacle approaches the UAV it is aimed at.

    Attributes:
        horizontal: ``(rng, config, plan_heading) -> (speed, heading)`` (m/s, rad).
        vertical: ``(rng, vz_max) -> climb`` (m/s, positive up) at which it climbs through
            its target's altitude, or ``None``: level, at a random altitude offset.
        summary: One line: what encounter it makes (the family's, for a one-encounter
            family).
        parameters: What it draws (units).
        draws: The same draws, declared for the batched scenarios (``None``: episodes
            with this encounter are drawn one at a time).
    """

    horizontal: Callable[[np.random.Generator, EnvConfig, float], tuple[float, float]]
    vertical: Callable[[np.random.Generator, float], float | None]
    summary: str
    parameters: str
    draws: EncounterDraws | None = None


def planned_position(plan: PlannedTrajectory, t: float, slots: np.ndarray) -> np.ndarray:
    """``(n_uavs, 3)`` planned UAV positions at time ``t`` (m)."""
    pos, _ = plan.uav_positions(np.array([t]), slots[None])
    return pos[0]


def _extend(waypoints: np.ndarray, config: EnvConfig) -> PlannedTrajectory:
    """The plan, flying on along its last leg past the timeline in longer episodes."""
    if config.episode_duration > TIMELINE_S:
        last = waypoints[-1] - waypoints[-2]
        extra = config.cruise_speed * (config.episode_duration - TIMELINE_S)
        waypoints[-1] += last / np.linalg.norm(last) * extra
    return PlannedTrajectory(waypoints[None], config.cruise_speed)


def straight_plan(config: EnvConfig, heading: float = 0.0) -> np.ndarray:
    """A straight plan at the flight altitude from the origin, one timeline long (m)."""
    length = config.cruise_speed * TIMELINE_S
    d = np.array([math.cos(heading), math.sin(heading), 0.0])
    start = np.array([0.0, 0.0, -FLIGHT_ALTITUDE])
    return np.array([start + d * length * k / (N_WAYPOINTS - 1) for k in range(N_WAYPOINTS)])


def _random_plan(rng: np.random.Generator, length: float) -> np.ndarray:
    heading = rng.uniform(-math.pi, math.pi)
    turns = rng.uniform(-math.pi / 4, math.pi / 4, size=N_WAYPOINTS - 2)
    turns *= rng.random(N_WAYPOINTS - 2) < 0.5  # about half the legs are straight
    fractions = np.sort(rng.uniform(0.2, 0.8, size=N_WAYPOINTS - 2))
    legs = np.diff(np.concatenate([[0.0], fractions, [1.0]])) * length
    # Python floats: the same IEEE operations as numpy's, without a small array per leg.
    x, y, z = 0.0, 0.0, -FLIGHT_ALTITUDE
    pts = [(x, y, z)]
    h = heading
    for k, leg in enumerate(legs.tolist()):
        if k > 0:
            h += turns[k - 1]
        x, y, z = x + leg * math.cos(h), y + leg * math.sin(h), z + leg * 0.0
        pts.append((x, y, z))
    return np.array(pts)


_SHRINK_FACTORS = np.linspace(1.0, 0.0, 21)


def _separated_start(slots: np.ndarray, pos: np.ndarray, separation: float) -> np.ndarray:
    """``pos`` with its scatter about ``slots`` shrunk until no two UAVs are within ``separation``.

    The largest of the factors 1, 0.95, ..., 0 that separates them (1 for most draws, which
    are then unchanged); no random draw, so the generator's stream is the same either way.
    """
    scatter = pos - slots
    for f in _SHRINK_FACTORS:
        cand = slots + f * scatter if f < 1.0 else pos
        d = np.linalg.norm(cand[:, None] - cand[None], axis=-1)
        d[np.diag_indices(len(d))] = np.inf
        if d.min() >= separation:
            return cand
    return slots + 0.0  # the pattern itself is tighter than the separation distance


def layout(
    config: EnvConfig,
    waypoints: np.ndarray,
    pattern: str | tuple | None = None,
    start: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
) -> Layout:
    """The formation on ``waypoints``, starting by ``start(start_slots, plan_dir)``.

    Args:
        config: The config.
        waypoints: The plan (extended in place for episodes longer than the timeline).
        pattern: The formation pattern (default ``config.formation``).
        start: ``(start_slots, plan_dir0) -> (uav_pos, uav_vel)``, before the separation
            check shrinks the scatter.
    """
    slots = pattern_slots(pattern or config.formation, config.n_uavs, config.formation_spacing)
    plan = _extend(waypoints, config)
    offsets = segment_offsets(plan.direction, slots[None])
    start_slots, _ = _planned_at(plan, slots, 0.0, offsets)
    uav_pos, uav_vel = start(start_slots, plan.direction[0, 0])  # type: ignore[misc]
    uav_pos = _separated_start(start_slots, uav_pos, config.uav.separation_distance)
    return Layout(waypoints, slots, plan, uav_pos, uav_vel, offsets)


def random_layout(
    rng: np.random.Generator, config: EnvConfig, pattern: str | tuple | None = None
) -> Layout:
    """A random plan (heading, up to two turns of at most 45 degrees), a scattered start."""
    n = config.n_uavs

    def start(slots: np.ndarray, plan_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = slots + rng.uniform(-_START_SCATTER_M, _START_SCATTER_M, size=(n, 3))
        vel = plan_dir * config.cruise_speed + rng.uniform(
            -_START_SPEED_SCATTER_MPS, _START_SPEED_SCATTER_MPS, size=(n, 3)
        )
        return pos, vel

    waypoints = _random_plan(rng, config.cruise_speed * TIMELINE_S)
    return layout(config, waypoints, pattern, start)


def aimed_obstacle(
    rng: np.random.Generator,
    config: EnvConfig,
    lay: Layout,
    encounter: Encounter,
    who: int | None = None,
) -> ObstacleStart:
    """An obstacle aimed at UAV ``who``'s planned position at a random meeting time.

    Draws the meeting time, the UAV (if ``who`` is None), ``w_max``, ``vz_max``, the
    encounter's speed and heading, an altitude offset, the encounter's climb and the pilot's
    reaction lead, in that order. The obstacle starts between the ground (plus
    ``airspace.obstacle_margin``) and the ceiling: a climb that would start it outside
    them is slowed (it still meets the target on time).
    """
    meet = rng.uniform(*MEET_TIME_RANGE) * TIMELINE_S
    if who is None:
        who = int(rng.integers(config.n_uavs))
    target, plan_dir = lay.planned_at(meet)
    target = target[who]
    w_max = rng.uniform(*TURN_RATE_RANGE_RADPS)
    vz_max = rng.uniform(*CLIMB_RATE_RANGE_MPS)
    speed, heading = encounter.horizontal(rng, config, math.atan2(plan_dir[1], plan_dir[0]))
    offset = np.array([0.0, 0.0, rng.uniform(*ALTITUDE_OFFSET_RANGE_M)])
    floor, ceiling = airspace(config)
    climb = encounter.vertical(rng, vz_max)
    if climb is None:
        climb = 0.0
    else:
        offset[2] = 0.0
        target_alt = -float(target[2])
        climb = min(max(climb, (target_alt - ceiling) / meet), (target_alt - floor) / meet)
    start = target + offset.copy()
    start[:2] -= speed * np.array([math.cos(heading), math.sin(heading)]) * meet
    start[2] += climb * meet  # NED: climbing means z decreases over time
    start[2] = -min(max(-start[2], floor), ceiling)  # a no-op unless the airspace is narrow
    # As in the paper's encounter: the pilot holds course until the encounter nears.
    hold = max(0.0, meet - rng.uniform(*REACTION_LEAD_RANGE_S))
    return ObstacleStart(start, heading, speed, w_max, vz_max, climb, hold)


def obstacle_slots(
    config: EnvConfig, first: Callable[[], ObstacleStart], background: Callable[[], ObstacleStart]
) -> list[ObstacleStart]:
    """``config.n_obstacles`` obstacles: ``first()`` in slot 0, ``background()`` beyond."""
    return [first() if k == 0 else background() for k in range(config.n_obstacles)]


def assemble(
    family: str, config: EnvConfig, lay: Layout, obstacles: list[ObstacleStart]
) -> ScenarioSpec:
    """The :class:`ScenarioSpec` of a layout and its obstacles (no random draw).

    Obstacles keep to an altitude band of 60 m about the flight altitude, widened to contain
    the ones that start outside it (steep climbers), within the airspace.
    """
    m, ob = config.n_obstacles, config.obstacle

    def column(name: str) -> np.ndarray:
        return np.array([float(getattr(o, name)) for o in obstacles], dtype=float)

    pos = np.array([o.pos for o in obstacles]).reshape(m, 3)
    floor, ceiling = airspace(config)
    band = np.tile(
        [FLIGHT_ALTITUDE - _ALT_BAND_HALF_WIDTH_M, FLIGHT_ALTITUDE + _ALT_BAND_HALF_WIDTH_M], (m, 1)
    )
    alts = -pos[:, 2]
    band[:, 0] = np.maximum(np.minimum(band[:, 0], alts), floor)
    band[:, 1] = np.minimum(np.maximum(band[:, 1], alts), ceiling)
    heading = column("heading")
    return ScenarioSpec(
        family=family,
        waypoints=lay.waypoints,
        cruise_speed=config.cruise_speed,
        slots=lay.slots,
        uav_pos=lay.uav_pos,
        uav_vel=lay.uav_vel,
        obstacle_pos=pos,
        obstacle_heading=np.mod(heading + math.pi, 2 * math.pi) - math.pi,
        obstacle_speed=column("speed"),
        obstacle_turn_rate=np.zeros(m),
        obstacle_climb_rate=column("climb_rate"),
        obstacle_max_turn_rate=column("max_turn_rate"),
        obstacle_max_climb_rate=column("max_climb_rate"),
        obstacle_radius=np.full(m, ob.radius),
        obstacle_alt_band=band,
        obstacle_active=np.ones(m, dtype=bool),
        obstacle_hold_until=column("hold_until"),
        wind=np.asarray(ob.wind, dtype=float),
    )
