"""Scenarios of many episodes at once: per-episode draws, then the geometry batched.

A partial reset of a vector env starts a few episodes per step. Built one at a time
(:func:`uasep_env.scenarios.sample_scenario`), each costs a few hundred small-array numpy
calls; here the families that declare a batched form (:attr:`ScenarioFamily.draws
<uasep_env.scenarios.registry.ScenarioFamily.draws>`) are built in two steps:

1. *draws*, per episode, from its own generator: the same numbers, in the same order, as
   the family's generator draws them (they never depend on the geometry), kept as plain
   floats (:class:`~uasep_env.scenarios.episode_draws.EpisodeDraws`), here;
2. *geometry*, once over all the episodes: the plans, slots, starts, planned positions at
   the meeting times, obstacle starts and altitude bands, stacked as a
   :class:`~uasep_env.scenarios.spec.ScenarioBatch` (:mod:`uasep_env.scenarios.batch_geometry`).

The numbers are those of the per-episode generator, bit for bit
(``tests/test_batched_scenarios.py``): each value is computed by the same operations in the
same order, with the same functions (Python's ``math.cos``, ``math.sin`` and ``math.atan2``
element by element where the generator uses them, the numpy functions where it uses those,
and Python's ``min``/``max`` semantics where it uses them). Families without a batched form
are drawn one at a time by :func:`sample_batch`, and stacked.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.scenarios.batch_geometry import (  # the geometry step, read from here too
    _geometry_of,
    _stacked,  # noqa: F401
    geometry,
    geometry_inputs,
    scenario_geometry,
)
from uasep_env.scenarios.building import (
    _START_SCATTER_M,
    _START_SPEED_SCATTER_MPS,
    ALTITUDE_OFFSET_RANGE_M,
    CLIMB_RATE_RANGE_MPS,
    MEET_TIME_RANGE,
    REACTION_LEAD_RANGE_S,
    TIMELINE_S,
    TURN_RATE_RANGE_RADPS,
    Encounter,
    EncounterDraws,
)
from uasep_env.scenarios.episode_draws import (
    _N_COLS,
    _N_PLAN,
    _PLAN_HIGH,
    _PLAN_LOW,
    _TURNS,  # noqa: F401 (read from here too)
    EpisodeDraws,
)
from uasep_env.scenarios.registry import Mix, get_family
from uasep_env.scenarios.spec import ScenarioBatch

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = [
    "DrawTables",
    "EpisodeDraws",
    "draw_encounters",
    "draw_tables",
    "geometry",
    "geometry_inputs",
    "sample_batch",
    "scenario_geometry",
]


@functools.cache
def _bounds(d: EncounterDraws) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Low and high ends and ranges of an encounter's draws after its meeting time and UAV."""
    low = [TURN_RATE_RANGE_RADPS[0], CLIMB_RATE_RANGE_MPS[0], d.speed[0]]
    high = [TURN_RATE_RANGE_RADPS[1], CLIMB_RATE_RANGE_MPS[1], d.speed[1]]
    if d.either_side:
        low.append(0.0)
        high.append(1.0)
    low += [d.turn[0], ALTITUDE_OFFSET_RANGE_M[0]]
    high += [d.turn[1], ALTITUDE_OFFSET_RANGE_M[1]]
    if d.climbs:
        low.append(0.0)
        high.append(1.0)
    low.append(REACTION_LEAD_RANGE_S[0])
    high.append(REACTION_LEAD_RANGE_S[1])
    return _low_and_range(low, high)


@functools.cache
def _layout_bounds(n: int, meet: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Low and high ends and ranges of a layout's draws for ``n`` UAVs (then a meeting time)."""
    low = _PLAN_LOW + [-_START_SCATTER_M] * (3 * n) + [-_START_SPEED_SCATTER_MPS] * (3 * n)
    high = _PLAN_HIGH + [_START_SCATTER_M] * (3 * n) + [_START_SPEED_SCATTER_MPS] * (3 * n)
    if meet:
        low.append(MEET_TIME_RANGE[0])
        high.append(MEET_TIME_RANGE[1])
    return _low_and_range(low, high)


def _low_and_range(
    low: list[float], high: list[float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    lo, hi = np.array(low), np.array(high)
    return lo, hi, hi - lo  # numpy's uniform takes high - low too


def _uniforms_by_formula(
    rng: np.random.Generator, low: np.ndarray, high: np.ndarray, span: np.ndarray
) -> np.ndarray:
    """``low + span * rng.random()``, element by element: numpy's uniform, written out.

    numpy draws ``uniform(low, high)`` as ``low + (high - low) * next_double`` (and
    ``random()`` is ``next_double``): the same doubles as consecutive ``uniform`` and
    ``random`` calls, in one fast call. Used only where :data:`_FORMULA_IS_EXACT` (a
    numpy built to fuse the multiply-add would round differently).
    """
    return low + span * rng.random(len(low))


def _uniforms_by_call(
    rng: np.random.Generator, low: np.ndarray, high: np.ndarray, span: np.ndarray
) -> np.ndarray:
    """``rng.uniform`` with arrays of bounds (numpy's own arithmetic; slower)."""
    return rng.uniform(low, high)


def _formula_is_exact() -> bool:
    """Whether :func:`_uniforms_by_formula` gives ``rng.uniform``'s numbers on this numpy."""
    check = np.random.default_rng(20261203)
    low = check.uniform(-500.0, 500.0, 256)
    high = low + check.uniform(0.0, 1000.0, 256)
    low[:8] = [-math.pi, -math.pi / 4, 0.0, 0.2, -8.0, -1.0, 3.0, 10.0]
    high[:8] = [math.pi, math.pi / 4, 1.0, 0.8, 8.0, 1.0, 12.0, 40.0]
    a, b = np.random.default_rng(7), np.random.default_rng(7)
    want = np.concatenate([a.uniform(lo, hi, 64) for lo, hi in zip(low, high, strict=True)])
    got = np.concatenate(
        [
            _uniforms_by_formula(b, *_low_and_range([lo] * 64, [hi] * 64))
            for lo, hi in zip(low, high, strict=True)
        ]
    )
    return bool(np.array_equal(want, got))


#: Whether this numpy's uniform is the unfused ``low + span * next_double`` (checked once).
_FORMULA_IS_EXACT = _formula_is_exact()
_uniforms = _uniforms_by_formula if _FORMULA_IS_EXACT else _uniforms_by_call


def _draw_obstacle(
    rng: np.random.Generator,
    config: EnvConfig,
    encounter: Encounter,
    who: int | None,
    meet: float | None = None,
) -> list[float]:
    """:func:`~uasep_env.scenarios.building.aimed_obstacle`'s draws, as one row.

    ``meet``: the meeting time's uniform draw, if drawn already (with the layout's).
    """
    d = encounter.draws
    assert d is not None  # families with such an encounter declare no batched form
    if meet is None:
        meet = rng.uniform(*MEET_TIME_RANGE)
    meet = meet * TIMELINE_S
    if who is None:
        who = int(rng.integers(config.n_uavs))
    r = _uniforms(rng, *_bounds(d)).tolist()
    w_max, vz_max, speed = r[0], r[1], r[2]
    if d.above_cruise:
        speed = config.cruise_speed + speed
    k = 3
    if d.either_side:
        side = 1.0 if r[k] < 0.5 else -1.0
        turn = side * r[k + 1]
        k += 2
    else:
        turn = r[k]
        k += 1
    alt = r[k]
    k += 1
    climb = math.nan
    if d.climbs:
        climb = (1.0 if r[k] < 0.5 else -1.0) * vz_max
        k += 1
    lead = r[k]
    return [meet, who, w_max, vz_max, speed, d.heading_offset, turn, alt, climb, d.climbs, lead]


def draw_encounters(
    family: str,
    config: EnvConfig,
    rng: np.random.Generator,
    first: Encounter | None,
    traffic: Mix,
    encounters: dict[str, Encounter],
    pattern: str | tuple | None = None,
    who: int | None = None,
) -> EpisodeDraws:
    """The draws of a random layout and its aimed obstacles.

    Args:
        family: The family's name.
        config: The config.
        rng: The episode's generator.
        first: Slot 0's encounter (``None``: background traffic, like the others).
        traffic: The mix background traffic's kinds are drawn from.
        encounters: The encounter kinds by name.
        pattern: The formation pattern (``None``: the config's).
        who: The UAV slot 0 is aimed at (``None``: drawn).
    """
    # The layout's draws and slot 0's meeting time are consecutive uniforms: one call.
    meet_too = config.n_obstacles > 0 and first is not None
    drawn = _uniforms(rng, *_layout_bounds(config.n_uavs, meet_too))
    layout = drawn[: _N_PLAN + 6 * config.n_uavs]
    rows = []
    for k in range(config.n_obstacles):
        if k == 0 and first is not None:
            rows.append(_draw_obstacle(rng, config, first, who, float(drawn[-1])))
        else:
            rows.append(_draw_obstacle(rng, config, encounters[traffic.draw(rng)], None))
    obstacles = np.array(rows, dtype=float).reshape(config.n_obstacles, _N_COLS)
    return EpisodeDraws(family, pattern, layout, obstacles)


class DrawTables(NamedTuple):
    """A family's draws as tables: what :func:`encounter_draws` compiles (:func:`draw_tables`).

    Attributes:
        member_cum: ``(K,)`` the cumulative weights of the member families drawn per episode
            (its :class:`Mix`; one member: none drawn).
        first: ``(K,)`` each member's slot-0 encounter, a row of the encounter tables (-1:
            background traffic like the other slots).
        traffic_cum: ``(T,)`` the cumulative weights of the background traffic's kinds.
        traffic_kind: ``(T,)`` their encounter rows.
        low: ``(E, 8)`` each encounter's uniform draws' low ends (:func:`_bounds`, padded).
        span: ``(E, 8)`` their spans.
        count: ``(E,)`` how many it draws.
        flags: ``(E, 3)`` whether its speed is above the cruise speed, it comes from either
            side, it climbs or descends.
        heading_offset: ``(E,)`` its heading offset from the plan's (rad).
        names: Each member's family name.
        draws: The family's per-episode draws (drawing its member).
        member_draws: Each member family's per-episode draws.
    """

    member_cum: np.ndarray
    first: np.ndarray
    traffic_cum: np.ndarray
    traffic_kind: np.ndarray
    low: np.ndarray
    span: np.ndarray
    count: np.ndarray
    flags: np.ndarray
    heading_offset: np.ndarray
    names: tuple[str, ...]
    draws: Callable[..., EpisodeDraws]
    member_draws: tuple[Callable[..., EpisodeDraws], ...]


def draw_tables(
    members: dict[str, Encounter | None],
    mix: Mix | None,
    traffic: Mix,
    encounters: dict[str, Encounter],
    draws: Callable[..., EpisodeDraws],
    member_draws: tuple[Callable[..., EpisodeDraws], ...],
) -> DrawTables:
    """The tables of a family whose episodes are :func:`draw_encounters`' of its members.

    Args:
        members: Each member family's name and slot-0 encounter (``None``: background).
        mix: The mix a member is drawn from per episode (its names in ``members``' order),
            or ``None`` for a family of one member.
        traffic: The mix of the background traffic's kinds.
        encounters: The encounter kinds by name.
        draws: The family's per-episode draws.
        member_draws: Each member's per-episode draws, in ``members``' order.
    """
    kinds = list(encounters.values())
    names = tuple(members)
    if mix is not None and mix.names != names:
        raise ValueError(f"the mix {mix.names} does not list the members {names}")
    weights = [mix.weights[n] for n in names] if mix is not None else [1]
    low, span = np.zeros((len(kinds), 8)), np.zeros((len(kinds), 8))
    count = np.zeros(len(kinds), dtype=np.int64)
    flags = np.zeros((len(kinds), 3), dtype=bool)
    offset = np.zeros(len(kinds))
    for e, kind in enumerate(kinds):
        d = kind.draws
        assert d is not None  # families with such an encounter declare no batched form
        lo, _, sp = _bounds(d)
        count[e] = len(lo)
        low[e, : len(lo)], span[e, : len(lo)] = lo, sp
        flags[e] = d.above_cruise, d.either_side, d.climbs
        offset[e] = d.heading_offset
    index = {id(kind): e for e, kind in enumerate(kinds)}
    return DrawTables(
        member_cum=np.cumsum(weights, dtype=np.int64),
        first=np.array([-1 if f is None else index[id(f)] for f in members.values()], np.int64),
        traffic_cum=np.cumsum(list(traffic.weights.values()), dtype=np.int64),
        traffic_kind=np.array([index[id(encounters[n])] for n in traffic.names], np.int64),
        low=low,
        span=span,
        count=count,
        flags=flags,
        heading_offset=offset,
        names=names,
        draws=draws,
        member_draws=member_draws,
    )


@compiled_twin(
    "encounter_draws",
    exact=_FORMULA_IS_EXACT,
    layout_bounds=_layout_bounds,
    meet_range=MEET_TIME_RANGE,
    timeline=TIMELINE_S,
)
def encounter_draws(
    rngs: list[np.random.Generator], config: EnvConfig, tables: DrawTables, member: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each generator's episode drawn by ``tables``' family, stacked.

    Compiled as ``encounter_draws``, which draws from the tables.

    Args:
        rngs: Each episode's generator (left where its draws leave it).
        config: The environment config.
        tables: The family's :class:`DrawTables`.
        member: The member drawn (-1: drawn per episode by the family's mix).

    Returns:
        ``(members, layout, obstacles)``: each episode's member ``(B,)``, layout draws
        ``(B, L)`` and obstacles' draws ``(B, M, 11)`` (:class:`EpisodeDraws`).
    """
    draw = tables.draws if member < 0 else tables.member_draws[member]
    drawn = [draw(rng, config) for rng in rngs]
    members = np.array([tables.names.index(d.family) for d in drawn], dtype=np.int64)
    obstacles = np.zeros((len(drawn), config.n_obstacles, _N_COLS))
    for k, d in enumerate(drawn):
        obstacles[k] = d.obstacles
    return members, np.stack([d.layout for d in drawn]), obstacles


def sample_batch(rngs: list[np.random.Generator], config: EnvConfig) -> ScenarioBatch:
    """Draw one episode's initial conditions per generator, as one batch.

    The same numbers as :func:`uasep_env.scenarios.sample_scenario` with each generator,
    bit for bit, and the generators left in the same states.

    Args:
        rngs: Each episode's generator (at least one).
        config: The environment config (``config.scenario`` names the family).
    """
    family = get_family(config.scenario)
    if family.draw_tables is not None:  # the draws compiled, from the family's tables
        tables, member = family.draw_tables()
        members, lay, ob = encounter_draws(rngs, config, tables, member)
        names = [tables.names[k] for k in members.tolist()]
        return _geometry_of(names, [None] * len(rngs), lay, ob, config)
    if family.draws is None:
        return ScenarioBatch.from_specs([family.generate(rng, config) for rng in rngs])
    return geometry([family.draws(rng, config) for rng in rngs], config)
