"""A batch of episodes' geometry from their draws, computed once over the batch.

The second step of :mod:`uasep_env.scenarios.batched`: the plans, slots, starts, planned
positions at the meeting times, obstacle starts and altitude bands of many episodes, from
their :class:`~uasep_env.scenarios.episode_draws.EpisodeDraws`, stacked as a
:class:`~uasep_env.scenarios.spec.ScenarioBatch`. Bit for bit what the per-episode
generator makes of the same draws (the module docstring of
:mod:`~uasep_env.scenarios.batched` says how); :func:`scenario_geometry` has a compiled twin.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config.groups import FLIGHT_ALTITUDE
from uasep_env.scenarios.building import (
    _ALT_BAND_HALF_WIDTH_M,
    _SHRINK_FACTORS,
    TIMELINE_S,
    _separated_start,
    airspace,
)
from uasep_env.scenarios.episode_draws import (
    _ALT,
    _CLIMB,
    _CLIMBS,
    _LEAD,
    _MEET,
    _N_COLS,
    _N_PLAN,
    _OFFSET,
    _SPEED,
    _TURN,
    _TURNS,
    _VZ_MAX,
    _W_MAX,
    _WHO,
    EpisodeDraws,
)
from uasep_env.scenarios.spec import N_WAYPOINTS, ScenarioBatch
from uasep_env.sim.formation import PlannedTrajectory, pattern_slots, segment_offsets

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = ["geometry", "geometry_inputs", "scenario_geometry"]


def _py_max(a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """Python's ``max(a, b)`` element by element (``a`` unless ``b > a``)."""
    return np.where(b > a, b, a)


def _py_min(a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """Python's ``min(a, b)`` element by element (``a`` unless ``b < a``)."""
    return np.where(b < a, b, a)


def _each(fn: Callable[..., float], *args: np.ndarray) -> np.ndarray:
    """``fn`` (a ``math`` function) element by element: libm's numbers, as the generator's."""
    columns = [a.tolist() for a in args]
    return np.array([fn(*xs) for xs in zip(*columns, strict=True)], dtype=float)


def _plans(draws: np.ndarray, cruise_speed: float, extra: float) -> np.ndarray:
    """``(B, N_WAYPOINTS, 3)`` the random plans, extended by ``extra`` (m) for long episodes."""
    b = len(draws)
    heading = draws[:, 0]
    turns = draws[:, 1 : 1 + _TURNS] * (draws[:, 1 + _TURNS : 1 + 2 * _TURNS] < 0.5)
    fractions = np.sort(draws[:, 1 + 2 * _TURNS : _N_PLAN], axis=1)
    edges = np.concatenate([np.zeros((b, 1)), fractions, np.ones((b, 1))], axis=1)
    legs = np.diff(edges, axis=1) * (cruise_speed * TIMELINE_S)
    # Each leg's heading: the turns added in order, as the generator does.
    h = np.empty((b, N_WAYPOINTS - 1))
    h[:, 0] = heading
    for k in range(1, N_WAYPOINTS - 1):
        h[:, k] = h[:, k - 1] + turns[:, k - 1]
    cos_h = _each(math.cos, h.ravel()).reshape(h.shape)
    sin_h = _each(math.sin, h.ravel()).reshape(h.shape)
    # The way-points, each the previous plus its leg (a cumulative sum adds in that order).
    steps = np.empty((b, N_WAYPOINTS, 3))
    steps[:, 0] = [0.0, 0.0, -FLIGHT_ALTITUDE]
    steps[:, 1:, 0] = legs * cos_h
    steps[:, 1:, 1] = legs * sin_h
    steps[:, 1:, 2] = legs * 0.0
    wp = np.cumsum(steps, axis=1)
    if extra > 0.0:
        # One row at a time, as the generator does (a 1-D norm is a dot product).
        for row in wp:
            last = row[-1] - row[-2]
            row[-1] += last / np.linalg.norm(last) * extra
    return wp


def _slots(patterns: list[str | tuple | None], config: EnvConfig) -> np.ndarray:
    """``(B, n_uavs, 3)`` each episode's formation pattern (``None``: the config's)."""
    out = np.empty((len(patterns), config.n_uavs, 3))
    for k, pattern in enumerate(patterns):
        out[k] = _pattern(pattern or config.formation, config.n_uavs, config.formation_spacing)
    return out


@functools.lru_cache(maxsize=64)
def _pattern(pattern: str | tuple, n: int, spacing: float) -> np.ndarray:
    """:func:`pattern_slots`, made once per pattern (read-only)."""
    slots = pattern_slots(pattern, n, spacing)
    slots.flags.writeable = False
    return slots


def _planned_at(
    plan: PlannedTrajectory, offsets: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Planned UAV positions ``(B, n_uavs, 3)`` and the plan's direction at times ``t``."""
    located = plan.locate(t)
    center, _, direction = plan.center_and_direction(t, located)
    return center[:, None, :] + offsets[np.arange(len(t)), located[1]], direction


def _stacked(draws: list[EpisodeDraws], config: EnvConfig) -> tuple[np.ndarray, np.ndarray]:
    """The layouts ``(B, L)`` and obstacles' draws ``(B, M, 11)`` of ``draws``, stacked."""
    lay = np.stack([d.layout for d in draws])
    if not config.n_obstacles:
        return lay, np.zeros((len(draws), 0, _N_COLS))
    return lay, np.stack([d.obstacles for d in draws])


def geometry_inputs(
    patterns: list[str | tuple | None], lay: np.ndarray, ob: np.ndarray, config: EnvConfig
) -> tuple:
    """:func:`scenario_geometry`'s arguments for episodes of these patterns and draws."""
    long = config.episode_duration > TIMELINE_S
    extra = config.cruise_speed * (config.episode_duration - TIMELINE_S) if long else 0.0
    floor, ceiling = airspace(config)
    return (lay, ob, _slots(patterns, config), float(config.cruise_speed), float(extra),
            float(config.uav.separation_distance), float(floor), float(ceiling))  # fmt: skip


def geometry(draws: list[EpisodeDraws], config: EnvConfig) -> ScenarioBatch:
    """The episodes of ``draws``, their geometry computed once over the batch.

    Bit for bit what :func:`~uasep_env.scenarios.building.random_layout`,
    :func:`~uasep_env.scenarios.building.aimed_obstacle` and
    :func:`~uasep_env.scenarios.building.assemble` make of the same draws.
    """
    lay, ob = _stacked(draws, config)
    return _geometry_of([d.family for d in draws], [d.pattern for d in draws], lay, ob, config)


def _geometry_of(
    families: list[str],
    patterns: list[str | tuple | None],
    lay: np.ndarray,
    ob: np.ndarray,
    config: EnvConfig,
) -> ScenarioBatch:
    """:func:`geometry` of stacked draws."""
    b, m = len(families), config.n_obstacles
    args = geometry_inputs(patterns, lay, ob, config)
    slots = args[2]
    wp, cum, direction, offsets, uav_pos, uav_vel, pos, heading, climb, hold, band = (
        scenario_geometry(*args)
    )
    obc = config.obstacle
    wind = np.empty((b, 3))  # np.tile's wrapper costs more than the rows
    wind[...] = obc.wind
    return ScenarioBatch(
        families=families,
        waypoints=wp,
        cruise_speed=np.full(b, float(config.cruise_speed)),
        slots=slots,
        uav_pos=uav_pos,
        uav_vel=uav_vel,
        obstacle_pos=pos,
        obstacle_heading=heading,
        obstacle_speed=ob[..., _SPEED].copy(),
        obstacle_turn_rate=np.zeros((b, m)),
        obstacle_climb_rate=climb,
        obstacle_max_turn_rate=ob[..., _W_MAX].copy(),
        obstacle_max_climb_rate=ob[..., _VZ_MAX].copy(),
        obstacle_radius=np.full((b, m), obc.radius, dtype=float),
        obstacle_alt_band=band,
        obstacle_active=np.ones((b, m), dtype=bool),
        obstacle_hold_until=hold,
        wind=wind,
        plan=PlannedTrajectory.from_geometry(wp, cum, direction, config.cruise_speed),
        plan_offsets=offsets,
    )


@compiled_twin(
    "scenario_geometry",
    n_plan=_N_PLAN,
    timeline=TIMELINE_S,
    altitude=FLIGHT_ALTITUDE,
    band_half=_ALT_BAND_HALF_WIDTH_M,
    shrink=_SHRINK_FACTORS,
)
def scenario_geometry(
    lay: np.ndarray,
    ob: np.ndarray,
    slots: np.ndarray,
    cruise_speed: float,
    extra: float,
    separation: float,
    floor: float,
    ceiling: float,
) -> tuple[np.ndarray, ...]:
    """The arrays of a batch of episodes from their draws (compiled as ``scenario_geometry``).

    Args:
        lay: ``(B, L)`` each episode's layout draws (:attr:`EpisodeDraws.layout`).
        ob: ``(B, M, 11)`` its obstacles' draws (:attr:`EpisodeDraws.obstacles`).
        slots: ``(B, N, 3)`` its formation pattern (m).
        cruise_speed: The plan's speed (m/s).
        extra: How far the plan flies on past the timeline (m; 0: not at all).
        separation: The UAVs' separation distance (m).
        floor: The lowest altitude an obstacle starts at (m, up).
        ceiling: The highest (m, up).

    Returns:
        ``(waypoints, cum, direction, offsets, uav_pos, uav_vel, obstacle_pos,
        obstacle_heading, climb_rate, hold_until, alt_band)``: the plan's way-points
        ``(B, W, 3)``, arc lengths ``(B, W)`` and directions ``(B, W - 1, 3)``
        (:class:`~uasep_env.sim.formation.PlannedTrajectory`), the slots rotated along each
        segment ``(B, W - 1, N, 3)``, the UAVs' starts ``(B, N, 3)``, the obstacles' starts
        ``(B, M, 3)``, headings (wrapped to ``[-pi, pi)``), climb rates and times they fly
        straight ``(B, M)`` and altitude bands ``(B, M, 2)``.
    """
    b, n, m = len(lay), slots.shape[1], ob.shape[1]
    wp = _plans(lay, cruise_speed, extra)
    plan = PlannedTrajectory(wp, cruise_speed)
    offsets = segment_offsets(plan.direction, slots)
    start_slots, _ = _planned_at(plan, offsets, np.zeros(b))
    scatter = lay[:, _N_PLAN:]
    uav_pos = start_slots + scatter[:, : 3 * n].reshape(b, n, 3)
    plan_dir = plan.direction[:, 0, :]
    uav_vel = (plan_dir * cruise_speed)[:, None, :] + scatter[:, 3 * n :].reshape(b, n, 3)
    # The start scatter is shrunk only where two UAVs start too close (rare): those rows
    # one at a time, as the generator does.
    d = np.linalg.norm(uav_pos[:, :, None] - uav_pos[:, None], axis=-1)
    d[:, np.arange(n), np.arange(n)] = np.inf
    for k in np.flatnonzero(~(d.min(axis=(1, 2)) >= separation)):
        uav_pos[k] = _separated_start(start_slots[k], uav_pos[k], separation)

    pos = np.empty((b, m, 3))
    heading = np.empty((b, m))
    climb = np.empty((b, m))
    hold = np.empty((b, m))
    rows = np.arange(b)
    for j in range(m):
        o = ob[:, j]
        meet = o[:, _MEET]
        targets, direction = _planned_at(plan, offsets, meet)
        target = targets[rows, o[:, _WHO].astype(np.intp)]
        plan_heading = _each(math.atan2, direction[:, 1], direction[:, 0])
        h = (plan_heading + o[:, _OFFSET]) + o[:, _TURN]
        climbs = o[:, _CLIMBS] != 0.0
        target_alt = -target[:, 2]
        with np.errstate(invalid="ignore"):  # nan climbs of level obstacles, not used
            clamped = _py_min(
                _py_max(o[:, _CLIMB], (target_alt - ceiling) / meet), (target_alt - floor) / meet
            )
        c = np.where(climbs, clamped, 0.0)
        start = np.empty((b, 3))
        start[:, 0] = target[:, 0] + 0.0
        start[:, 1] = target[:, 1] + 0.0
        start[:, 2] = target[:, 2] + np.where(climbs, 0.0, o[:, _ALT])
        speed = o[:, _SPEED]
        start[:, 0] -= speed * _each(math.cos, h) * meet
        start[:, 1] -= speed * _each(math.sin, h) * meet
        start[:, 2] += c * meet
        start[:, 2] = -_py_min(_py_max(-start[:, 2], floor), ceiling)
        pos[:, j], heading[:, j], climb[:, j] = start, h, c
        hold[:, j] = _py_max(0.0, meet - o[:, _LEAD])

    # assemble(): the altitude bands, widened to contain the starts, within the airspace.
    band = np.empty((b, m, 2))
    band[..., 0] = FLIGHT_ALTITUDE - _ALT_BAND_HALF_WIDTH_M
    band[..., 1] = FLIGHT_ALTITUDE + _ALT_BAND_HALF_WIDTH_M
    alts = -pos[..., 2]
    band[..., 0] = np.maximum(np.minimum(band[..., 0], alts), floor)
    band[..., 1] = np.minimum(np.maximum(band[..., 1], alts), ceiling)
    wrapped = np.mod(heading + math.pi, 2 * math.pi) - math.pi
    return (plan.waypoints, plan.cum, plan.direction, offsets, uav_pos, uav_vel, pos, wrapped,
            climb, hold, band)  # fmt: skip
