"""The result types of the episode metrics: per-UAV families, per-UAV and episode summaries.

Each is a frozen dataclass whose :meth:`~_Plain.to_dict` is its JSON layout (through
:func:`uasep_env.runtime.jsonio.to_plain`): nested results become dicts, per-axis triples
``{"x": ..., "y": ..., "z": ...}``. Definitions of every quantity: :mod:`uasep_env.metrics`.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field
from typing import Any, TypeVar

from uasep_env.runtime.jsonio import PLAIN, dumps, to_plain
from uasep_env.sim.dynamics import AXES

__all__ = [
    "Axis3",
    "ConflictTimeline",
    "DeviationStats",
    "EpisodeMetrics",
    "EpisodeSummary",
    "FluctuationStats",
    "UAVMetrics",
]

Axis3 = tuple[float, float, float]


def _axis_dict(value: Axis3) -> dict[str, float]:
    return {ax: float(v) for ax, v in zip(AXES, value, strict=True)}


#: Metadata of a per-axis (x, y, z) field: written ``{"x": ..., "y": ..., "z": ...}``.
_PER_AXIS = {PLAIN: _axis_dict}

_T = TypeVar("_T")


def _result(cls: type[_T]) -> type[_T]:
    """A result type: a frozen, keyword-only dataclass whose ``Axis3`` fields are per-axis.

    A field annotated ``Axis3`` gets :data:`_PER_AXIS` (written ``{"x", "y", "z"}``), so
    that the annotation alone says so.
    """
    for name, annotation in inspect.get_annotations(cls).items():
        if annotation == "Axis3":  # the annotations are strings (postponed evaluation)
            setattr(cls, name, field(metadata=_PER_AXIS))
    return dataclass(frozen=True, kw_only=True)(cls)


class _Plain:
    """``to_dict`` of the result dataclasses: their JSON layout, NaN / inf kept as floats."""

    def to_dict(self) -> dict[str, Any]:
        """Return a plain, JSON-serialisable dict (NaN/inf are kept as Python floats).

        Returns:
            Nested dict of bool / int / float / str / None. Per-axis triples are written
            as ``{"x": ..., "y": ..., "z": ...}``.
        """
        return to_plain(self)


@_result
class DeviationStats(_Plain):
    """Deviation from the planned trajectory of one UAV after ``settle_time`` (m, s).

    Attributes:
        max_norm: Largest deviation norm ``|p - p_planned|`` (m).
        rms_norm: Root mean square of the deviation norm (m).
        max_abs: Per-axis (x, y, z) largest absolute deviation (m).
        rms: Per-axis (x, y, z) root mean square deviation (m).
        time_off_track: Samples with deviation ``> deviation_threshold`` times dt (s).
        max_norm_time: Time of the largest deviation norm (s).
    """

    max_norm: float
    rms_norm: float
    max_abs: Axis3
    rms: Axis3
    time_off_track: float
    max_norm_time: float


@_result
class ConflictTimeline(_Plain):
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


@_result
class FluctuationStats(_Plain):
    """Velocity and acceleration fluctuation of one UAV after ``settle_time``, per axis.

    Attributes:
        vel_std: Per-axis population standard deviation (ddof=0) of velocity (m/s).
        acc_std: Per-axis population standard deviation of acceleration (m/s^2).
        vel_max_rate: Per-axis ``max |v[k+1] - v[k]| / dt`` (m/s^2); NaN with < 2 samples.
        acc_max_rate: Per-axis ``max |a[k+1] - a[k]| / dt`` (m/s^3); NaN with < 2 samples.
        acc_max_abs: Per-axis largest absolute acceleration (m/s^2).
        speed_max: Largest speed ``|v|`` (m/s).
    """

    vel_std: Axis3
    acc_std: Axis3
    vel_max_rate: Axis3
    acc_max_rate: Axis3
    acc_max_abs: Axis3
    speed_max: float


@_result
class UAVMetrics(_Plain):
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
        cost: The UAV's episode cost: the sum over the episode's steps of its per-step cost
            (the cost channel, :mod:`uasep_env.interface.costs`; ``infos[agent]["cost"]``),
            a weighted number of steps, whole episode (``settle_time`` does not apply).
            With the default weights, the steps it spent in loss of separation. NaN when
            the record has no cost (:attr:`EpisodeRecord.step_cost` None).
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
    cost: float = math.nan


@_result
class EpisodeSummary(_Plain):
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
        cost: The team's episode cost: the mean over UAVs of their episode costs
            (:attr:`UAVMetrics.cost`), i.e. the sum over steps of the centralised
            ``info["cost"]`` (the mean of the agents' costs, as the reward is the mean of
            theirs). NaN without a recorded cost.
        max_uav_cost: The largest episode cost of one UAV (the worst agent's). NaN without
            a recorded cost.
    """

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
    cost: float = math.nan
    max_uav_cost: float = math.nan


@_result
class EpisodeMetrics(_Plain):
    """All metrics of one episode.

    Attributes:
        episode: Whole-episode summary.
        uavs: Per-UAV metrics, in record order.
        config: Thresholds and parameters used (m, s), for provenance.
    """

    episode: EpisodeSummary
    uavs: tuple[UAVMetrics, ...]
    config: dict[str, float] = field(default_factory=dict)

    def to_json(self, **kwargs: Any) -> str:
        """Return strict JSON (non-finite floats written as ``null``).

        Args:
            **kwargs: Passed on to :func:`json.dumps` (e.g. ``indent``).

        Returns:
            A JSON string.
        """
        return dumps(self, **kwargs)

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
