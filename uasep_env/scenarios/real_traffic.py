"""The ``real_traffic`` family: recorded aircraft placed to meet the formation.

Every obstacle slot replays a recorded track of the real-traffic dataset
(:mod:`uasep_env.real_traffic`; flights of ``obstacle.replay_split`` only, a distinct track
per slot) flown by :mod:`uasep_env.sim.replay`. The formation's side is a random layout as in
the synthetic families. Each obstacle is aimed, like theirs, at a random UAV's planned
position at a meeting time ``t_c`` of 60-140 s on the 200 s timeline, now with a miss
distance ``d`` of 0-10 m:

1. a stretch of a recorded track without a gap over ``obstacle.replay_max_gap`` is drawn,
   uniformly in time over the split's stretches (this is the time shift: its sample at
   ``t_c`` meets the formation), resampled every ``dt`` by linear interpolation
   (:meth:`~uasep_env.real_traffic.RealTrafficDataset.draw_segments`);
2. it is scaled about its position at ``t_c`` by ``obstacle.replay_speed_scale``, rotated
   about the vertical by a uniform angle and translated so that at ``t_c`` it is at the
   target's planned position plus a miss vector of length ``d``, perpendicular to the
   relative velocity there (its direction about that velocity uniform);
3. the placement is kept if the placed track stays between ``airspace.ground_altitude +
   airspace.obstacle_margin`` and ``airspace.ceiling_altitude`` all along, starts at least
   50 m from every UAV's planned position, and its closest approach to the target's plan is
   at ``t_c`` (no sample farther than 1 s from ``t_c`` is closer than ``d``); otherwise
   steps 1-2 are drawn again (up to 200 times).

The scenario then holds one position per physics step of the episode
(:class:`ReplaySpec`), plus where each came from. The predictor assumes a Dubins aircraft
of ``obstacle.max_turn_rate`` and ``obstacle.max_climb_rate`` at the placed track's median
speed. All draws come from the episode's generator, so a seed fixes the episode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from uasep_env.scenarios.building import (
    MEET_TIME_RANGE,
    TIMELINE_S,
    Layout,
    ObstacleStart,
    airspace,
    assemble,
    random_layout,
)
from uasep_env.scenarios.spec import ScenarioSpec
from uasep_env.sim.formation import PlannedTrajectory
from uasep_env.sim.obstacles import aircraft_class_code

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = [
    "MISS_DISTANCE_RANGE_M",
    "REAL_TRAFFIC_BANK",
    "REAL_TRAFFIC_SLOW_BANK",
    "ReplaySpec",
    "check_replay_tracks",
    "generate",
    "replay_samples",
    "usable_tracks",
]

#: The real-traffic bank's config (seeds :data:`~uasep_env.scenarios.REAL_TRAFFIC_TEST_SEEDS`):
#: recorded tracks of the test flights only, at their recorded speeds.
REAL_TRAFFIC_BANK: dict = {
    "scenario": "real_traffic",
    "obstacle": {"model": "replay", "replay_split": "test"},
}
#: The same seeds with the recorded tracks slowed to the synthetic obstacles' speeds (x0.2:
#: gliders at about 8 m/s, helicopters at 12 m/s; turn rates and timing as recorded).
REAL_TRAFFIC_SLOW_BANK: dict = {
    "scenario": "real_traffic",
    "obstacle": {"model": "replay", "replay_split": "test", "replay_speed_scale": 0.2},
}
#: Miss distance of an encounter: the placed track's closest approach to its target's plan.
MISS_DISTANCE_RANGE_M = (0.0, 10.0)
#: Least distance of a placed track's start from every UAV's planned start (m).
START_CLEARANCE_M = 50.0
#: No sample farther than this from the meeting time comes closer than the miss distance (s).
MEET_TOLERANCE_S = 1.0
#: Placements drawn before the scenario gives up (a narrow airspace, a tiny split).
MAX_PLACEMENTS = 200


@dataclass
class ReplaySpec(ScenarioSpec):
    """A :class:`ScenarioSpec` whose obstacles replay recorded tracks.

    Attributes:
        obstacle_track: ``(M, K, 3)`` each obstacle's position at every physics step from
            the reset (m, NED); ``K`` = the episode's physics steps + 1, at most the 200 s
            timeline's (:func:`replay_samples`).
        obstacle_replay: ``(M,)`` which slots replay their track (all).
        obstacle_track_index: ``(M,)`` the tracks' indices in the dataset.
        obstacle_track_start: ``(M,)`` time into each track at the reset (s).
        obstacle_rotation: ``(M,)`` the angle each track is rotated by about the vertical
            (rad, from north towards east); it is scaled by ``obstacle.replay_speed_scale``
            about its position at the meeting time first.
        obstacle_target: ``(M,)`` the UAV each is aimed at.
        obstacle_meet_time: ``(M,)`` the time of its closest approach to the target's plan (s).
        obstacle_miss_distance: ``(M,)`` the distance then (m).

    :attr:`obstacle_aircraft_class` gives the recorded tracks' class codes
    (:data:`uasep_env.sim.obstacles.AIRCRAFT_CLASSES`).
    """

    obstacle_track: np.ndarray
    obstacle_replay: np.ndarray
    obstacle_track_index: np.ndarray
    obstacle_track_start: np.ndarray
    obstacle_rotation: np.ndarray
    obstacle_target: np.ndarray
    obstacle_meet_time: np.ndarray
    obstacle_miss_distance: np.ndarray

    @property
    def obstacle_aircraft_class(self) -> np.ndarray:
        """``(M,)`` the recorded tracks' class codes (from the dataset, not a drawn field)."""
        tracks = _dataset().tracks
        return np.array(
            [aircraft_class_code(tracks[int(i)].aircraft_class) for i in self.obstacle_track_index],
            dtype=np.int64,
        )


def _dataset():  # noqa: ANN202 -- the dataset, loaded on first use (cached by the loader)
    from uasep_env import real_traffic

    return real_traffic.load()


def _durations(config: EnvConfig) -> tuple[int, float]:
    """``K`` (samples of the episode's track) and the length of the stretch drawn (s).

    The stretch is the 200 s timeline, whatever the episode's length: a shorter episode is
    the start of the same encounter (as in the synthetic families), and in a longer one the
    obstacle flies on level at its last horizontal velocity (:mod:`uasep_env.sim.replay`).
    """
    n = round(TIMELINE_S / config.dt)
    return min(config.max_steps * config.decision_interval, n) + 1, n * config.dt


def replay_samples(config: EnvConfig) -> int:
    """Samples of each replayed track: one per physics step, up to the 200 s timeline."""
    return _durations(config)[0]


@lru_cache(maxsize=32)
def usable_tracks(split: str, duration: float, max_gap: float) -> tuple[int, ...]:
    """Dataset indices of ``split``'s tracks with ``duration`` s without a longer gap."""
    out = []
    for tr in _dataset().select(split):
        cuts = np.flatnonzero(np.diff(tr.times) > max_gap)
        lo = np.concatenate([[0], cuts + 1])
        hi = np.concatenate([cuts, [len(tr.times) - 1]])
        if any(tr.times[b] - tr.times[a] >= duration for a, b in zip(lo, hi, strict=True)):
            out.append(tr.index)
    return tuple(out)


def check_replay_tracks(config: EnvConfig) -> None:
    """Raise unless ``config.obstacle.replay_split`` holds a distinct track per obstacle slot.

    Raises:
        ValueError: Naming ``n_obstacles`` and the split, with how many tracks it holds.
    """
    ob = config.obstacle
    _, duration = _durations(config)
    have = len(usable_tracks(ob.replay_split, duration, ob.replay_max_gap))
    if config.n_obstacles > have:
        raise ValueError(
            f"invalid config value n_obstacles={config.n_obstacles!r}: the 'real_traffic' "
            f"scenario flies a distinct recorded track per obstacle, and "
            f"obstacle.replay_split={ob.replay_split!r} holds {have} with {duration:g} s "
            f"without a gap over obstacle.replay_max_gap={ob.replay_max_gap:g} s"
        )


def _plan_samples(lay: Layout, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every UAV's planned position and velocity at each of ``times``: ``(T, N, 3)`` each."""
    plan = PlannedTrajectory(np.repeat(lay.plan.waypoints, len(times), 0), lay.plan.cruise_speed)
    pos, vel = plan.uav_positions(times, np.repeat(lay.slots[None], len(times), 0))
    return pos, np.array(vel)


def _perpendicular(u: np.ndarray, angle: float) -> np.ndarray:
    """The unit vector at ``angle`` about ``u`` in the plane perpendicular to it."""
    n = np.linalg.norm(u)
    u = u / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(u, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:  # a vertical relative velocity
        e1 = np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    return math.cos(angle) * e1 + math.sin(angle) * e2


def _replayed(
    rng: np.random.Generator,
    config: EnvConfig,
    lay: Layout,
    plan: tuple[np.ndarray, np.ndarray],
    used: list[int],
) -> tuple[ObstacleStart, dict]:
    """One obstacle replaying a track placed to meet the formation (see the module)."""
    ob, dt = config.obstacle, config.dt
    k_ep, duration = _durations(config)
    j_c = round(rng.uniform(*MEET_TIME_RANGE) * TIMELINE_S / dt)
    who = int(rng.integers(config.n_uavs))
    miss = rng.uniform(*MISS_DISTANCE_RANGE_M)
    plan_pos, plan_vel = plan
    target = plan_pos[:, who]
    floor, ceiling = airspace(config)
    times = dt * np.arange(len(target))
    away = np.abs(times - j_c * dt) > MEET_TOLERANCE_S
    for _ in range(MAX_PLACEMENTS):
        seg = _dataset().draw_segments(
            rng, 1, duration, dt, split=ob.replay_split, max_gap=ob.replay_max_gap
        )
        theta, phi = rng.uniform(-math.pi, math.pi, size=2)
        track = int(seg.track[0])
        if track in used:
            continue
        q = (seg.positions[0] - seg.positions[0, j_c]) * ob.replay_speed_scale
        c, s = math.cos(theta), math.sin(theta)
        q = q @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # rows rotated by theta
        rel_vel = (q[j_c + 1] - q[j_c - 1]) / (2 * dt) - plan_vel[j_c, who]
        pos = q + target[j_c] + miss * _perpendicular(rel_vel, phi)
        alt = -pos[:, 2]
        dist = np.linalg.norm(pos - target, axis=-1)
        start_gap = np.linalg.norm(plan_pos[0] - pos[0], axis=-1).min()
        if (
            alt.min() >= floor
            and alt.max() <= ceiling
            and start_gap >= START_CLEARANCE_M
            and (dist[away] > miss).all()
        ):
            used.append(track)
            break
    else:
        raise ValueError(
            f"the 'real_traffic' scenario placed no track of obstacle.replay_split="
            f"{ob.replay_split!r} in {MAX_PLACEMENTS} draws between airspace.ground_altitude"
            f" + airspace.obstacle_margin ({floor:g} m) and airspace.ceiling_altitude "
            f"({ceiling:g} m) (obstacle.replay_speed_scale={ob.replay_speed_scale:g})"
        )
    vel = (pos[1] - pos[0]) / dt
    air = np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=-1) / dt  # the whole stretch
    start = ObstacleStart(
        pos=pos[0],
        heading=math.atan2(vel[1], vel[0]),
        speed=max(float(np.median(air)), 0.1),  # shapes the predicted reachable set
        max_turn_rate=ob.max_turn_rate,
        max_climb_rate=ob.max_climb_rate,
        climb_rate=-float(vel[2]),
        hold_until=0.0,
    )
    info = {
        "track": pos[:k_ep],
        "index": track,
        "start": float(seg.start[0]),
        "rotation": float(theta),
        "target": who,
        "meet": j_c * dt,
        "miss": miss,
    }
    return start, info


def generate(rng: np.random.Generator, config: EnvConfig) -> ReplaySpec:
    """One ``real_traffic`` episode (the family's generator)."""
    check_replay_tracks(config)
    lay = random_layout(rng, config)
    k_ep, duration = _durations(config)
    # The samples draw_segments gives a stretch of `duration` (its own rounding).
    n_samples = int(np.floor(duration / config.dt + 1e-9)) + 1
    plan = _plan_samples(lay, config.dt * np.arange(n_samples))
    used: list[int] = []
    placed = [_replayed(rng, config, lay, plan, used) for _ in range(config.n_obstacles)]
    spec = assemble("real_traffic", config, lay, [p[0] for p in placed])
    m = config.n_obstacles

    def column(key: str, dtype: type = float) -> np.ndarray:
        return np.array([p[1][key] for p in placed], dtype=dtype).reshape(m)

    return ReplaySpec(
        **vars(spec),
        obstacle_track=np.array([p[1]["track"] for p in placed]).reshape(m, k_ep, 3),
        obstacle_replay=np.ones(m, dtype=bool),
        obstacle_track_index=column("index", int),
        obstacle_track_start=column("start"),
        obstacle_rotation=column("rotation"),
        obstacle_target=column("target", int),
        obstacle_meet_time=column("meet"),
        obstacle_miss_distance=column("miss"),
    )
