"""Episode metrics for UAV-formation separation management (paper section 4).

This module turns one recorded episode (an :class:`EpisodeRecord`) into the quantities the paper
reports in section 4, and aggregates them over many episodes:

* **Safety** (section 4.3, figures 8-9): UAV-UAV and UAV-obstacle centre distances against the
  collision distance and the loss-of-separation thresholds, the distance to each obstacle's
  predicted reachable region, counts of loss-of-separation / collision events and the time spent
  in loss of separation.
* **Trajectory deviation** (section 4.4.1, figures 10-11): deviation of the true position from
  the planned position, as a norm and per axis, and the conflict-resolution timeline (the paper's
  UAV3 "started to move away from the planned trajectory at 103 s, successfully resolved the
  conflict at 122 s, and returned to the planned trajectory at 130 s. The entire conflict
  resolution took 27 s"; the previous method's 110 s / 121 s / 148 s, 38 s).
* **Velocity and acceleration fluctuation** (section 4.4.2, figures 12-14): per-axis standard
  deviation and largest change per second.
* **Path-length ratio**: flown path length over planned path length.

Frame: NED (x north, y east, z down); metres, seconds, m/s, m/s^2. All arrays are numpy float64.

Conventions used throughout (all thresholds are strict "closer than"):

* A UAV pair is in *loss of separation* at a sample when its centre distance is
  ``< uav_separation``; a UAV and an *active* obstacle when their centre distance is
  ``< obstacle_separation``. A *collision* is a centre distance ``< collision_distance``.
* An *event* is a rising edge of such a boolean per pair along time: a sample in violation
  whose previous sample is not. A violation already present at the first sample counts as one
  event. An obstacle that becomes inactive and active again while still too close therefore
  gives two events.
* *Time in loss of separation* is the number of samples in violation times ``dt`` (a
  sample-and-hold integral). Per UAV it is the time during which the UAV violates separation
  with at least one other UAV (respectively obstacle); for the episode it is the time during
  which at least one pair does. Event counts are per pair: a UAV's count is the sum over the
  pairs it belongs to, the episode count is the sum over distinct pairs (each UAV-UAV pair is
  counted once).
* Minimum distances are taken over the samples (no sub-sample interpolation), over the whole
  episode (``settle_time`` does not apply to safety metrics). Inactive obstacles are ignored.
  A minimum over an empty set (one UAV, no obstacle, or no obstacle ever active) is NaN and its
  index fields are -1.
* Deviation, timeline, fluctuation and path-length statistics use only the samples with
  ``time >= settle_time``.

The conflict-resolution timeline (per UAV) is defined exactly as follows, with
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

Aggregation over episodes (:func:`aggregate`): every numeric scalar gets mean, sample standard
deviation (ddof=1), min, max, sum, the number of episodes ``n`` and of finite values
``n_valid``, and a two-sided Student-t confidence interval for the mean
``mean +/- t_{(1+c)/2, n_valid-1} * std / sqrt(n_valid)``. Every boolean is treated as a rate
(fraction of episodes where it is True) with a Wilson score interval. NaNs are ignored.
The t quantile is computed without scipy by inverting the Student-t CDF, written with the
regularised incomplete beta function (continued fraction, Lentz's method) and solved by
bisection; it is accurate to about 1e-10 (see :func:`t_quantile`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ConflictTimeline",
    "DeviationStats",
    "EpisodeMetrics",
    "EpisodeRecord",
    "EpisodeSummary",
    "FluctuationStats",
    "UAVMetrics",
    "aggregate",
    "conflict_timelines",
    "deviation_stats",
    "episode_metrics",
    "flatten_metrics",
    "fluctuation_stats",
    "format_table",
    "normal_quantile",
    "obstacle_distances",
    "pairwise_uav_distances",
    "path_lengths",
    "rising_edge_counts",
    "summary_table",
    "t_interval",
    "t_quantile",
    "trajectory_deviation",
    "wilson_interval",
]

Axis3 = tuple[float, float, float]
_AXES = ("x", "y", "z")


# --------------------------------------------------------------------------------------------
# Input record
# --------------------------------------------------------------------------------------------


def _as_float_array(name: str, value: ArrayLike) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float64 array ({exc})") from exc
    return arr


def _check_shape(name: str, arr: np.ndarray, shape: tuple[int | None, ...]) -> None:
    ok = arr.ndim == len(shape) and all(
        want is None or have == want for have, want in zip(arr.shape, shape, strict=False)
    )
    if not ok:
        want_txt = "(" + ", ".join("?" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want_txt}, got {arr.shape}")


def _check_scalar(name: str, value: float, *, positive: bool = False) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a real number, got {value!r}") from exc
    if not math.isfinite(out):
        raise ValueError(f"{name}: must be finite, got {out}")
    if positive and out <= 0.0:
        raise ValueError(f"{name}: must be > 0, got {out}")
    return out


@dataclass(frozen=True, eq=False)
class EpisodeRecord:
    """One recorded episode of a formation flight among obstacles (NED frame, SI units).

    Arrays are converted to numpy (float64, ``obstacle_active`` bool) and validated in
    ``__post_init__``; every problem raises :class:`ValueError` whose message starts with the
    name of the offending field. ``T`` is the number of samples, ``N`` the number of UAVs
    (``N >= 1``) and ``M`` the number of obstacles (``M >= 0``).

    Attributes:
        time: (T,) sample times (s), strictly increasing with uniform step ``dt``.
        dt: Sample step (s), ``> 0``; must match ``diff(time)`` (relative tolerance 1e-6).
        uav_pos: (T, N, 3) true UAV positions (m).
        uav_vel: (T, N, 3) true UAV velocities (m/s).
        uav_acc: (T, N, 3) applied UAV accelerations (m/s^2).
        planned_pos: (T, N, 3) planned position of each UAV at each sample (m).
        obstacle_pos: (T, M, 3) true obstacle positions (m); may be non-finite where the
            obstacle is inactive.
        obstacle_active: (T, M) bool, True where the obstacle is present.
        region_distance: (T, N, M) signed distance (m, negative inside) from each UAV to each
            obstacle's predicted reachable region; may be non-finite where inactive.
        collision_distance: Collision distance (m), ``> 0``: a UAV-UAV or UAV-obstacle centre
            distance below it is a collision.
        uav_separation: UAV-UAV loss-of-separation threshold (m), ``> collision_distance``.
        obstacle_separation: UAV-obstacle loss-of-separation threshold (m),
            ``>= collision_distance``.
        deviation_threshold: A UAV is off its planned trajectory when its deviation is
            ``> deviation_threshold`` (m), ``> 0``.
        settle_time: Samples before this time (s) are ignored by the deviation, timeline,
            fluctuation and path-length statistics; must not exceed ``time[-1]``.
        uav_names: Optional UAV names (N unique strings); default ``("uav_0", "uav_1", ...)``.
    """

    time: NDArray[np.float64]
    dt: float
    uav_pos: NDArray[np.float64]
    uav_vel: NDArray[np.float64]
    uav_acc: NDArray[np.float64]
    planned_pos: NDArray[np.float64]
    obstacle_pos: NDArray[np.float64]
    obstacle_active: NDArray[np.bool_]
    region_distance: NDArray[np.float64]
    collision_distance: float
    uav_separation: float
    obstacle_separation: float
    deviation_threshold: float = 1.0
    settle_time: float = 0.0
    uav_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        """Convert and validate every field; raise ValueError naming the bad field."""
        setf = object.__setattr__

        dt = _check_scalar("dt", self.dt, positive=True)
        setf(self, "dt", dt)

        time = _as_float_array("time", self.time)
        _check_shape("time", time, (None,))
        n_t = time.shape[0]
        if n_t < 1:
            raise ValueError("time: needs at least one sample")
        if not np.all(np.isfinite(time)):
            raise ValueError("time: contains non-finite values")
        if n_t > 1:
            steps = np.diff(time)
            if np.any(steps <= 0.0):
                raise ValueError("time: must be strictly increasing")
            if not np.allclose(steps, dt, rtol=1e-6, atol=1e-9 * dt):
                raise ValueError(
                    f"time: step must be uniform and equal to dt={dt}, got steps in "
                    f"[{steps.min()}, {steps.max()}]"
                )
        setf(self, "time", time)

        uav_pos = _as_float_array("uav_pos", self.uav_pos)
        _check_shape("uav_pos", uav_pos, (n_t, None, 3))
        n_uav = uav_pos.shape[1]
        if n_uav < 1:
            raise ValueError("uav_pos: needs at least one UAV")
        for name in ("uav_pos", "uav_vel", "uav_acc", "planned_pos"):
            arr = uav_pos if name == "uav_pos" else _as_float_array(name, getattr(self, name))
            _check_shape(name, arr, (n_t, n_uav, 3))
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name}: contains non-finite values")
            setf(self, name, arr)

        obstacle_pos = _as_float_array("obstacle_pos", self.obstacle_pos)
        _check_shape("obstacle_pos", obstacle_pos, (n_t, None, 3))
        n_obs = obstacle_pos.shape[1]

        active_raw = np.asarray(self.obstacle_active)
        _check_shape("obstacle_active", active_raw, (n_t, n_obs))
        if active_raw.dtype != np.bool_:
            if active_raw.size and not (
                np.issubdtype(active_raw.dtype, np.number)
                and np.all((active_raw == 0) | (active_raw == 1))
            ):
                raise ValueError("obstacle_active: must be boolean (or 0/1)")
            active_raw = active_raw.astype(bool)
        active = np.ascontiguousarray(active_raw, dtype=bool)
        setf(self, "obstacle_active", active)

        if not np.all(np.isfinite(obstacle_pos[active])):
            raise ValueError("obstacle_pos: non-finite values where the obstacle is active")
        setf(self, "obstacle_pos", obstacle_pos)

        region = _as_float_array("region_distance", self.region_distance)
        _check_shape("region_distance", region, (n_t, n_uav, n_obs))
        if np.any(np.isnan(region) & active[:, None, :]):
            raise ValueError("region_distance: NaN where the obstacle is active")
        setf(self, "region_distance", region)

        coll = _check_scalar("collision_distance", self.collision_distance, positive=True)
        usep = _check_scalar("uav_separation", self.uav_separation, positive=True)
        osep = _check_scalar("obstacle_separation", self.obstacle_separation, positive=True)
        if usep <= coll:
            raise ValueError(f"uav_separation: must be > collision_distance ({coll}), got {usep}")
        if osep < coll:
            raise ValueError(
                f"obstacle_separation: must be >= collision_distance ({coll}), got {osep}"
            )
        setf(self, "collision_distance", coll)
        setf(self, "uav_separation", usep)
        setf(self, "obstacle_separation", osep)

        thr = _check_scalar("deviation_threshold", self.deviation_threshold, positive=True)
        setf(self, "deviation_threshold", thr)
        settle = _check_scalar("settle_time", self.settle_time)
        if settle > time[-1] + 1e-9 * dt:
            raise ValueError(f"settle_time: {settle} s is after the last sample ({time[-1]} s)")
        setf(self, "settle_time", settle)

        if self.uav_names is None:
            names = tuple(f"uav_{i}" for i in range(n_uav))
        else:
            if isinstance(self.uav_names, str):
                raise ValueError("uav_names: expected a sequence of str, got a single str")
            names = tuple(self.uav_names)
            if len(names) != n_uav:
                raise ValueError(f"uav_names: expected {n_uav} names, got {len(names)}")
            if not all(isinstance(n, str) and n for n in names):
                raise ValueError("uav_names: names must be non-empty str")
            if len(set(names)) != n_uav:
                raise ValueError("uav_names: names must be unique")
        setf(self, "uav_names", names)

    @property
    def n_steps(self) -> int:
        """Number of samples T."""
        return int(self.time.shape[0])

    @property
    def n_uavs(self) -> int:
        """Number of UAVs N."""
        return int(self.uav_pos.shape[1])

    @property
    def n_obstacles(self) -> int:
        """Number of obstacles M."""
        return int(self.obstacle_pos.shape[1])

    @property
    def names(self) -> tuple[str, ...]:
        """UAV names (always set after validation)."""
        assert self.uav_names is not None
        return self.uav_names

    def settled_mask(self) -> NDArray[np.bool_]:
        """Return the (T,) mask of samples with ``time >= settle_time`` (1e-9 dt tolerance)."""
        return self.time >= self.settle_time - 1e-9 * self.dt

    def first_settled_index(self) -> int:
        """Return the index of the first sample with ``time >= settle_time``."""
        return int(np.argmax(self.settled_mask()))


# --------------------------------------------------------------------------------------------
# Result dataclasses
# --------------------------------------------------------------------------------------------


def _py(value: Any) -> Any:
    """Convert numpy scalars / tuples / nested dataclasses into plain JSON-able Python."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _py(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): _py(v) for k, v in value.items()}
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (tuple, list, np.ndarray)):
        return [_py(v) for v in value]
    return value


class _DictMixin:
    """``to_dict`` for result dataclasses: per-axis tuples become ``{"x", "y", "z"}`` dicts."""

    _AXIS_FIELDS: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """Return a plain, JSON-serialisable dict (NaN/inf are kept as Python floats).

        Returns:
            Nested dict of bool / int / float / str / None. Per-axis triples are written
            as ``{"x": ..., "y": ..., "z": ...}``.
        """
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if f.name in self._AXIS_FIELDS:
                out[f.name] = {ax: float(v) for ax, v in zip(_AXES, value, strict=True)}
            elif isinstance(value, _DictMixin):
                out[f.name] = value.to_dict()
            else:
                out[f.name] = _py(value)
        return out


@dataclass(frozen=True)
class DeviationStats(_DictMixin):
    """Deviation from the planned trajectory of one UAV after ``settle_time`` (m, s).

    Attributes:
        max_norm: Largest deviation norm ``|p - p_planned|`` (m).
        rms_norm: Root mean square of the deviation norm (m).
        max_abs: Per-axis (x, y, z) largest absolute deviation (m).
        rms: Per-axis (x, y, z) root mean square deviation (m).
        time_off_track: Samples with deviation ``> deviation_threshold`` times dt (s).
        max_norm_time: Time of the largest deviation norm (s).
    """

    _AXIS_FIELDS = ("max_abs", "rms")

    max_norm: float
    rms_norm: float
    max_abs: Axis3
    rms: Axis3
    time_off_track: float
    max_norm_time: float


@dataclass(frozen=True)
class ConflictTimeline(_DictMixin):
    """Conflict-resolution timeline of one UAV (s); see the module docstring for definitions.

    Attributes:
        left: True if the UAV went off track after ``settle_time``.
        started_off_track: True if the UAV was already off track at the first settled sample.
        t_leave: Time the UAV left the planned trajectory (s), NaN if it never left.
        t_resolved: Time of closest approach to any obstacle's reachable region within the
            excursion (s), NaN if no obstacle was active during it.
        t_back: Time the UAV was back on the planned trajectory for ``hold_time`` (s).
        never_returned: True if the UAV left and never came back (``t_back`` NaN).
        t_region_exit: First time at or after ``t_resolved`` when the UAV is outside every
            active obstacle's reachable region (s), NaN if never or undefined.
        resolved_region_distance: Region distance at ``t_resolved`` (m, negative inside).
        time_to_resolve: ``t_resolved - t_leave`` (s).
        recovery_time: ``t_back - t_resolved`` (s).
        conflict_duration: ``t_back - t_leave`` (s), the paper's conflict-resolution time.
        n_departures: Rising edges of "off track" after ``settle_time``.
        hold_time: The hold time used (s).
    """

    left: bool
    started_off_track: bool
    t_leave: float
    t_resolved: float
    t_back: float
    never_returned: bool
    t_region_exit: float
    resolved_region_distance: float
    time_to_resolve: float
    recovery_time: float
    conflict_duration: float
    n_departures: int
    hold_time: float


@dataclass(frozen=True)
class FluctuationStats(_DictMixin):
    """Velocity and acceleration fluctuation of one UAV after ``settle_time``, per axis.

    Attributes:
        vel_std: Per-axis population standard deviation (ddof=0) of velocity (m/s).
        acc_std: Per-axis population standard deviation of acceleration (m/s^2).
        vel_max_rate: Per-axis ``max |v[k+1] - v[k]| / dt`` (m/s^2); NaN with < 2 samples.
        acc_max_rate: Per-axis ``max |a[k+1] - a[k]| / dt`` (m/s^3); NaN with < 2 samples.
        acc_max_abs: Per-axis largest absolute acceleration (m/s^2).
        speed_max: Largest speed ``|v|`` (m/s).
    """

    _AXIS_FIELDS = ("vel_std", "acc_std", "vel_max_rate", "acc_max_rate", "acc_max_abs")

    vel_std: Axis3
    acc_std: Axis3
    vel_max_rate: Axis3
    acc_max_rate: Axis3
    acc_max_abs: Axis3
    speed_max: float


@dataclass(frozen=True)
class UAVMetrics(_DictMixin):
    """Metrics of one UAV in one episode.

    Index fields (``*_index``) are -1 when the corresponding minimum is undefined (NaN).

    Attributes:
        name: UAV name.
        index: UAV index in the record.
        min_uav_separation: Smallest centre distance to another UAV (m), whole episode.
        min_uav_separation_partner_index: Index of that other UAV.
        min_uav_separation_time: Time of that minimum (s).
        min_obstacle_distance: Smallest centre distance to an active obstacle (m).
        min_obstacle_distance_obstacle_index: Index of that obstacle.
        min_obstacle_distance_time: Time of that minimum (s).
        min_region_distance: Smallest signed distance to an active obstacle's region (m).
        min_region_distance_obstacle_index: Index of that obstacle.
        min_region_distance_time: Time of that minimum (s).
        uav_los_events: Rising edges of UAV-UAV loss of separation, summed over partners.
        uav_los_time: Time in loss of separation with at least one other UAV (s).
        obstacle_los_events: Rising edges of UAV-obstacle loss of separation, summed over
            obstacles.
        obstacle_los_time: Time in loss of separation with at least one obstacle (s).
        uav_collision_events: Rising edges of UAV-UAV collision, summed over partners.
        obstacle_collision_events: Rising edges of UAV-obstacle collision, summed over
            obstacles.
        collision: True if the UAV collided with anything.
        deviation: Deviation from the planned trajectory.
        timeline: Conflict-resolution timeline.
        fluctuation: Velocity / acceleration fluctuation.
        path_length: Flown path length after ``settle_time`` (m).
        planned_path_length: Planned path length over the same samples (m).
        path_length_ratio: ``path_length / planned_path_length``; NaN if the plan is static.
    """

    name: str
    index: int
    min_uav_separation: float
    min_uav_separation_partner_index: int
    min_uav_separation_time: float
    min_obstacle_distance: float
    min_obstacle_distance_obstacle_index: int
    min_obstacle_distance_time: float
    min_region_distance: float
    min_region_distance_obstacle_index: int
    min_region_distance_time: float
    uav_los_events: int
    uav_los_time: float
    obstacle_los_events: int
    obstacle_los_time: float
    uav_collision_events: int
    obstacle_collision_events: int
    collision: bool
    deviation: DeviationStats
    timeline: ConflictTimeline
    fluctuation: FluctuationStats
    path_length: float
    planned_path_length: float
    path_length_ratio: float


@dataclass(frozen=True)
class EpisodeSummary(_DictMixin):
    """Whole-episode summary (minima over UAVs, totals, any-flags).

    Attributes:
        duration: ``time[-1] - time[0]`` (s).
        n_uavs: Number of UAVs.
        n_obstacles: Number of obstacles.
        min_uav_separation: Smallest UAV-UAV centre distance (m).
        min_uav_separation_uav_a_index: Lower index of the closest pair.
        min_uav_separation_uav_b_index: Higher index of the closest pair.
        min_uav_separation_time: Time of that minimum (s).
        min_obstacle_distance: Smallest UAV-obstacle centre distance (m).
        min_obstacle_distance_uav_index: UAV of that minimum.
        min_obstacle_distance_obstacle_index: Obstacle of that minimum.
        min_obstacle_distance_time: Time of that minimum (s).
        min_region_distance: Smallest UAV-to-reachable-region signed distance (m).
        min_region_distance_uav_index: UAV of that minimum.
        min_region_distance_obstacle_index: Obstacle of that minimum.
        min_region_distance_time: Time of that minimum (s).
        uav_los_events: UAV-UAV loss-of-separation events, summed over distinct pairs.
        uav_los_time: Time during which at least one UAV pair is in loss of separation (s).
        obstacle_los_events: UAV-obstacle loss-of-separation events, summed over pairs.
        obstacle_los_time: Time during which at least one UAV-obstacle pair is in loss of
            separation (s).
        uav_collision_events: UAV-UAV collision events, summed over distinct pairs.
        obstacle_collision_events: UAV-obstacle collision events, summed over pairs.
        collision_events: ``uav_collision_events + obstacle_collision_events``.
        uav_collision: Any UAV-UAV collision.
        obstacle_collision: Any UAV-obstacle collision.
        collision: Any collision.
        uav_loss_of_separation: Any UAV-UAV loss of separation.
        obstacle_loss_of_separation: Any UAV-obstacle loss of separation.
        loss_of_separation: Any loss of separation.
        max_deviation: Largest deviation norm over UAVs after ``settle_time`` (m).
        max_rms_deviation: Largest per-UAV RMS deviation norm (m).
        n_uavs_left: Number of UAVs that left their planned trajectory.
        any_never_returned: True if some UAV left and never came back.
        first_t_leave: Earliest ``t_leave`` over UAVs (s).
        max_conflict_duration: Largest ``conflict_duration`` over UAVs (s).
        max_vel_std: Per-axis largest velocity standard deviation over UAVs (m/s).
        max_acc_std: Per-axis largest acceleration standard deviation over UAVs (m/s^2).
        max_vel_rate: Per-axis largest ``|dv|/dt`` over UAVs (m/s^2).
        max_acc_rate: Per-axis largest ``|da|/dt`` over UAVs (m/s^3).
        max_path_length_ratio: Largest path-length ratio over UAVs.
    """

    _AXIS_FIELDS = ("max_vel_std", "max_acc_std", "max_vel_rate", "max_acc_rate")

    duration: float
    n_uavs: int
    n_obstacles: int
    min_uav_separation: float
    min_uav_separation_uav_a_index: int
    min_uav_separation_uav_b_index: int
    min_uav_separation_time: float
    min_obstacle_distance: float
    min_obstacle_distance_uav_index: int
    min_obstacle_distance_obstacle_index: int
    min_obstacle_distance_time: float
    min_region_distance: float
    min_region_distance_uav_index: int
    min_region_distance_obstacle_index: int
    min_region_distance_time: float
    uav_los_events: int
    uav_los_time: float
    obstacle_los_events: int
    obstacle_los_time: float
    uav_collision_events: int
    obstacle_collision_events: int
    collision_events: int
    uav_collision: bool
    obstacle_collision: bool
    collision: bool
    uav_loss_of_separation: bool
    obstacle_loss_of_separation: bool
    loss_of_separation: bool
    max_deviation: float
    max_rms_deviation: float
    n_uavs_left: int
    any_never_returned: bool
    first_t_leave: float
    max_conflict_duration: float
    max_vel_std: Axis3
    max_acc_std: Axis3
    max_vel_rate: Axis3
    max_acc_rate: Axis3
    max_path_length_ratio: float


@dataclass(frozen=True)
class EpisodeMetrics(_DictMixin):
    """All metrics of one episode.

    Attributes:
        episode: Whole-episode summary.
        uavs: Per-UAV metrics, in record order.
        config: Thresholds and parameters used (m, s), for provenance.
    """

    episode: EpisodeSummary
    uavs: tuple[UAVMetrics, ...]
    config: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Return a nested, JSON-serialisable dict.

        Returns:
            ``{"episode": {...}, "uavs": [{...}, ...], "config": {...}}``.
        """
        return {
            "episode": self.episode.to_dict(),
            "uavs": [u.to_dict() for u in self.uavs],
            "config": _py(dict(self.config)),
        }

    def to_json(self, **kwargs: Any) -> str:
        """Return strict JSON (non-finite floats written as ``null``).

        Args:
            **kwargs: Passed on to :func:`json.dumps` (e.g. ``indent``).

        Returns:
            A JSON string.
        """
        return json.dumps(_json_safe(self.to_dict()), allow_nan=False, **kwargs)

    def uav(self, name: str) -> UAVMetrics:
        """Return the metrics of the UAV called ``name``.

        Args:
            name: UAV name.

        Returns:
            That UAV's metrics.

        Raises:
            KeyError: If there is no such UAV.
        """
        for u in self.uavs:
            if u.name == name:
                return u
        raise KeyError(name)


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


# --------------------------------------------------------------------------------------------
# Elementary vectorised helpers
# --------------------------------------------------------------------------------------------


def pairwise_uav_distances(uav_pos: ArrayLike) -> NDArray[np.float64]:
    """Return UAV-UAV centre distances.

    Args:
        uav_pos: (T, N, 3) positions (m).

    Returns:
        (T, N, N) distances (m), ``+inf`` on the diagonal.
    """
    pos = np.asarray(uav_pos, dtype=np.float64)
    diff = pos[:, :, None, :] - pos[:, None, :, :]
    dist = np.linalg.norm(diff, axis=-1)
    n = pos.shape[1]
    dist[:, np.arange(n), np.arange(n)] = np.inf
    return dist


def obstacle_distances(
    uav_pos: ArrayLike, obstacle_pos: ArrayLike, obstacle_active: ArrayLike
) -> NDArray[np.float64]:
    """Return UAV-obstacle centre distances, ``+inf`` where the obstacle is inactive.

    Args:
        uav_pos: (T, N, 3) UAV positions (m).
        obstacle_pos: (T, M, 3) obstacle positions (m).
        obstacle_active: (T, M) bool.

    Returns:
        (T, N, M) distances (m).
    """
    pos = np.asarray(uav_pos, dtype=np.float64)
    obs = np.asarray(obstacle_pos, dtype=np.float64)
    active = np.asarray(obstacle_active, dtype=bool)
    with np.errstate(invalid="ignore"):
        dist = np.linalg.norm(pos[:, :, None, :] - obs[:, None, :, :], axis=-1)
    return np.where(active[:, None, :], dist, np.inf)


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


_NAN3: Axis3 = (math.nan, math.nan, math.nan)


# --------------------------------------------------------------------------------------------
# Per-UAV metric families
# --------------------------------------------------------------------------------------------


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
    return [
        DeviationStats(
            max_norm=float(max_norm[i]),
            rms_norm=float(rms_norm[i]),
            max_abs=_axis3(max_abs[i]),
            rms=_axis3(rms[i]),
            time_off_track=float(off[i]),
            max_norm_time=float(t[arg[i]]),
        )
        for i in range(record.n_uavs)
    ]


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
    hold_time = _check_scalar("hold_time", hold_time)
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
    return [
        FluctuationStats(
            vel_std=_axis3(vel_std[i]),
            acc_std=_axis3(acc_std[i]),
            vel_max_rate=_axis3(vel_rate[i]),
            acc_max_rate=_axis3(acc_rate[i]),
            acc_max_abs=_axis3(acc_max_abs[i]),
            speed_max=float(speed_max[i]),
        )
        for i in range(record.n_uavs)
    ]


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


# --------------------------------------------------------------------------------------------
# Episode metrics
# --------------------------------------------------------------------------------------------


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


def episode_metrics(record: EpisodeRecord, hold_time: float = 2.0) -> EpisodeMetrics:
    """Compute every metric of one episode.

    Args:
        record: The episode.
        hold_time: Hold time (s) of the conflict-resolution timeline (see
            :func:`conflict_timelines`).

    Returns:
        The episode's :class:`EpisodeMetrics`.
    """
    n, m = record.n_uavs, record.n_obstacles
    t = record.time
    dt = record.dt

    # ---- UAV-UAV -----------------------------------------------------------------------
    dd = pairwise_uav_distances(record.uav_pos)  # (T, N, N), inf diagonal
    upper = np.triu(np.ones((n, n), dtype=bool), k=1)
    uu_los = dd < record.uav_separation
    uu_col = dd < record.collision_distance
    uu_los_edges = rising_edge_counts(uu_los)  # (N, N) symmetric, 0 diagonal
    uu_col_edges = rising_edge_counts(uu_col)

    # ---- UAV-obstacle ------------------------------------------------------------------
    od = obstacle_distances(record.uav_pos, record.obstacle_pos, record.obstacle_active)
    uo_los = od < record.obstacle_separation  # (T, N, M); inf (inactive) is never True
    uo_col = od < record.collision_distance
    uo_los_edges = rising_edge_counts(uo_los)  # (N, M)
    uo_col_edges = rising_edge_counts(uo_col)
    region = np.where(record.obstacle_active[:, None, :], record.region_distance, np.inf)

    devs = deviation_stats(record)
    timelines = conflict_timelines(record, hold_time=hold_time)
    flucts = fluctuation_stats(record)
    flown, planned, ratio = path_lengths(record)

    uavs: list[UAVMetrics] = []
    for i in range(n):
        sep, (k_sep, j_sep) = _masked_argmin(dd[:, i, :])
        odist, (k_od, j_od) = _masked_argmin(od[:, i, :])
        rdist, (k_rd, j_rd) = _masked_argmin(region[:, i, :])
        uavs.append(
            UAVMetrics(
                name=record.names[i],
                index=i,
                min_uav_separation=sep,
                min_uav_separation_partner_index=j_sep,
                min_uav_separation_time=float(t[k_sep]) if k_sep >= 0 else math.nan,
                min_obstacle_distance=odist,
                min_obstacle_distance_obstacle_index=j_od,
                min_obstacle_distance_time=float(t[k_od]) if k_od >= 0 else math.nan,
                min_region_distance=rdist,
                min_region_distance_obstacle_index=j_rd,
                min_region_distance_time=float(t[k_rd]) if k_rd >= 0 else math.nan,
                uav_los_events=int(uu_los_edges[i].sum()),
                uav_los_time=float(uu_los[:, i, :].any(axis=-1).sum() * dt),
                obstacle_los_events=int(uo_los_edges[i].sum()),
                obstacle_los_time=float(uo_los[:, i, :].any(axis=-1).sum() * dt),
                uav_collision_events=int(uu_col_edges[i].sum()),
                obstacle_collision_events=int(uo_col_edges[i].sum()),
                collision=bool(uu_col[:, i, :].any() or uo_col[:, i, :].any()),
                deviation=devs[i],
                timeline=timelines[i],
                fluctuation=flucts[i],
                path_length=float(flown[i]),
                planned_path_length=float(planned[i]),
                path_length_ratio=float(ratio[i]),
            )
        )

    # ---- Episode summary ---------------------------------------------------------------
    dd_upper = np.where(upper[None], dd, np.inf)
    sep, (k_sep, a_sep, b_sep) = _masked_argmin(dd_upper)
    odist, (k_od, i_od, j_od) = _masked_argmin(od)
    rdist, (k_rd, i_rd, j_rd) = _masked_argmin(region)
    uu_events = int(uu_los_edges[upper].sum())
    uo_events = int(uo_los_edges.sum())
    uu_col_events = int(uu_col_edges[upper].sum())
    uo_col_events = int(uo_col_edges.sum())
    any_uu_los_t = uu_los.any(axis=(1, 2))
    any_uo_los_t = uo_los.any(axis=(1, 2))
    summary = EpisodeSummary(
        duration=float(t[-1] - t[0]),
        n_uavs=n,
        n_obstacles=m,
        min_uav_separation=sep,
        min_uav_separation_uav_a_index=a_sep,
        min_uav_separation_uav_b_index=b_sep,
        min_uav_separation_time=float(t[k_sep]) if k_sep >= 0 else math.nan,
        min_obstacle_distance=odist,
        min_obstacle_distance_uav_index=i_od,
        min_obstacle_distance_obstacle_index=j_od,
        min_obstacle_distance_time=float(t[k_od]) if k_od >= 0 else math.nan,
        min_region_distance=rdist,
        min_region_distance_uav_index=i_rd,
        min_region_distance_obstacle_index=j_rd,
        min_region_distance_time=float(t[k_rd]) if k_rd >= 0 else math.nan,
        uav_los_events=uu_events,
        uav_los_time=float(any_uu_los_t.sum() * dt),
        obstacle_los_events=uo_events,
        obstacle_los_time=float(any_uo_los_t.sum() * dt),
        uav_collision_events=uu_col_events,
        obstacle_collision_events=uo_col_events,
        collision_events=uu_col_events + uo_col_events,
        uav_collision=uu_col_events > 0,
        obstacle_collision=uo_col_events > 0,
        collision=(uu_col_events + uo_col_events) > 0,
        uav_loss_of_separation=uu_events > 0,
        obstacle_loss_of_separation=uo_events > 0,
        loss_of_separation=(uu_events + uo_events) > 0,
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
    )
    config = {
        "dt": dt,
        "collision_distance": record.collision_distance,
        "uav_separation": record.uav_separation,
        "obstacle_separation": record.obstacle_separation,
        "deviation_threshold": record.deviation_threshold,
        "settle_time": record.settle_time,
        "hold_time": float(hold_time),
    }
    return EpisodeMetrics(episode=summary, uavs=tuple(uavs), config=config)


# --------------------------------------------------------------------------------------------
# Statistics: quantiles and confidence intervals (no scipy)
# --------------------------------------------------------------------------------------------


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz's method)."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c = 1.0
    d = 1.0 - qab * x / qap
    d = tiny if abs(d) < tiny else d
    d = 1.0 / d
    h = d
    for mm in range(1, 1000):
        m2 = 2 * mm
        aa = mm * (b - mm) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = tiny if abs(d) < tiny else d
        c = 1.0 + aa / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        h *= d * c
        aa = -(a + mm) * (qab + mm) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = tiny if abs(d) < tiny else d
        c = 1.0 + aa / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return h


def _betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta function ``I_x(a, b)`` for ``0 <= x <= 1``."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    ln_front = (
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    front = math.exp(ln_front)
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def _t_cdf(x: float, df: float) -> float:
    """Student-t cumulative distribution function."""
    tail = 0.5 * _betainc(0.5 * df, 0.5, df / (df + x * x))
    return 1.0 - tail if x >= 0.0 else tail


def _bisect_quantile(cdf: Any, p: float) -> float:
    """Invert an increasing, symmetric-about-0 CDF by bracketing and bisection."""
    if p == 0.5:
        return 0.0
    target = p if p > 0.5 else 1.0 - p
    hi = 1.0
    while cdf(hi) < target:
        hi *= 2.0
        if hi > 1e300:
            return math.inf if p > 0.5 else -math.inf
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if cdf(mid) < target:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-14 * max(1.0, hi):
            break
    q = 0.5 * (lo + hi)
    return q if p > 0.5 else -q


def _check_probability(name: str, p: float) -> float:
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ValueError(f"{name}: must be in (0, 1), got {p}")
    return p


def normal_quantile(p: float) -> float:
    """Quantile of the standard normal distribution (bisection on ``erfc``, ~1e-14).

    Args:
        p: Probability in (0, 1).

    Returns:
        ``z`` with ``Phi(z) = p``.

    Raises:
        ValueError: If ``p`` is outside (0, 1).
    """
    p = _check_probability("p", p)
    return _bisect_quantile(lambda x: 0.5 * math.erfc(-x / math.sqrt(2.0)), p)


def t_quantile(p: float, df: float) -> float:
    """Quantile of Student's t distribution, without scipy.

    The CDF is ``1 - I_{df/(df+t^2)}(df/2, 1/2) / 2`` for ``t >= 0`` (``I`` the regularised
    incomplete beta function, evaluated by its continued fraction with Lentz's method); the
    quantile is found by bracketing and bisection to a relative tolerance of 1e-14, so the
    result is accurate to about 1e-10 (e.g. ``t_quantile(0.975, 1) = 12.7062047``,
    ``t_quantile(0.975, 4) = 2.7764451``, ``t_quantile(0.975, 29) = 2.0452296``).
    ``df = 1`` and ``df = 2`` use their closed forms.

    Args:
        p: Probability in (0, 1).
        df: Degrees of freedom, ``> 0`` (non-integer allowed).

    Returns:
        ``t`` with ``P(T <= t) = p``.

    Raises:
        ValueError: If ``p`` is outside (0, 1) or ``df <= 0``.
    """
    p = _check_probability("p", p)
    df = float(df)
    if not df > 0.0 or not math.isfinite(df):
        raise ValueError(f"df: must be a finite number > 0, got {df}")
    if df == 1.0:
        return math.tan(math.pi * (p - 0.5))
    if df == 2.0:
        return (2.0 * p - 1.0) / math.sqrt(2.0 * p * (1.0 - p))
    return _bisect_quantile(lambda x: _t_cdf(x, df), p)


def t_interval(values: ArrayLike, confidence: float = 0.95) -> tuple[float, float]:
    """Student-t confidence interval for the mean of ``values`` (NaNs ignored).

    ``mean +/- t_{(1+confidence)/2, n-1} * s / sqrt(n)`` with ``s`` the sample standard
    deviation (ddof=1) and ``n`` the number of finite values.

    Args:
        values: Sample values.
        confidence: Confidence level in (0, 1).

    Returns:
        ``(low, high)``; ``(NaN, NaN)`` when fewer than two finite values.
    """
    confidence = _check_probability("confidence", confidence)
    arr = np.asarray(values, dtype=np.float64).ravel()
    arr = arr[np.isfinite(arr)]
    n = arr.size
    if n < 2:
        return math.nan, math.nan
    mean = float(arr.mean())
    half = t_quantile(0.5 * (1.0 + confidence), n - 1) * float(arr.std(ddof=1)) / math.sqrt(n)
    return mean - half, mean + half


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion.

    ``(p + z^2/(2n) -/+ z sqrt(p(1-p)/n + z^2/(4n^2))) / (1 + z^2/n)`` with ``p = k/n`` and
    ``z`` the normal quantile at ``(1+confidence)/2``. At ``k = 0`` it gives
    ``[0, z^2/(n+z^2)]``, at ``k = n`` ``[n/(n+z^2), 1]``.

    Args:
        successes: Number of successes ``k``, ``0 <= k <= n``.
        n: Number of trials.
        confidence: Confidence level in (0, 1).

    Returns:
        ``(low, high)``; ``(NaN, NaN)`` when ``n == 0``.

    Raises:
        ValueError: If ``successes`` is outside ``[0, n]`` or ``n < 0``.
    """
    confidence = _check_probability("confidence", confidence)
    if n < 0 or not 0 <= successes <= n:
        raise ValueError(f"successes: need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return math.nan, math.nan
    z = normal_quantile(0.5 * (1.0 + confidence))
    p = successes / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2.0 * n)) / denom
    half = z * math.sqrt(p * (1.0 - p) / n + z2 / (4.0 * n * n)) / denom
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high


# --------------------------------------------------------------------------------------------
# Aggregation over episodes
# --------------------------------------------------------------------------------------------


def flatten_metrics(metrics: EpisodeMetrics | Mapping[str, Any]) -> dict[str, float | bool]:
    """Flatten one episode's metrics into ``{"dotted.key": scalar}``.

    Keys are ``episode.<field>`` and ``uav.<name>.<field>`` (nested fields and per-axis
    values joined with dots, e.g. ``uav.uav_2.deviation.max_abs.z``). Identifier fields
    (``name``, ``index``, ``*_index``, ``hold_time``, ``n_uavs``, ``n_obstacles``) and the
    ``config`` block are left out.

    Args:
        metrics: An :class:`EpisodeMetrics` or its ``to_dict()``.

    Returns:
        Flat dict of float / int / bool values.
    """
    d = metrics.to_dict() if isinstance(metrics, EpisodeMetrics) else metrics
    skip = {"name", "index", "hold_time", "n_uavs", "n_obstacles"}
    out: dict[str, float | bool] = {}

    def walk(prefix: str, node: Any) -> None:
        for key, value in node.items():
            if key in skip or key.endswith("_index"):
                continue
            path = f"{prefix}.{key}"
            if isinstance(value, Mapping):
                walk(path, value)
            elif isinstance(value, (bool, np.bool_)):
                out[path] = bool(value)
            elif isinstance(value, (int, float, np.integer, np.floating)):
                out[path] = float(value)
            elif value is None:
                out[path] = math.nan

    walk("episode", d["episode"])
    for i, u in enumerate(d["uavs"]):
        walk(f"uav.{u.get('name', f'uav_{i}')}", u)
    return out


def aggregate(
    metrics: Sequence[EpisodeMetrics | Mapping[str, Any]], confidence: float = 0.95
) -> dict[str, dict[str, Any]]:
    """Aggregate scalar metrics over episodes.

    Every key of :func:`flatten_metrics` present in at least one episode is aggregated.
    Numeric keys give ``{"kind": "mean", "n", "n_valid", "mean", "std", "min", "max", "sum",
    "ci_low", "ci_high", "confidence"}`` (``std`` with ddof=1, Student-t interval; NaNs and
    episodes lacking the key are not valid values). Boolean keys give ``{"kind": "rate", "n",
    "n_valid", "successes", "rate", "mean" (= rate), "std" (NaN), "min", "max", "sum",
    "ci_low", "ci_high", "confidence"}`` with a Wilson score interval. ``n`` is the number of
    episodes aggregated.

    Args:
        metrics: Per-episode metrics (objects or their ``to_dict()``).
        confidence: Confidence level of the intervals, in (0, 1).

    Returns:
        Dict keyed by dotted metric name, in first-seen order.
    """
    confidence = _check_probability("confidence", confidence)
    flats = [flatten_metrics(m) for m in metrics]
    keys: dict[str, bool] = {}
    for f in flats:
        for k, v in f.items():
            keys.setdefault(k, isinstance(v, bool))
    n_ep = len(flats)
    out: dict[str, dict[str, Any]] = {}
    for key, is_bool in keys.items():
        present = [f[key] for f in flats if key in f]
        if is_bool:
            vals = np.asarray([bool(v) for v in present], dtype=bool)
            k = int(vals.sum())
            n_valid = int(vals.size)
            rate = k / n_valid if n_valid else math.nan
            low, high = wilson_interval(k, n_valid, confidence)
            out[key] = {
                "kind": "rate",
                "n": n_ep,
                "n_valid": n_valid,
                "successes": k,
                "rate": rate,
                "mean": rate,
                "std": math.nan,
                "min": float(vals.min()) if n_valid else math.nan,
                "max": float(vals.max()) if n_valid else math.nan,
                "sum": float(k),
                "ci_low": low,
                "ci_high": high,
                "confidence": confidence,
            }
        else:
            arr = np.asarray(present, dtype=np.float64)
            arr = arr[np.isfinite(arr)]
            n_valid = int(arr.size)
            low, high = t_interval(arr, confidence)
            out[key] = {
                "kind": "mean",
                "n": n_ep,
                "n_valid": n_valid,
                "mean": float(arr.mean()) if n_valid else math.nan,
                "std": float(arr.std(ddof=1)) if n_valid >= 2 else math.nan,
                "min": float(arr.min()) if n_valid else math.nan,
                "max": float(arr.max()) if n_valid else math.nan,
                "sum": float(arr.sum()),
                "ci_low": low,
                "ci_high": high,
                "confidence": confidence,
            }
    return out


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------

_UAV_COLUMNS: tuple[str, ...] = (
    "min_uav_separation",
    "min_obstacle_distance",
    "min_region_distance",
    "uav_los_events",
    "obstacle_los_events",
    "collision",
    "deviation.max_norm",
    "deviation.rms_norm",
    "timeline.t_leave",
    "timeline.t_resolved",
    "timeline.t_back",
    "timeline.conflict_duration",
    "path_length_ratio",
)

_EPISODE_COLUMNS: tuple[str, ...] = (
    "min_uav_separation",
    "min_obstacle_distance",
    "min_region_distance",
    "uav_los_events",
    "obstacle_los_events",
    "collision",
    "max_deviation",
    "max_conflict_duration",
)

_AGG_COLUMNS: tuple[str, ...] = (
    "metric",
    "kind",
    "mean",
    "std",
    "ci_low",
    "ci_high",
    "min",
    "max",
    "n_valid",
)


def _lookup(d: Mapping[str, Any], dotted: str) -> Any:
    node: Any = d
    for part in dotted.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return math.nan
        node = node[part]
    return node


def summary_table(
    data: Mapping[str, Mapping[str, Any]] | EpisodeMetrics | Sequence[EpisodeMetrics],
    keys: Sequence[str] | None = None,
) -> list[tuple[Any, ...]]:
    """Build table rows; the first row is the header.

    * ``aggregate(...)`` output: one row per metric with columns ``metric, kind, mean, std,
      ci_low, ci_high, min, max, n_valid``; ``keys`` selects (and orders) metrics, matched
      exactly or as a dotted suffix (``"episode.collision"`` or ``"collision"``).
    * One :class:`EpisodeMetrics`: one row per UAV, ``keys`` = dotted per-UAV fields
      (default: separation, loss of separation, deviation and timeline).
    * A sequence of :class:`EpisodeMetrics`: one row per episode, ``keys`` = dotted
      episode-summary fields.

    Args:
        data: What to tabulate.
        keys: Metric or column selection, see above.

    Returns:
        Rows as tuples, header first; pass them to :func:`format_table`.
    """
    if isinstance(data, EpisodeMetrics):
        cols = tuple(keys) if keys is not None else _UAV_COLUMNS
        rows: list[tuple[Any, ...]] = [("uav", *cols)]
        for u in data.uavs:
            ud = u.to_dict()
            rows.append((u.name, *(_lookup(ud, c) for c in cols)))
        return rows
    if isinstance(data, Mapping):
        rows = [_AGG_COLUMNS]
        names = list(data.keys())
        if keys is not None:
            chosen: list[str] = []
            for k in keys:
                chosen.extend(n for n in names if n == k or n.endswith("." + k))
            names = list(dict.fromkeys(chosen))
        for name in names:
            s = data[name]
            rows.append((name, *(s.get(c, math.nan) for c in _AGG_COLUMNS[1:])))
        return rows
    cols = tuple(keys) if keys is not None else _EPISODE_COLUMNS
    rows = [("episode", *cols)]
    for i, em in enumerate(data):
        ed = em.episode.to_dict()
        rows.append((i, *(_lookup(ed, c) for c in cols)))
    return rows


def _format_cell(value: Any, floatfmt: str) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if math.isnan(value):
            return "nan"
        return format(float(value), floatfmt)
    if isinstance(value, Mapping):
        return "(" + ", ".join(_format_cell(v, floatfmt) for v in value.values()) + ")"
    if value is None:
        return "-"
    return str(value)


def format_table(
    rows: Sequence[Sequence[Any]],
    headers: Sequence[str] | None = None,
    floatfmt: str = ".4g",
) -> str:
    """Format rows as a plain-text table.

    Text columns are left-aligned, numeric columns right-aligned; a dashed rule separates
    the header. Floats use ``floatfmt``, booleans print as ``yes``/``no``.

    Args:
        rows: Table rows. When ``headers`` is None the first row is the header (the shape
            :func:`summary_table` returns).
        headers: Column headers, or None.
        floatfmt: Format spec for floats.

    Returns:
        The table as a string (no trailing newline).

    Raises:
        ValueError: If a row's length differs from the header's.
    """
    rows = [tuple(r) for r in rows]
    if headers is None:
        if not rows:
            return ""
        headers, body = tuple(str(h) for h in rows[0]), rows[1:]
    else:
        headers, body = tuple(str(h) for h in headers), rows
    width = len(headers)
    for r in body:
        if len(r) != width:
            raise ValueError(f"rows: a row has {len(r)} cells, the header has {width}")
    cells = [[_format_cell(v, floatfmt) for v in r] for r in body]
    numeric = [
        bool(body)
        and all(
            isinstance(r[j], (int, float, np.integer, np.floating)) and not isinstance(r[j], bool)
            for r in body
        )
        for j in range(width)
    ]
    widths = [max([len(headers[j])] + [len(c[j]) for c in cells]) for j in range(width)]

    def line(values: Sequence[str]) -> str:
        parts = [
            v.rjust(widths[j]) if numeric[j] else v.ljust(widths[j]) for j, v in enumerate(values)
        ]
        return "  ".join(parts).rstrip()

    out = [line(headers), "  ".join("-" * w for w in widths)]
    out.extend(line(c) for c in cells)
    return "\n".join(out)
