"""Scenarios: the paper's encounter and seeded families of random encounters.

A scenario turns a :class:`numpy.random.Generator` and the config into one episode's
initial conditions (:class:`ScenarioSpec`): the planned trajectory, the UAVs' initial
states, and every obstacle's initial state and performance. All randomness comes from the
generator passed in, so a seed fixes the episode.

Families (``EnvConfig.scenario``):

* ``paper`` -- section 4: three UAVs in line abreast (slots ``[-20,0,0], [20,0,0],
  [0,0,0]``) set out from scattered positions with different velocities, form up, and fly
  north at 100 m altitude; an obstacle (4 m/s, ``w_max`` = 0.013 rad/s, the paper's values)
  comes towards them from the north-north-east and crosses their track, 5 m below them,
  aimed at the middle UAV's planned position at t = 115 s (the paper's encounter is at
  100-130 s). Its pilot flies straight until 25 s before the encounter and manoeuvres at
  random from then on; only those manoeuvres and the noise depend on the seed.
* ``crossing`` / ``head_on`` / ``overtaking`` / ``climbing`` -- one obstacle aimed at a random
  UAV's planned position at a random time, from the side, the front, behind (faster than
  the formation) or from above/below while climbing or descending.
* ``multi_obstacle`` -- every obstacle slot aimed at the formation, each from a random family.
* ``large_formation`` -- a crossing encounter through the middle of a wedge/grid formation
  (use with ``n_uavs`` >= 6).
* ``random`` -- a family drawn uniformly per episode from the five above.

In every family, obstacle slots beyond the first are background traffic aimed at the
formation at other times. Every obstacle holds its initial course until 10-40 s before its
encounter (drawn per obstacle; 25 s in ``paper``) and then manoeuvres at random, so that
encounters happen and their outcome is uncertain. Random planned trajectories have a random
heading and up to two turns of at most 45 degrees.

The encounters' timing does not depend on ``episode_duration``: they are laid out on the
default 200 s timeline (meetings at 60-140 s, the paper's at 115 s), so a shorter episode is
the start of the same encounter and a longer one flies on along the plan's last leg. No
scenario starts with two UAVs within ``uav.separation_distance`` (the start scatter is shrunk
towards the formation slots when a draw would) or an obstacle near a UAV (obstacles start
at least a minute's flight from their encounter).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.formation import PlannedTrajectory, pattern_slots
from uasep_env.obstacles import ObstacleState

__all__ = [
    "HELD_OUT_PAPER_SEEDS",
    "HELD_OUT_SEEDS",
    "N_WAYPOINTS",
    "RANDOM_FAMILIES",
    "SCENARIO_DEFAULTS",
    "TRAINING_SEEDS",
    "VALIDATION_SEEDS",
    "ScenarioSpec",
    "check_training_seeds",
    "place_obstacles",
    "sample_scenario",
]

#: Way-points of every planned trajectory (shorter plans are padded with their end point).
N_WAYPOINTS = 4
#: Families drawn by the ``random`` scenario.
RANDOM_FAMILIES = ("crossing", "head_on", "overtaking", "climbing", "multi_obstacle")
#: Config a family is meant to be flown with, applied where a scenario is chosen by name
#: (the gym id ``uasep/LargeFormation-v1``, ``uasep-eval --scenario``), before overrides.
SCENARIO_DEFAULTS: dict[str, dict] = {
    "large_formation": {"n_uavs": 8, "formation": "wedge", "n_obstacles": 2},
}

# Seed ranges of learned baselines: training, validation and the held-out bank never meet.
#: Seeds training environments may be created with (environment ``e`` of a batch seeded
#: ``seed`` starts from ``seed + e`` and then continues its own generator).
TRAINING_SEEDS = range(0, 1_000_000)
#: Seeds of the encounters a training run checks itself on (``random`` scenario).
VALIDATION_SEEDS = range(4_000_000, 4_001_000)
#: The held-out bank: 500 ``random`` encounters (crossing, head-on, overtaking, climbing,
#: multi-obstacle), the seeds every controller is compared on and training never draws.
HELD_OUT_SEEDS = range(5_000_000, 5_000_500)
#: The held-out bank's ``paper`` scenario runs (noise and the pilot's late manoeuvres).
HELD_OUT_PAPER_SEEDS = range(5_000_000, 5_000_020)


def check_training_seeds(seed: int, n_envs: int) -> None:
    """Raise ``ValueError`` unless ``[seed, seed + n_envs)`` lies in :data:`TRAINING_SEEDS`."""
    if not (
        isinstance(seed, int)
        and seed >= TRAINING_SEEDS.start
        and seed + n_envs <= TRAINING_SEEDS.stop
    ):
        raise ValueError(
            f"seed={seed!r}: training seeds [seed, seed + n_envs) must lie in "
            f"[{TRAINING_SEEDS.start}, {TRAINING_SEEDS.stop}), disjoint from the held-out bank"
        )


# Ranges of the random families (units in the names).
_SPEED_RANGE_MPS = (3.0, 12.0)
_TURN_RATE_RANGE_RADPS = (0.01, 0.15)
_CLIMB_RATE_RANGE_MPS = (0.2, 2.0)
# Encounters are laid out on a fixed timeline, whatever the episode's length: a shorter
# episode is the first part of the same encounter, a longer one flies on along the last leg.
_TIMELINE_S = 200.0  # the default episode_duration
_MEET_TIME_RANGE_S = (0.3, 0.7)  # fraction of the timeline
_REACTION_LEAD_RANGE_S = (10.0, 40.0)  # the pilot starts manoeuvring this long before
_ALTITUDE_M = 100.0
_ALT_BAND_HALF_WIDTH_M = 60.0
_START_SCATTER_M = 8.0
_START_SPEED_SCATTER_MPS = 1.0

# The paper's encounter (section 4; constants chosen here, the paper gives none).
_PAPER_MEET_TIME_S = 115.0
_PAPER_OBSTACLE_BELOW_M = 10.0
_PAPER_REACTION_LEAD_S = 25.0  # the obstacle's pilot starts manoeuvring 25 s before
_PAPER_OBSTACLE_HEADING_RAD = np.pi + 0.35  # south-south-west: crosses the track east to west
_PAPER_START = np.array(  # initial positions relative to the planned slots (m, NED)
    [[-12.0, -9.0, 4.0], [-4.0, 7.0, -5.0], [-18.0, 6.0, 2.0]]
)
_PAPER_START_VEL = np.array([[4.0, 1.0, 0.0], [5.5, -1.0, 0.5], [3.0, 0.0, -0.3]])  # m/s


@dataclass
class ScenarioSpec:
    """Initial conditions of one episode (NED, SI units).

    Attributes:
        family: Name of the family that generated it.
        waypoints: ``(N_WAYPOINTS, 3)`` planned trajectory of the formation centre (m).
        cruise_speed: Speed along it (m/s).
        slots: ``(n_uavs, 3)`` formation pattern (m, formation frame).
        uav_pos: ``(n_uavs, 3)`` initial positions (m).
        uav_vel: ``(n_uavs, 3)`` initial velocities (m/s).
        obs_pos: ``(M, 3)`` obstacle positions (m).
        obs_heading: ``(M,)`` headings (rad from north towards east).
        obs_speed: ``(M,)`` horizontal airspeeds (m/s).
        obs_turn_rate: ``(M,)`` initial turn commands (rad/s).
        obs_climb_rate: ``(M,)`` initial climb commands, positive up (m/s).
        obs_max_turn_rate: ``(M,)`` ``w_max`` (rad/s).
        obs_max_climb_rate: ``(M,)`` ``vz_max`` (m/s).
        obs_radius: ``(M,)`` safety radii (m).
        obs_alt_band: ``(M, 2)`` altitude bands (m, positive up).
        obs_active: ``(M,)`` slots in use.
        obs_hold_until: ``(M,)`` time before which the pilot keeps the initial commands (s).
        wind: ``(3,)`` steady wind (m/s, NED).
    """

    family: str
    waypoints: np.ndarray
    cruise_speed: float
    slots: np.ndarray
    uav_pos: np.ndarray
    uav_vel: np.ndarray
    obs_pos: np.ndarray
    obs_heading: np.ndarray
    obs_speed: np.ndarray
    obs_turn_rate: np.ndarray
    obs_climb_rate: np.ndarray
    obs_max_turn_rate: np.ndarray
    obs_max_climb_rate: np.ndarray
    obs_radius: np.ndarray
    obs_alt_band: np.ndarray
    obs_active: np.ndarray
    obs_hold_until: np.ndarray
    wind: np.ndarray


def _straight_plan(start: np.ndarray, heading: float, length: float) -> np.ndarray:
    d = np.array([math.cos(heading), math.sin(heading), 0.0])
    pts = [start + d * length * k / (N_WAYPOINTS - 1) for k in range(N_WAYPOINTS)]
    return np.array(pts)


def _random_plan(rng: np.random.Generator, length: float) -> np.ndarray:
    heading = rng.uniform(-math.pi, math.pi)
    turns = rng.uniform(-math.pi / 4, math.pi / 4, size=N_WAYPOINTS - 2)
    turns *= rng.random(N_WAYPOINTS - 2) < 0.5  # about half the legs are straight
    fractions = np.sort(rng.uniform(0.2, 0.8, size=N_WAYPOINTS - 2))
    legs = np.diff(np.concatenate([[0.0], fractions, [1.0]])) * length
    pts = [np.array([0.0, 0.0, -_ALTITUDE_M])]
    h = heading
    for k, leg in enumerate(legs):
        if k > 0:
            h += turns[k - 1]
        pts.append(pts[-1] + leg * np.array([math.cos(h), math.sin(h), 0.0]))
    return np.array(pts)


def _planned_uav(plan: PlannedTrajectory, t: float, slots: np.ndarray) -> np.ndarray:
    pos, _ = plan.uav_positions(np.array([t]), slots[None])
    return pos[0]


def _aim(
    rng: np.random.Generator,
    family: str,
    target: np.ndarray,
    plan_dir: np.ndarray,
    meet_time: float,
    config: EnvConfig,
) -> tuple[np.ndarray, float, float, float, float, float]:
    """Obstacle start, heading, speed, w_max, vz_max, climb so that it meets ``target``."""
    plan_heading = math.atan2(plan_dir[1], plan_dir[0])
    w_max = rng.uniform(*_TURN_RATE_RANGE_RADPS)
    vz_max = rng.uniform(*_CLIMB_RATE_RANGE_MPS)
    climb = 0.0
    if family == "head_on":
        speed = rng.uniform(*_SPEED_RANGE_MPS)
        heading = plan_heading + math.pi + rng.uniform(-0.35, 0.35)
    elif family == "overtaking":
        speed = config.cruise_speed + rng.uniform(3.0, 8.0)
        heading = plan_heading + rng.uniform(-0.25, 0.25)
    else:  # crossing, climbing: from either side
        speed = rng.uniform(*_SPEED_RANGE_MPS)
        side = 1.0 if rng.random() < 0.5 else -1.0
        heading = plan_heading + side * rng.uniform(math.pi / 4, 3 * math.pi / 4)
    offset = np.array([0.0, 0.0, rng.uniform(-8.0, 8.0)])
    if family == "climbing":
        climb = (1.0 if rng.random() < 0.5 else -1.0) * vz_max
        offset[2] = 0.0
    horiz = speed * np.array([math.cos(heading), math.sin(heading)])
    start = target + offset.copy()
    start[:2] -= horiz * meet_time
    start[2] += climb * meet_time  # NED: climbing means z decreases over time
    return start, heading, speed, w_max, vz_max, climb


def _separated_start(slots: np.ndarray, pos: np.ndarray, separation: float) -> np.ndarray:
    """``pos`` with its scatter about ``slots`` shrunk until no two UAVs are within ``separation``.

    The largest of the factors 1, 0.95, ..., 0 that separates them (1 for most draws, which
    are then unchanged); no random draw, so the generator's stream is the same either way.
    """
    scatter = pos - slots
    for f in np.linspace(1.0, 0.0, 21):
        cand = slots + f * scatter if f < 1.0 else pos
        d = np.linalg.norm(cand[:, None] - cand[None], axis=-1)
        d[np.diag_indices(len(d))] = np.inf
        if d.min() >= separation:
            return cand
    return slots + 0.0  # the pattern itself is tighter than the separation distance


def sample_scenario(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    """Draw one episode's initial conditions.

    Args:
        rng: The episode's generator (all randomness comes from it).
        config: The environment config.

    Returns:
        The scenario.
    """
    n, m = config.n_uavs, config.n_obstacles
    family = config.scenario
    if family == "random":
        family = RANDOM_FAMILIES[int(rng.integers(len(RANDOM_FAMILIES)))]
    length = config.cruise_speed * _TIMELINE_S
    pattern = config.formation
    if family == "large_formation" and pattern == "paper":
        pattern = "wedge"
    slots = pattern_slots(pattern, n, config.formation_spacing)

    if config.scenario == "paper":
        waypoints = _straight_plan(np.array([0.0, 0.0, -_ALTITUDE_M]), 0.0, length)
    else:
        waypoints = _random_plan(rng, length)
    if config.episode_duration > _TIMELINE_S:  # fly on along the last leg
        last = waypoints[-1] - waypoints[-2]
        extra = config.cruise_speed * (config.episode_duration - _TIMELINE_S)
        waypoints[-1] += last / np.linalg.norm(last) * extra
    plan = PlannedTrajectory(waypoints[None], config.cruise_speed)
    start_slots = _planned_uav(plan, 0.0, slots)
    plan_dir0 = plan.direction[0, 0]

    if family == "paper":
        scatter = np.resize(_PAPER_START, (n, 3))
        uav_pos = start_slots + scatter
        uav_vel = np.resize(_PAPER_START_VEL, (n, 3)).copy()
        uav_vel *= min(1.0, config.uav.max_speed / 6.0)
    else:
        uav_pos = start_slots + rng.uniform(-_START_SCATTER_M, _START_SCATTER_M, size=(n, 3))
        uav_vel = plan_dir0 * config.cruise_speed + rng.uniform(
            -_START_SPEED_SCATTER_MPS, _START_SPEED_SCATTER_MPS, size=(n, 3)
        )
    uav_pos = _separated_start(start_slots, uav_pos, config.uav.separation_distance)

    ob = config.obstacle
    obs_pos = np.zeros((m, 3))
    obs_heading = np.zeros(m)
    obs_speed = np.full(m, ob.speed)
    obs_turn = np.zeros(m)
    obs_climb = np.zeros(m)
    obs_hold = np.zeros(m)
    obs_wmax = np.full(m, ob.max_turn_rate)
    obs_vzmax = np.full(m, ob.max_climb_rate)
    for k in range(m):
        if k == 0 and family == "paper":
            meet = min(_PAPER_MEET_TIME_S, 0.575 * _TIMELINE_S)  # 115 s, as its float was
            target = _planned_uav(plan, meet, slots)[n - 1 if n == 3 else n // 2]
            heading = _PAPER_OBSTACLE_HEADING_RAD
            start = target + np.array([0.0, 0.0, _PAPER_OBSTACLE_BELOW_M])
            start[:2] -= ob.speed * meet * np.array([math.cos(heading), math.sin(heading)])
            obs_pos[k], obs_heading[k] = start, heading
            # The pilot flies straight until the encounter draws near, then reacts at random.
            obs_hold[k] = max(0.0, meet - _PAPER_REACTION_LEAD_S)
            continue
        if k == 0 and family in ("crossing", "head_on", "overtaking", "climbing"):
            sub = family
        elif k == 0 and family == "large_formation":
            sub = "crossing"
        else:
            sub = ("crossing", "head_on", "overtaking", "climbing")[int(rng.integers(4))]
        frac = rng.uniform(*_MEET_TIME_RANGE_S)
        meet = frac * _TIMELINE_S
        if family == "large_formation" and k == 0:
            who = int(np.argmin(np.linalg.norm(slots, axis=1)))
        else:
            who = int(rng.integers(n))
        planned_at_meet = _planned_uav(plan, meet, slots)[who]
        direction = plan.heading_velocity(np.array([meet]))[0]
        start, heading, speed, w_max, vz_max, climb = _aim(
            rng, sub, planned_at_meet, direction, meet, config
        )
        obs_pos[k], obs_heading[k], obs_speed[k] = start, heading, speed
        obs_wmax[k], obs_vzmax[k], obs_climb[k] = w_max, vz_max, climb
        # As in the paper's encounter: the pilot holds course until the encounter nears.
        obs_hold[k] = max(0.0, meet - rng.uniform(*_REACTION_LEAD_RANGE_S))
    alt_band = np.tile(
        [_ALTITUDE_M - _ALT_BAND_HALF_WIDTH_M, _ALTITUDE_M + _ALT_BAND_HALF_WIDTH_M], (m, 1)
    )
    # Obstacles starting outside the band (steep climbers) get a band that contains them.
    alts = -obs_pos[:, 2]
    alt_band[:, 0] = np.minimum(alt_band[:, 0], alts)
    alt_band[:, 1] = np.maximum(alt_band[:, 1], alts)
    return ScenarioSpec(
        family=family,
        waypoints=waypoints,
        cruise_speed=config.cruise_speed,
        slots=slots,
        uav_pos=uav_pos,
        uav_vel=uav_vel,
        obs_pos=obs_pos,
        obs_heading=np.mod(obs_heading + math.pi, 2 * math.pi) - math.pi,
        obs_speed=obs_speed,
        obs_turn_rate=obs_turn,
        obs_climb_rate=obs_climb,
        obs_max_turn_rate=obs_wmax,
        obs_max_climb_rate=obs_vzmax,
        obs_radius=np.full(m, ob.radius),
        obs_alt_band=alt_band,
        obs_active=np.ones(m, dtype=bool),
        obs_hold_until=obs_hold,
        wind=np.asarray(ob.wind, dtype=float),
    )


#: The obstacle state's per-obstacle fields that a :class:`ScenarioSpec` gives (``obs_*``).
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
        mask: ``(E,)`` bool; the environments starting an episode.
        specs: One spec per selected environment, in order.
        config: The configuration (how often and how the pilots change their commands).
    """
    for name in _OBSTACLE_FIELDS:
        getattr(obstacles, name)[mask] = np.stack([getattr(s, "obs_" + name) for s in specs])
    obstacles.switch_prob[mask] = min(1.0, config.dt / config.obstacle.mean_switch_time)
    obstacles.straight_prob[mask] = config.obstacle.straight_probability
    obstacles.wind[mask] = np.stack([s.wind for s in specs])
