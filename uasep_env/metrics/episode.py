"""Every metric of one episode (:func:`episode_metrics`): per-UAV results and the summary."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uasep_env.metrics.distances import obstacle_distances, pairwise_uav_distances
from uasep_env.metrics.families import (
    conflict_timelines,
    deviation_stats,
    fluctuation_stats,
    path_lengths,
    rising_edge_counts,
)
from uasep_env.metrics.record import EpisodeRecord
from uasep_env.metrics.results import Axis3, EpisodeMetrics, EpisodeSummary, UAVMetrics

__all__ = ["episode_costs", "episode_metrics"]


def _masked_argmin(values: np.ndarray) -> tuple[float, tuple[int, ...]]:
    """Return (min, unravelled index) of ``values``; (NaN, all -1) if no finite value."""
    if values.size == 0:
        return math.nan, (-1,) * values.ndim
    flat = np.where(np.isnan(values), np.inf, values).ravel()
    k = int(np.argmin(flat))
    if not np.isfinite(flat[k]):
        return math.nan, (-1,) * values.ndim
    idx = np.unravel_index(k, values.shape)
    return float(flat[k]), tuple(int(i) for i in idx)


def _nanmax(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0 or np.all(np.isnan(arr)):
        return math.nan
    return float(np.nanmax(arr))


def _nanmin(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0 or np.all(np.isnan(arr)):
        return math.nan
    return float(np.nanmin(arr))


def _axis_max(rows: Sequence[Axis3]) -> Axis3:
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    return tuple(_nanmax(arr[:, j]) for j in range(3))  # type: ignore[return-value]


def _time_at(t: np.ndarray, k: int) -> float:
    """``t[k]``, or NaN for the -1 index of an undefined minimum."""
    return float(t[k]) if k >= 0 else math.nan


@dataclass(frozen=True, kw_only=True)
class _Pairs:
    """Per-sample UAV-UAV and UAV-obstacle quantities of one episode (the safety metrics).

    ``dd`` (T, N, N) UAV-UAV distances (inf diagonal), ``od`` (T, N, M) UAV-obstacle
    distances and ``region`` (T, N, M) region distances (inf where inactive); the ``*_los`` /
    ``*_col`` masks and their rising-edge counts per pair (``*_edges``).
    """

    dd: np.ndarray
    uu_los: np.ndarray
    uu_col: np.ndarray
    uu_los_edges: np.ndarray  # (N, N) symmetric, 0 diagonal
    uu_col_edges: np.ndarray
    od: np.ndarray
    uo_los: np.ndarray  # inf (inactive) is never True
    uo_col: np.ndarray
    uo_los_edges: np.ndarray  # (N, M)
    uo_col_edges: np.ndarray
    region: np.ndarray


def _pairs(record: EpisodeRecord) -> _Pairs:
    dd = pairwise_uav_distances(record.uav_pos)
    uu_los = dd < record.uav_separation
    uu_col = dd < record.collision_distance
    od = obstacle_distances(record.uav_pos, record.obstacle_pos, record.obstacle_active)
    uo_los = od < record.obstacle_separation
    uo_col = od < record.collision_distance
    return _Pairs(
        dd=dd,
        uu_los=uu_los,
        uu_col=uu_col,
        uu_los_edges=rising_edge_counts(uu_los),
        uu_col_edges=rising_edge_counts(uu_col),
        od=od,
        uo_los=uo_los,
        uo_col=uo_col,
        uo_los_edges=rising_edge_counts(uo_los),
        uo_col_edges=rising_edge_counts(uo_col),
        region=np.where(record.obstacle_active[:, None, :], record.region_distance, np.inf),
    )


def _uav_safety(record: EpisodeRecord, p: _Pairs, i: int) -> dict[str, object]:
    """The safety fields of UAV ``i``'s :class:`UAVMetrics`."""
    t, dt = record.time, record.dt
    sep, (k_sep, j_sep) = _masked_argmin(p.dd[:, i, :])
    odist, (k_od, j_od) = _masked_argmin(p.od[:, i, :])
    rdist, (k_rd, j_rd) = _masked_argmin(p.region[:, i, :])
    return {
        "min_uav_separation": sep,
        "min_uav_separation_partner_index": j_sep,
        "min_uav_separation_time": _time_at(t, k_sep),
        "min_obstacle_distance": odist,
        "min_obstacle_distance_obstacle_index": j_od,
        "min_obstacle_distance_time": _time_at(t, k_od),
        "min_region_distance": rdist,
        "min_region_distance_obstacle_index": j_rd,
        "min_region_distance_time": _time_at(t, k_rd),
        "uav_los_events": int(p.uu_los_edges[i].sum()),
        "uav_los_time": float(p.uu_los[:, i, :].any(axis=-1).sum() * dt),
        "obstacle_los_events": int(p.uo_los_edges[i].sum()),
        "obstacle_los_time": float(p.uo_los[:, i, :].any(axis=-1).sum() * dt),
        "uav_collision_events": int(p.uu_col_edges[i].sum()),
        "obstacle_collision_events": int(p.uo_col_edges[i].sum()),
        "collision": bool(p.uu_col[:, i, :].any() or p.uo_col[:, i, :].any()),
    }


def _episode_safety(record: EpisodeRecord, p: _Pairs) -> dict[str, object]:
    """The safety fields of the :class:`EpisodeSummary` (minima, distinct-pair event sums)."""
    t, dt, n = record.time, record.dt, record.n_uavs
    upper = np.triu(np.ones((n, n), dtype=bool), k=1)
    sep, (k_sep, a_sep, b_sep) = _masked_argmin(np.where(upper[None], p.dd, np.inf))
    odist, (k_od, i_od, j_od) = _masked_argmin(p.od)
    rdist, (k_rd, i_rd, j_rd) = _masked_argmin(p.region)
    uu_events = int(p.uu_los_edges[upper].sum())
    uo_events = int(p.uo_los_edges.sum())
    uu_col_events = int(p.uu_col_edges[upper].sum())
    uo_col_events = int(p.uo_col_edges.sum())
    return {
        "min_uav_separation": sep,
        "min_uav_separation_uav_a_index": a_sep,
        "min_uav_separation_uav_b_index": b_sep,
        "min_uav_separation_time": _time_at(t, k_sep),
        "min_obstacle_distance": odist,
        "min_obstacle_distance_uav_index": i_od,
        "min_obstacle_distance_obstacle_index": j_od,
        "min_obstacle_distance_time": _time_at(t, k_od),
        "min_region_distance": rdist,
        "min_region_distance_uav_index": i_rd,
        "min_region_distance_obstacle_index": j_rd,
        "min_region_distance_time": _time_at(t, k_rd),
        "uav_los_events": uu_events,
        "uav_los_time": float(p.uu_los.any(axis=(1, 2)).sum() * dt),
        "obstacle_los_events": uo_events,
        "obstacle_los_time": float(p.uo_los.any(axis=(1, 2)).sum() * dt),
        "uav_collision_events": uu_col_events,
        "obstacle_collision_events": uo_col_events,
        "collision_events": uu_col_events + uo_col_events,
        "uav_collision": uu_col_events > 0,
        "obstacle_collision": uo_col_events > 0,
        "collision": (uu_col_events + uo_col_events) > 0,
        "uav_loss_of_separation": uu_events > 0,
        "obstacle_loss_of_separation": uo_events > 0,
        "loss_of_separation": (uu_events + uo_events) > 0,
    }


def episode_costs(record: EpisodeRecord) -> np.ndarray:
    """Each UAV's episode cost: its per-step costs summed over the episode (all NaN without).

    Args:
        record: The episode.

    Returns:
        ``(N,)`` float64 (0 for an episode of one sample: no step).
    """
    if record.step_cost is None:
        return np.full(record.n_uavs, math.nan)
    return record.step_cost.sum(axis=0)


def episode_metrics(record: EpisodeRecord, hold_time: float = 2.0) -> EpisodeMetrics:
    """Compute every metric of one episode.

    Args:
        record: The episode.
        hold_time: Hold time (s) of the conflict-resolution timeline (see
            :func:`conflict_timelines`).

    Returns:
        The episode's :class:`EpisodeMetrics`.
    """
    t = record.time
    pairs = _pairs(record)
    devs = deviation_stats(record)
    timelines = conflict_timelines(record, hold_time=hold_time)
    flucts = fluctuation_stats(record)
    flown, planned, ratio = path_lengths(record)
    costs = episode_costs(record)
    uavs = tuple(
        UAVMetrics(
            name=record.names[i],
            index=i,
            **_uav_safety(record, pairs, i),  # type: ignore[arg-type]
            deviation=devs[i],
            timeline=timelines[i],
            fluctuation=flucts[i],
            path_length=float(flown[i]),
            planned_path_length=float(planned[i]),
            path_length_ratio=float(ratio[i]),
            cost=float(costs[i]),
        )
        for i in range(record.n_uavs)
    )
    summary = EpisodeSummary(
        duration=float(t[-1] - t[0]),
        n_uavs=record.n_uavs,
        n_obstacles=record.n_obstacles,
        **_episode_safety(record, pairs),  # type: ignore[arg-type]
        max_deviation=_nanmax([d.max_norm for d in devs]),
        max_rms_deviation=_nanmax([d.rms_norm for d in devs]),
        n_uavs_left=sum(tl.left for tl in timelines),
        any_never_returned=any(tl.never_returned for tl in timelines),
        first_t_leave=_nanmin([tl.t_leave for tl in timelines]),
        max_conflict_duration=_nanmax([tl.conflict_duration for tl in timelines]),
        max_vel_std=_axis_max([f.vel_std for f in flucts]),
        max_acc_std=_axis_max([f.acc_std for f in flucts]),
        max_vel_rate=_axis_max([f.vel_max_rate for f in flucts]),
        max_acc_rate=_axis_max([f.acc_max_rate for f in flucts]),
        max_path_length_ratio=_nanmax(list(ratio)),
        cost=float(costs.mean()),
        max_uav_cost=float(costs.max()),
    )
    config = {
        "dt": record.dt,
        "collision_distance": record.collision_distance,
        "uav_separation": record.uav_separation,
        "obstacle_separation": record.obstacle_separation,
        "deviation_threshold": record.deviation_threshold,
        "settle_time": record.settle_time,
        "hold_time": float(hold_time),
    }
    return EpisodeMetrics(episode=summary, uavs=uavs, config=config)
