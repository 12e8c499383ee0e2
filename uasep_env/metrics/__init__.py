"""Episode metrics for UAV-formation separation management (paper section 4).

This package turns one recorded episode (an :class:`EpisodeRecord`, :mod:`.record`) into the
quantities the paper reports in section 4 (:func:`episode_metrics`, :mod:`.episode`; result
types in :mod:`.results`), and aggregates them over many episodes (:func:`aggregate`,
:mod:`.aggregate`, with the intervals of :mod:`.statistics`):

* **Safety** (section 4.3, figures 8-9): UAV-UAV and UAV-obstacle centre distances
  (:mod:`.distances`) against the collision distance and the loss-of-separation thresholds,
  the distance to each obstacle's predicted reachable region, counts of loss-of-separation /
  collision events and the time spent in loss of separation.
* **Trajectory deviation** (section 4.4.1, figures 10-11): deviation of the true position from
  the planned position, as a norm and per axis, and the conflict-resolution timeline (the
  paper's UAV3 "started to move away from the planned trajectory at 103 s, successfully
  resolved the conflict at 122 s, and returned to the planned trajectory at 130 s. The entire
  conflict resolution took 27 s"; the previous method's 110 s / 121 s / 148 s, 38 s). Its exact
  definition: :mod:`.families`.
* **Velocity and acceleration fluctuation** (section 4.4.2, figures 12-14): per-axis standard
  deviation and largest change per second.
* **Path-length ratio**: flown path length over planned path length.
* **Cost** (the cost channel of constrained RL, :mod:`uasep_env.interface.costs`): each
  UAV's episode cost, its per-step costs (``EpisodeRecord.step_cost``) summed over the
  episode; for the episode the team mean over UAVs and the worst UAV's. NaN when the record
  carries no cost.

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

Aggregation over episodes (:func:`aggregate`): every numeric scalar gets mean, sample standard
deviation (ddof=1), min, max, sum, the number of episodes ``n`` and of finite values
``n_valid``, and a two-sided Student-t confidence interval for the mean
``mean +/- t_{(1+c)/2, n_valid-1} * std / sqrt(n_valid)``. Every boolean is treated as a rate
(fraction of episodes where it is True) with a Wilson score interval. NaNs are ignored.
Text tables: :mod:`.summary`.
"""

from uasep_env.metrics.aggregate import aggregate, flatten_metrics
from uasep_env.metrics.distances import obstacle_distances, pairwise_uav_distances
from uasep_env.metrics.episode import episode_metrics
from uasep_env.metrics.families import (
    conflict_timelines,
    deviation_stats,
    fluctuation_stats,
    path_lengths,
    rising_edge_counts,
    trajectory_deviation,
)
from uasep_env.metrics.record import EpisodeRecord
from uasep_env.metrics.results import (
    ConflictTimeline,
    DeviationStats,
    EpisodeMetrics,
    EpisodeSummary,
    FluctuationStats,
    UAVMetrics,
)
from uasep_env.metrics.statistics import normal_quantile, t_interval, t_quantile, wilson_interval
from uasep_env.metrics.summary import format_table, summary_table

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
