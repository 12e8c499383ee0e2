"""The scenario families, each one registered object: its generator and its documentation.

This file is the one place families are declared and registered (in the order
``EnvConfig.scenario``'s names are listed). A family's generator builds its episode from
the shared blocks of :mod:`uasep_env.scenarios.building`; an encounter kind (how an
obstacle approaches the UAV it is aimed at, with its documentation) is an
:class:`~uasep_env.scenarios.building.Encounter` in :data:`ENCOUNTERS`, and each is also a
family of one such encounter. Two mixes are declared here, once: :data:`RANDOM_MIX` (the families
the ``random`` scenario draws per episode) and :data:`TRAFFIC_MIX` (the encounter kinds of
background traffic and of ``multi_obstacle``). Adding a family: an entry in
:data:`ENCOUNTERS` (for one encounter of a new kind) or a generator registered below; add it
to a mix only if ``random`` should draw it (that moves every bank: see ``tests/test_banks.py``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.scenarios import real_traffic as _real_traffic
from uasep_env.scenarios.batched import DrawTables, EpisodeDraws, draw_encounters, draw_tables
from uasep_env.scenarios.building import (
    SPEED_RANGE_MPS,
    TIMELINE_S,
    Encounter,
    EncounterDraws,
    Layout,
    ObstacleStart,
    aimed_obstacle,
    airspace,
    assemble,
    layout,
    obstacle_slots,
    random_layout,
    straight_plan,
)
from uasep_env.scenarios.registry import FAMILIES, Mix, ScenarioFamily, register
from uasep_env.scenarios.spec import ScenarioSpec
from uasep_env.sim.formation import pattern_slots

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = ["ENCOUNTERS", "RANDOM_MIX", "TRAFFIC_MIX"]


# ---- Encounter kinds: how an obstacle approaches its target ---------------------------------
def _from_either_side(
    rng: np.random.Generator, config: EnvConfig, plan_heading: float
) -> tuple[float, float]:
    speed = rng.uniform(*SPEED_RANGE_MPS)
    side = 1.0 if rng.random() < 0.5 else -1.0
    return speed, plan_heading + side * rng.uniform(math.pi / 4, 3 * math.pi / 4)


def _from_the_front(
    rng: np.random.Generator, config: EnvConfig, plan_heading: float
) -> tuple[float, float]:
    speed = rng.uniform(*SPEED_RANGE_MPS)
    return speed, plan_heading + math.pi + rng.uniform(-0.35, 0.35)


def _from_behind(
    rng: np.random.Generator, config: EnvConfig, plan_heading: float
) -> tuple[float, float]:
    speed = config.cruise_speed + rng.uniform(3.0, 8.0)  # faster than the formation
    return speed, plan_heading + rng.uniform(-0.25, 0.25)


def _level(rng: np.random.Generator, vz_max: float) -> float | None:
    return None


def _climbing_or_descending(rng: np.random.Generator, vz_max: float) -> float | None:
    return (1.0 if rng.random() < 0.5 else -1.0) * vz_max


_MEETS = "Meets a random UAV's plan at 60-140 s; "
_CLIMBING = (
    "climbing or descending at `vz_max` (slower where it would start below ground + "
    "`airspace.obstacle_margin` or above the ceiling)."
)

#: The kinds of encounter; each is also a family of one such encounter (registered below).
ENCOUNTERS: dict[str, Encounter] = {
    "crossing": Encounter(
        horizontal=_from_either_side,
        vertical=_level,
        summary="An obstacle crosses the formation's track from either side.",
        parameters=_MEETS + "speed 3-12 m/s, 45-135° off the track, altitude ±8 m.",
        draws=EncounterDraws(
            speed=SPEED_RANGE_MPS, either_side=True, turn=(math.pi / 4, 3 * math.pi / 4)
        ),
    ),
    "head_on": Encounter(
        horizontal=_from_the_front,
        vertical=_level,
        summary="An obstacle comes head-on.",
        parameters=_MEETS + "speed 3-12 m/s, within ±20° of head-on, altitude ±8 m.",
        draws=EncounterDraws(speed=SPEED_RANGE_MPS, heading_offset=math.pi, turn=(-0.35, 0.35)),
    ),
    "overtaking": Encounter(
        horizontal=_from_behind,
        vertical=_level,
        summary="A faster obstacle overtakes the formation from behind.",
        parameters=_MEETS + "speed cruise + 3-8 m/s, within ±14° of the track, altitude ±8 m.",
        draws=EncounterDraws(speed=(3.0, 8.0), above_cruise=True, turn=(-0.25, 0.25)),
    ),
    "climbing": Encounter(
        horizontal=_from_either_side,
        vertical=_climbing_or_descending,
        summary="An obstacle climbs or descends through the formation's altitude.",
        parameters=_MEETS + "speed 3-12 m/s, 45-135° off the track, " + _CLIMBING,
        draws=EncounterDraws(
            speed=SPEED_RANGE_MPS,
            either_side=True,
            turn=(math.pi / 4, 3 * math.pi / 4),
            climbs=True,
        ),
    ),
}

#: The encounter kinds of background traffic (and of every ``multi_obstacle`` slot).
TRAFFIC_MIX = Mix(weights={"crossing": 1, "head_on": 1, "overtaking": 1, "climbing": 1})


def _background(rng: np.random.Generator, config: EnvConfig, lay: Layout) -> ObstacleStart:
    """Traffic aimed at a random UAV at another time, of a kind drawn from TRAFFIC_MIX."""
    kind = TRAFFIC_MIX.draw(rng)
    return aimed_obstacle(rng, config, lay, ENCOUNTERS[kind])


def _encounter(kind: str) -> ScenarioFamily:
    """The family of one encounter of ``kind`` aimed at a random UAV, plus background."""
    encounter = ENCOUNTERS[kind]

    def generate(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
        lay = random_layout(rng, config)
        obstacles = obstacle_slots(
            config,
            lambda: aimed_obstacle(rng, config, lay, encounter),
            lambda: _background(rng, config, lay),
        )
        return assemble(kind, config, lay, obstacles)

    def draws(rng: np.random.Generator, config: EnvConfig) -> EpisodeDraws:
        return draw_encounters(kind, config, rng, encounter, TRAFFIC_MIX, ENCOUNTERS)

    return ScenarioFamily(
        name=kind,
        summary=encounter.summary,
        parameters=encounter.parameters,
        generate=generate,
        **_batched_form(draws, _tables_of(kind) if kind in RANDOM_MIX.names else None),
    )


# ---- The paper's encounter (section 4; constants chosen here, the paper gives none) ---------
_PAPER_MEET_TIME_S = 115.0
_PAPER_OBSTACLE_BELOW_M = 10.0
_PAPER_REACTION_LEAD_S = 25.0  # the obstacle's pilot starts manoeuvring 25 s before
_PAPER_OBSTACLE_HEADING_RAD = np.pi + 0.35  # south-south-west: crosses the track east to west
_PAPER_START = np.array(  # initial positions relative to the planned slots (m, NED)
    [[-12.0, -9.0, 4.0], [-4.0, 7.0, -5.0], [-18.0, 6.0, 2.0]]
)
_PAPER_START_VEL = np.array([[4.0, 1.0, 0.0], [5.5, -1.0, 0.5], [3.0, 0.0, -0.3]])  # m/s


def _paper(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    n, ob = config.n_uavs, config.obstacle

    def start(slots: np.ndarray, plan_dir: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        vel = np.resize(_PAPER_START_VEL, (n, 3)).copy()
        vel *= min(1.0, config.uav.max_speed / 6.0)
        return slots + np.resize(_PAPER_START, (n, 3)), vel

    lay = layout(config, straight_plan(config), start=start)

    def first() -> ObstacleStart:
        meet = min(_PAPER_MEET_TIME_S, 0.575 * TIMELINE_S)  # 115 s, as its float was
        target = lay.planned_at(meet)[0][n - 1 if n == 3 else n // 2]
        heading = _PAPER_OBSTACLE_HEADING_RAD
        pos = target + np.array([0.0, 0.0, _PAPER_OBSTACLE_BELOW_M])
        pos[:2] -= ob.speed * meet * np.array([math.cos(heading), math.sin(heading)])
        floor, ceiling = airspace(config)
        pos[2] = -min(max(-pos[2], floor), ceiling)  # a no-op unless the airspace is narrow
        # The pilot flies straight until the encounter draws near, then reacts at random.
        hold = max(0.0, meet - _PAPER_REACTION_LEAD_S)
        return ObstacleStart(pos, heading, ob.speed, ob.max_turn_rate, ob.max_climb_rate, 0.0, hold)

    obstacles = obstacle_slots(config, first, lambda: _background(rng, config, lay))
    return assemble("paper", config, lay, obstacles)


def _multi_obstacle(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    lay = random_layout(rng, config)
    obstacles = obstacle_slots(
        config, lambda: _background(rng, config, lay), lambda: _background(rng, config, lay)
    )
    return assemble("multi_obstacle", config, lay, obstacles)


def _multi_obstacle_draws(rng: np.random.Generator, config: EnvConfig) -> EpisodeDraws:
    return draw_encounters("multi_obstacle", config, rng, None, TRAFFIC_MIX, ENCOUNTERS)


def _large_formation_draws(rng: np.random.Generator, config: EnvConfig) -> EpisodeDraws:
    pattern = "wedge" if config.formation == "paper" else config.formation
    slots = pattern_slots(pattern, config.n_uavs, config.formation_spacing)
    middle = int(np.argmin(np.linalg.norm(slots, axis=1)))
    crossing = ENCOUNTERS["crossing"]
    return draw_encounters(
        "large_formation", config, rng, crossing, TRAFFIC_MIX, ENCOUNTERS, pattern, middle
    )


def _batched(*encounters: Encounter) -> bool:
    """Whether every one of ``encounters`` declares its draws (a batched form is possible)."""
    return all(e.draws is not None for e in encounters)


def _batched_form(
    draws: Callable[..., EpisodeDraws],
    tables: Callable[[], tuple[DrawTables, int]] | None = None,
) -> dict[str, Any]:
    """A family's ``ScenarioFamily.draws`` and ``draw_tables``, as keyword arguments.

    ``None`` both unless every encounter kind declares its draws (its background traffic
    may be of any kind).
    """
    if not _batched(*ENCOUNTERS.values()):
        return {"draws": None, "draw_tables": None}
    return {"draws": draws, "draw_tables": tables}


def _large_formation(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    lay = random_layout(rng, config, "wedge" if config.formation == "paper" else None)
    middle = int(np.argmin(np.linalg.norm(lay.slots, axis=1)))
    obstacles = obstacle_slots(
        config,
        lambda: aimed_obstacle(rng, config, lay, ENCOUNTERS["crossing"], who=middle),
        lambda: _background(rng, config, lay),
    )
    return assemble("large_formation", config, lay, obstacles)


# ---- Collision courses: encounters that end in a collision unless the formation avoids ------
_COLLISION_MEET_RANGE = (0.45, 0.6)  # fraction of the episode (at most the 200 s timeline)
_COLLISION_MIN_MEET_S = 20.0  # so that no short episode starts inside the separation
_COLLISION_HEADINGS = {  # the obstacle's heading relative to the plan's (rad), by kind
    "head_on": lambda rng: math.pi,
    "crossing": lambda rng: (1.0 if rng.random() < 0.5 else -1.0) * math.pi / 2,
}


def _collision_course(kind: str) -> ScenarioFamily:
    """A non-manoeuvring obstacle aimed exactly at a UAV's planned position, at its altitude.

    Safety tests need encounters that plan tracking alone does not survive: the paper's
    obstacle passes 10 m below the formation, and every drawn family's obstacle has an
    altitude offset and a pilot who may turn away. Here nothing but the controller separates
    the aircraft.
    """

    def generate(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
        n, ob = config.n_uavs, config.obstacle
        lay = layout(  # in formation, at cruise speed along the plan
            config,
            straight_plan(config),
            start=lambda slots, d: (slots.copy(), np.tile(d * config.cruise_speed, (n, 1))),
        )
        timeline = min(config.episode_duration, TIMELINE_S)
        meet = max(rng.uniform(*_COLLISION_MEET_RANGE) * timeline, _COLLISION_MIN_MEET_S)
        who = int(rng.integers(n))
        target = lay.planned_at(meet)[0][who]
        heading = _COLLISION_HEADINGS[kind](rng)  # the plan heads north (0 rad)
        speed = rng.uniform(*SPEED_RANGE_MPS)
        pos = target.copy()
        pos[:2] -= speed * meet * np.array([math.cos(heading), math.sin(heading)])
        hold = 2.0 * config.episode_duration  # the pilot never reacts
        first = ObstacleStart(
            pos=pos,
            heading=heading,
            speed=speed,
            max_turn_rate=ob.max_turn_rate,
            max_climb_rate=ob.max_climb_rate,
            climb_rate=0.0,
            hold_until=hold,
        )
        obstacles = obstacle_slots(config, lambda: first, lambda: _background(rng, config, lay))
        return assemble(f"collision_{kind}", config, lay, obstacles)

    what = "head-on" if kind == "head_on" else "at right angles, from either side"
    return ScenarioFamily(
        name=f"collision_{kind}",
        summary=f"A collision course: a straight-flying obstacle meets a UAV {what}.",
        parameters=(
            "The paper's straight plan and pattern; the obstacle flies straight at 3-12 m/s, "
            "never manoeuvres, at the altitude of a random UAV's plan, and reaches that UAV's "
            "planned position at 45-60 % of the episode (at most of 200 s; at least 20 s "
            "in). Without avoidance it collides; a safety test's encounter."
        ),
        generate=generate,
    )


def _random(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    return FAMILIES[RANDOM_MIX.draw(rng)].generate(rng, config)


def _random_draws(rng: np.random.Generator, config: EnvConfig) -> EpisodeDraws:
    return FAMILIES[RANDOM_MIX.draw(rng)].draws(rng, config)  # type: ignore[misc]


#: The families the ``random`` scenario draws per episode, with their integer weights.
RANDOM_MIX = Mix(
    weights={"crossing": 1, "head_on": 1, "overtaking": 1, "climbing": 1, "multi_obstacle": 1}
)


@functools.cache
def _random_tables() -> DrawTables:
    """The ``random`` family's draws as tables (its members registered by then)."""
    members = {name: ENCOUNTERS.get(name) for name in RANDOM_MIX.names}
    return draw_tables(
        members,
        RANDOM_MIX,
        TRAFFIC_MIX,
        ENCOUNTERS,
        _random_draws,
        tuple(FAMILIES[name].draws for name in members),  # type: ignore[misc]
    )


def _tables_of(member: str | None) -> Callable[[], tuple[DrawTables, int]]:
    """``ScenarioFamily.draw_tables`` of the ``random`` family or one of its members."""
    if member is None:
        return lambda: (_random_tables(), -1)
    return lambda: (_random_tables(), RANDOM_MIX.names.index(member))


# ---- The registry, in the order the names are listed ----------------------------------------
register(
    ScenarioFamily(
        name="paper",
        summary="Section 4's encounter: an obstacle crosses the track of three UAVs in line.",
        parameters=(
            "Fixed geometry (north at 100 m; the obstacle 10 m below from the north-north-east, "
            "meeting the middle UAV at 115 s); only its manoeuvres from 90 s on and the noise "
            "depend on the seed."
        ),
        generate=_paper,
        gym_name="PaperEncounter",
    )
)
register(
    ScenarioFamily(
        name="random",
        summary="One of the families below, drawn per episode.",
        parameters="Weights: " + RANDOM_MIX.describe() + ".",
        generate=_random,
        gym_name="Formation",
        mix=RANDOM_MIX,
        **_batched_form(_random_draws, _tables_of(None)),
    )
)
for _kind in ENCOUNTERS:
    register(_encounter(_kind))
register(
    ScenarioFamily(
        name="multi_obstacle",
        summary="Every obstacle slot aimed at the formation, each of a random kind.",
        parameters="Each slot's kind drawn from " + TRAFFIC_MIX.describe() + ".",
        generate=_multi_obstacle,
        **_batched_form(_multi_obstacle_draws, _tables_of("multi_obstacle")),
    )
)
register(
    ScenarioFamily(
        name="large_formation",
        summary="A crossing through the middle of a large formation (use `n_uavs` >= 6).",
        parameters=(
            "A crossing encounter aimed at the UAV nearest the formation's centre; the "
            "`paper` pattern becomes a wedge."
        ),
        generate=_large_formation,
        **_batched_form(_large_formation_draws),
        gym_name="LargeFormation",
        defaults={"n_uavs": 8, "formation": "wedge", "n_obstacles": 2},
    )
)

# Collision courses: not in RANDOM_MIX, so no existing bank moves.
for _kind in _COLLISION_HEADINGS:
    register(_collision_course(_kind))

# Recorded aircraft (issue 20): not in RANDOM_MIX, so no existing bank moves.
register(
    ScenarioFamily(
        name="real_traffic",
        summary="A recorded glider, helicopter or fixed-wing track placed to meet the formation.",
        parameters=(
            "Obstacle model `replay` (its default here). Each slot replays a distinct recorded "
            "track of `obstacle.replay_split` (default training flights), scaled by "
            "`obstacle.replay_speed_scale`, rotated and shifted so that its closest approach to "
            "a random UAV's plan is at 60-140 s and 0-10 m; it stays between ground + "
            "`airspace.obstacle_margin` and the ceiling."
        ),
        generate=_real_traffic.generate,
        gym_name="RealTraffic",
        obstacle_model="replay",
    )
)
