"""Per-UAV metric families: deviation, conflict-resolution timeline, fluctuation, path length.

Deviation, timeline, fluctuation and path-length statistics use only the samples with
``time >= settle_time``.

``d(t) = |p(t) - p_planned(t)|`` and "off track" meaning ``d(t) > deviation_threshold``:

1. ``t_leave``: the first sample with ``time >= settle_time`` at which the UAV is off track.
   If there is none the UAV never left: every timeline time and duration is NaN, ``left`` is
   False. If the UAV is already off track at the first sample after ``settle_time``, ``t_leave``
   is that sample and ``started_off_track`` is True (the formation had probably not formed up).
2. A sample ``k`` is *back on track* when ``d <= deviation_threshold`` at every sample in
   ``[time[k], time[k] + hold_time]`` and that whole window lies inside the record (a return
   that cannot be confirmed for ``hold_time`` before the episode ends does not count). The
   *excursion* runs from ``t_leave`` up to (not including) the first back-on-track sample
   after ``t_leave``, or to the end of the record when there is none. Short dips below the
   threshold (shorter than ``hold_time``) stay inside the excursion.
3. ``t_resolved`` ("the moment the conflict is over"): the time, within the excursion, of the
   closest approach to any obstacle's predicted reachable region, i.e. the sample minimising
   ``min over active obstacles of region_distance`` (first sample on ties). From then on the
   threat recedes. NaN when no obstacle is active during the excursion.
4. ``t_back``: the first back-on-track sample at or after ``t_resolved`` (at or after
   ``t_leave`` when ``t_resolved`` is NaN). By construction this is the end of the excursion.
   NaN, with ``never_returned`` True, when the UAV never comes back.
5. Durations: ``conflict_duration = t_back - t_leave`` (the paper's "entire conflict
   resolution took 27 s" = 130 s - 103 s), ``time_to_resolve = t_resolved - t_leave`` and
   ``recovery_time = t_back - t_resolved``; NaN whenever an end point is NaN.
6. Also reported: ``t_region_exit``, the first sample at or after ``t_resolved`` at which the UAV
   is outside every active obstacle's reachable region (``region_distance > 0`` for all active
   obstacles), and ``resolved_region_distance``, the region distance at ``t_resolved``.

Only the first excursion after ``settle_time`` is timed; ``n_departures`` counts the rising
edges of "off track" after ``settle_time`` (without hold-time hysteresis).

"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env.metrics.record import EpisodeRecord, check_scalar
from uasep_env.metrics.results import Axis3, ConflictTimeline, DeviationStats, FluctuationStats

__all__ = [
    "conflict_timelines",
    "deviation_stats",
    "fluctuation_stats",
    "path_lengths",
    "rising_edge_counts",
    "trajectory_deviation",
]


def rising_edge_counts(mask: ArrayLike) -> NDArray[np.int64]:
    """Count rising edges of a boolean array along axis 0 (time).

    A True at the first sample counts as a rising edge.

    Args:
        mask: (T, ...) boolean array.

    Returns:
        (...) integer counts.
    """
    m = np.asarray(mask, dtype=bool)
    if m.shape[0] == 0:
        return np.zeros(m.shape[1:], dtype=np.int64)
    rises = m[1:] & ~m[:-1]
    return (m[0].astype(np.int64) + rises.sum(axis=0)).astype(np.int64)


def trajectory_deviation(record: EpisodeRecord) -> NDArray[np.float64]:
    """Return the deviation from the planned trajectory, ``uav_pos - planned_pos``.

    Args:
        record: The episode.

    Returns:
        (T, N, 3) deviation vectors (m).
    """
    return record.uav_pos - record.planned_pos


def _axis3(values: np.ndarray) -> Axis3:
    return (float(values[0]), float(values[1]), float(values[2]))


_R = TypeVar("_R")


def _per_uav(result: Callable[..., _R], **columns: np.ndarray) -> list[_R]:
    """One ``result`` per UAV, each field row ``i`` of its column.

    ``(N, 3)`` columns give per-axis triples, ``(N,)`` ones floats.
    """
    n = len(next(iter(columns.values())))
    return [
        result(**{k: _axis3(v[i]) if v.ndim == 2 else float(v[i]) for k, v in columns.items()})
        for i in range(n)
    ]


def deviation_stats(record: EpisodeRecord) -> list[DeviationStats]:
    """Deviation statistics per UAV over the samples with ``time >= settle_time``.

    Args:
        record: The episode.

    Returns:
        One :class:`DeviationStats` per UAV.
    """
    sel = record.settled_mask()
    dev = trajectory_deviation(record)[sel]  # (S, N, 3)
    t = record.time[sel]
    norm = np.linalg.norm(dev, axis=-1)  # (S, N)
    max_norm = norm.max(axis=0)
    arg = norm.argmax(axis=0)
    rms_norm = np.sqrt(np.mean(norm**2, axis=0))
    max_abs = np.abs(dev).max(axis=0)  # (N, 3)
    rms = np.sqrt(np.mean(dev**2, axis=0))
    off = (norm > record.deviation_threshold).sum(axis=0) * record.dt
    return _per_uav(
        DeviationStats,
        max_norm=max_norm,
        rms_norm=rms_norm,
        max_abs=max_abs,
        rms=rms,
        time_off_track=off,
        max_norm_time=t[arg],
    )


def _back_on_track(below: np.ndarray, hold_steps: int) -> np.ndarray:
    """Return, per sample, whether ``below`` holds on ``[k, k + hold_steps]`` inside the record.

    Args:
        below: (S,) or (S, N) boolean.
        hold_steps: Number of further samples that must also be below.

    Returns:
        Boolean array of ``below``'s shape.
    """
    s = below.shape[0]
    bad = np.concatenate(
        [np.zeros((1, *below.shape[1:]), dtype=np.int64), np.cumsum(~below, axis=0)], axis=0
    )
    ok = np.zeros(below.shape, dtype=bool)
    n_ok = s - hold_steps
    if n_ok > 0:
        ok[:n_ok] = (bad[hold_steps + 1 : hold_steps + 1 + n_ok] - bad[:n_ok]) == 0
    return ok


def _first_true(mask: np.ndarray, start: int) -> int:
    """Return the first index ``>= start`` where ``mask`` is True, or -1."""
    if start >= mask.shape[0]:
        return -1
    tail = mask[start:]
    if not tail.any():
        return -1
    return start + int(np.argmax(tail))


def conflict_timelines(record: EpisodeRecord, hold_time: float = 2.0) -> list[ConflictTimeline]:
    """Conflict-resolution timeline per UAV (definitions in the module docstring).

    Args:
        record: The episode.
        hold_time: Time (s) the deviation must stay ``<= deviation_threshold`` for the UAV to
            count as back on its planned trajectory; ``>= 0``.

    Returns:
        One :class:`ConflictTimeline` per UAV.

    Raises:
        ValueError: If ``hold_time`` is negative or not finite.
    """
    hold_time = check_scalar("hold_time", hold_time)
    if hold_time < 0.0:
        raise ValueError(f"hold_time: must be >= 0, got {hold_time}")
    hold_steps = math.ceil(hold_time / record.dt - 1e-9)

    sel = record.settled_mask()
    t = record.time[sel]
    norm = np.linalg.norm(trajectory_deviation(record)[sel], axis=-1)  # (S, N)
    off = norm > record.deviation_threshold
    back_ok = _back_on_track(~off, hold_steps)  # (S, N)
    departures = rising_edge_counts(off)

    active = record.obstacle_active[sel]  # (S, M)
    region = np.where(active[:, None, :], record.region_distance[sel], np.inf)  # (S, N, M)
    # (S, N) nearest active region, +inf when nothing is active.
    region_min = region.min(axis=-1) if record.n_obstacles else np.full(norm.shape, np.inf)
    outside = region_min > 0.0  # vacuous True when nothing is active

    out: list[ConflictTimeline] = []
    nan = math.nan
    for i in range(record.n_uavs):
        k_leave = _first_true(off[:, i], 0)
        if k_leave < 0:
            out.append(
                ConflictTimeline(
                    left=False,
                    started_off_track=False,
                    t_leave=nan,
                    t_resolved=nan,
                    t_back=nan,
                    never_returned=False,
                    t_region_exit=nan,
                    resolved_region_distance=nan,
                    time_to_resolve=nan,
                    recovery_time=nan,
                    conflict_duration=nan,
                    n_departures=int(departures[i]),
                    hold_time=hold_time,
                )
            )
            continue
        k_end = _first_true(back_ok[:, i], k_leave)  # first back-on-track sample, or -1
        stop = k_end if k_end >= 0 else t.shape[0]
        window = region_min[k_leave:stop, i]
        t_resolved = nan
        resolved_dist = nan
        t_exit = nan
        k_from = k_leave
        if window.size and np.isfinite(window).any():
            k_res = k_leave + int(np.argmin(window))
            t_resolved = float(t[k_res])
            resolved_dist = float(region_min[k_res, i])
            k_from = k_res
            k_exit = _first_true(outside[:, i] & np.isfinite(region_min[:, i]), k_res)
            t_exit = float(t[k_exit]) if k_exit >= 0 else nan
        k_back = _first_true(back_ok[:, i], k_from)
        t_leave = float(t[k_leave])
        t_back = float(t[k_back]) if k_back >= 0 else nan
        out.append(
            ConflictTimeline(
                left=True,
                started_off_track=k_leave == 0,
                t_leave=t_leave,
                t_resolved=t_resolved,
                t_back=t_back,
                never_returned=bool(k_back < 0),
                t_region_exit=t_exit,
                resolved_region_distance=resolved_dist,
                time_to_resolve=t_resolved - t_leave,
                recovery_time=t_back - t_resolved,
                conflict_duration=t_back - t_leave,
                n_departures=int(departures[i]),
                hold_time=hold_time,
            )
        )
    return out


def fluctuation_stats(record: EpisodeRecord) -> list[FluctuationStats]:
    """Velocity and acceleration fluctuation per UAV and axis after ``settle_time``.

    Args:
        record: The episode.

    Returns:
        One :class:`FluctuationStats` per UAV.
    """
    sel = record.settled_mask()
    vel = record.uav_vel[sel]  # (S, N, 3)
    acc = record.uav_acc[sel]
    vel_std = vel.std(axis=0)
    acc_std = acc.std(axis=0)
    acc_max_abs = np.abs(acc).max(axis=0)
    speed_max = np.linalg.norm(vel, axis=-1).max(axis=0)
    if vel.shape[0] >= 2:
        vel_rate = np.abs(np.diff(vel, axis=0)).max(axis=0) / record.dt
        acc_rate = np.abs(np.diff(acc, axis=0)).max(axis=0) / record.dt
    else:
        vel_rate = np.full((record.n_uavs, 3), np.nan)
        acc_rate = np.full((record.n_uavs, 3), np.nan)
    return _per_uav(
        FluctuationStats,
        vel_std=vel_std,
        acc_std=acc_std,
        vel_max_rate=vel_rate,
        acc_max_rate=acc_rate,
        acc_max_abs=acc_max_abs,
        speed_max=speed_max,
    )


def path_lengths(
    record: EpisodeRecord,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Flown and planned path lengths per UAV after ``settle_time``.

    Lengths are sums of straight segments between consecutive settled samples.

    Args:
        record: The episode.

    Returns:
        ``(flown, planned, ratio)``, each (N,): flown length (m), planned length (m) and
        ``flown / planned`` (NaN where the planned length is zero).
    """
    sel = record.settled_mask()
    flown = np.linalg.norm(np.diff(record.uav_pos[sel], axis=0), axis=-1).sum(axis=0)
    planned = np.linalg.norm(np.diff(record.planned_pos[sel], axis=0), axis=-1).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(planned > 0.0, flown / np.where(planned > 0.0, planned, 1.0), np.nan)
    return flown, planned, ratio
