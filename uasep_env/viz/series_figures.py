"""Figures 8-14 of the paper (time series of one episode) and the policies' comparison.

* figure 8: UAV-obstacle distances; figure 9: UAV-UAV distances;
* figures 10-11: deviation from the plan; figures 12-14: velocity and acceleration;
* the vertical acceleration of one UAV under every policy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from uasep_env.metrics import ConflictTimeline, conflict_timelines, trajectory_deviation
from uasep_env.sim.dynamics import AXES
from uasep_env.sim.geometry import uav_distances
from uasep_env.viz.figure_parts import (
    _fig_legend,
    _finish_time_axes,
    _nearest,
    _new_figure,
    _obstacle_dist,
    _shade_region,
    _shade_settle,
    _threshold_lines,
    _title,
    closest_approach,
    most_deviated_uav,
)
from uasep_env.viz.style import AXIS_NAMES, POLICY_STYLES, uav_colour

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from uasep_env.metrics.record import EpisodeRecord
    from uasep_env.rollout import Episode

__all__ = [
    "plot_acceleration_comparison",
    "plot_deviation",
    "plot_obstacle_distances",
    "plot_uav_distances",
    "plot_velocity_acceleration",
]


def _uav_lines(
    ax: Axes, record: EpisodeRecord, values: np.ndarray, lw: float, label: bool = True
) -> None:
    """One line per UAV of ``values`` ``(T, N)`` over time, in its colour (named if ``label``)."""
    for i in range(record.n_uavs):
        ax.plot(
            record.time,
            values[:, i],
            color=uav_colour(i),
            lw=lw,
            label=record.names[i] if label else None,
        )


def plot_obstacle_distances(episode: Episode, label: str = "") -> Figure:
    """Figure 8: distance between each UAV and the obstacle(s) over time.

    Top: centre distances with the collision distance (red dashed) and the UAV-obstacle
    separation distance; log scale, so that both the far field and the close approach read.
    Bottom: signed distance to the obstacle's predicted reachable region (negative inside).
    With several obstacles each UAV's line is its distance to the nearest active one.

    Args:
        episode: The episode.
        label: Policy label (for the title).

    Returns:
        The figure.
    """
    r = episode.record
    d = _obstacle_dist(episode)
    reg = np.where(r.obstacle_active[:, None, :], r.region_distance, np.nan)
    reg = np.where(np.abs(reg) < 1e8, reg, np.nan)
    nearest = r.n_obstacles > 1
    if nearest:  # one line per UAV: its nearest active obstacle / region
        d, reg = _nearest(d), _nearest(reg)
    fig = _new_figure((11.0, 7.5))
    ax, bx = fig.subplots(2, 1, sharex=True, height_ratios=(1.2, 1.0))
    if np.isfinite(d).any():
        _uav_lines(ax, r, d[:, :, 0], lw=1.4)
        _uav_lines(bx, r, reg[:, :, 0], lw=1.4)
    _threshold_lines(ax, r.collision_distance, r.obstacle_separation)
    if np.isfinite(d).any():
        ax.set_yscale("log")
        ax.set_ylim(max(0.5, 0.5 * r.collision_distance), None)
    ax.set_ylabel("UAV–obstacle distance (m, log)")
    ax.set_title("centre distance" + (" to the nearest obstacle" if nearest else ""), fontsize=11)
    bx.axhline(0.0, color="k", lw=1.0, label="region boundary")
    _shade_region(bx, episode, label=True)
    _shade_region(ax, episode)
    bx.set_ylabel("distance to reachable region (m)")
    bx.set_title(
        "distance to the "
        + ("nearest obstacle's" if nearest else "obstacle's")
        + " predicted reachable region (negative: inside)",
        fontsize=11,
    )
    fin = reg[np.isfinite(reg)]
    if fin.size:  # keep the encounter readable: clip the far field
        hi = min(float(fin.max()), max(150.0, 4.0 * abs(float(fin.min()))))
        bx.set_ylim(min(float(fin.min()), 0.0) - 5.0, hi)
    _fig_legend(fig, [ax, bx])
    _finish_time_axes([ax, bx], episode)
    fig.suptitle(f"UAV–obstacle safety distances — {_title(label)}", fontsize=12)
    return fig


def plot_uav_distances(episode: Episode, label: str = "") -> Figure:
    """Figure 9: distances between the UAVs of the formation over time.

    One line per pair (per UAV, to its nearest neighbour, beyond 10 pairs), with the
    collision distance (red dashed) and the UAV-UAV separation distance.

    Args:
        episode: The episode.
        label: Policy label (for the title).

    Returns:
        The figure.
    """
    r = episode.record
    n = r.n_uavs
    dd = uav_distances(r.uav_pos)
    fig = _new_figure((11.0, 5.5))
    ax = fig.subplots()
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if len(pairs) <= 10:
        for p, (i, j) in enumerate(pairs):
            ax.plot(
                r.time,
                dd[:, i, j],
                color=uav_colour(p),
                lw=1.5,
                label=f"{r.names[i]} – {r.names[j]}",
            )
    else:
        dd[:, np.arange(n), np.arange(n)] = np.inf
        nearest = dd.min(axis=2)
        for i in range(n):
            ax.plot(
                r.time,
                nearest[:, i],
                color=uav_colour(i),
                lw=1.0,
                label=f"{r.names[i]} nearest" if i < 10 else None,
            )
    _threshold_lines(ax, r.collision_distance, r.uav_separation)
    _shade_region(ax, episode, label=True)
    ax.set_ylim(0.0, None)
    ax.set_ylabel("UAV–UAV distance (m)")
    _fig_legend(fig, [ax])
    _finish_time_axes([ax], episode)
    ax.set_title(f"Distances between the UAVs — {_title(label)}", fontsize=12)
    return fig


# --------------------------------------------------------------------------------------------
# Figures 10-14: deviation, velocity, acceleration
# --------------------------------------------------------------------------------------------


def _timeline_lines(ax: Axes, tl: ConflictTimeline, name: str, label: bool) -> None:
    marks = (
        ("t_leave", "leaves", "--"),
        ("t_resolved", "resolved", "-."),
        ("t_back", "back", ":"),
    )
    for attr, verb, ls in marks:
        value = getattr(tl, attr)
        if math.isfinite(value):
            ax.axvline(
                value,
                color="k",
                ls=ls,
                lw=1.0,
                label=f"{name} {verb} at {value:.1f} s" if label else None,
            )


def plot_deviation(episode: Episode, label: str = "") -> Figure:
    """Figures 10-11: deviation from the planned trajectory per axis and UAV.

    Vertical lines mark the conflict-resolution timeline of the most deviated UAV (leaves the
    plan, resolves the conflict, is back on the plan; see :mod:`uasep_env.metrics`).

    Args:
        episode: The episode.
        label: Policy label (for the title).

    Returns:
        The figure.
    """
    r = episode.record
    dev = trajectory_deviation(r)
    worst = most_deviated_uav(episode)
    tl = conflict_timelines(r)[worst]
    fig = _new_figure((11.0, 8.5))
    axs = fig.subplots(3, 1, sharex=True)
    for a, ax in enumerate(axs):
        _shade_settle(ax, episode, label=a == 0)
        _uav_lines(ax, r, dev[:, :, a], lw=1.4, label=a == 0)
        _timeline_lines(ax, tl, r.names[worst], label=a == 0)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel(f"{AXIS_NAMES[AXES[a]]} deviation (m)")
        settled = dev[r.settled_mask(), :, a]
        if settled.size:  # scale on the statistics period: forming-up transients may clip
            lim = max(1.15 * float(np.abs(settled).max()), 0.5 * r.deviation_threshold)
            ax.set_ylim(-lim, lim)
    duration = tl.conflict_duration
    extra = (
        f"; {r.names[worst]} in conflict resolution for {duration:.1f} s"
        if math.isfinite(duration)
        else ""
    )
    _fig_legend(fig, list(axs), ncol=4)
    _finish_time_axes(list(axs), episode)
    fig.suptitle(
        f"Deviation from the planned trajectory — {_title(label)}{extra}\n"
        f"(off track: deviation > {r.deviation_threshold:g} m; back: within it for "
        f"{tl.hold_time:g} s; y scaled to the period after forming up)",
        fontsize=12,
    )
    return fig


def plot_velocity_acceleration(
    episode: Episode, label: str = "", accel_limit: float | None = None
) -> Figure:
    """Figures 12-14: velocity (left) and acceleration (right) per axis and UAV.

    Args:
        episode: The episode.
        label: Policy label (for the title).
        accel_limit: Per-axis acceleration bound (m/s^2) drawn as grey dashed lines, or None.

    Returns:
        The figure.
    """
    r = episode.record
    fig = _new_figure((13.0, 8.5))
    axs = fig.subplots(3, 2, sharex=True)
    for a in range(3):
        vax, aax = axs[a]
        for ax in (vax, aax):
            _shade_settle(ax, episode, label=(a == 0 and ax is vax))
            _shade_region(ax, episode, label=(a == 0 and ax is aax))
        _uav_lines(vax, r, r.uav_vel[:, :, a], lw=1.2, label=a == 0)
        _uav_lines(aax, r, r.uav_acc[:, :, a], lw=1.2, label=False)
        if accel_limit is not None:
            for s in (-1.0, 1.0):
                aax.axhline(
                    s * accel_limit,
                    color="0.4",
                    ls="--",
                    lw=0.9,
                    label="acceleration bound" if (a == 0 and s > 0) else None,
                )
        vax.set_ylabel(f"v {AXIS_NAMES[AXES[a]]} (m/s)")
        aax.set_ylabel(f"a {AXIS_NAMES[AXES[a]]} (m/s²)")
    axs[0, 0].set_title("velocity", fontsize=11)
    axs[0, 1].set_title("acceleration", fontsize=11)
    _fig_legend(fig, list(axs.ravel()))
    _finish_time_axes(list(axs[:, 0]), episode)
    _finish_time_axes(list(axs[:, 1]), episode)
    fig.suptitle(f"Velocity and acceleration — {_title(label)}", fontsize=12)
    return fig


def plot_acceleration_comparison(
    episodes_by_policy: Mapping[str, Episode],
    uav: int | None = None,
    axis: int = 2,
    window: float = 30.0,
) -> Figure:
    """Acceleration of one UAV along one axis under every policy, on one axes.

    Top: the whole episode, every policy on the same axes. Bottom: the same, zoomed on the
    encounter (``window`` seconds either side of the closest approach in the first episode).
    The legend gives each policy's standard deviation after ``settle_time``.

    Args:
        episodes_by_policy: One episode per policy (the same seed, for a fair comparison).
        uav: UAV index; None: the most deviated UAV over all the episodes.
        axis: 0, 1 or 2 for x (north), y (east), z (down).
        window: Half-width of the zoom (s).

    Returns:
        The figure.
    """
    eps = list(episodes_by_policy.values())
    if uav is None:
        uav = most_deviated_uav(eps)
    name = eps[0].record.names[uav]
    ax_name = AXIS_NAMES[AXES[axis]]
    approaches = closest_approach(eps[0])
    fig = _new_figure((11.0, 7.5 if approaches else 5.0))
    axs = fig.subplots(2, 1, height_ratios=(1.0, 1.0)) if approaches else [fig.subplots()]
    t_lo = min(float(ep.record.time[0]) for ep in eps)
    t_hi = max(float(ep.record.time[-1]) for ep in eps)
    for ax in axs:
        for p, (label, ep) in enumerate(episodes_by_policy.items()):
            r = ep.record
            colour, ls = POLICY_STYLES[p % len(POLICY_STYLES)]
            sel = r.settled_mask()
            std = float(np.std(r.uav_acc[sel, uav, axis])) if sel.any() else math.nan
            ax.plot(
                r.time,
                r.uav_acc[:, uav, axis],
                color=colour,
                ls=ls,
                lw=1.4,
                label=f"{_title(label)} (std {std:.3f} m/s²)",
            )
        _shade_settle(ax, eps[0], label=True)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel(f"a {ax_name} (m/s²)")
        ax.grid(True, alpha=0.3)
        ax.set_xlim(t_lo, t_hi)
    axs[0].set_title("whole episode", fontsize=11)
    if approaches:
        t_star = float(eps[0].record.time[approaches[0][1]])
        axs[1].set_xlim(max(t_lo, t_star - window), min(t_hi, t_star + window))
        axs[1].set_title(f"around the closest approach (t = {t_star:.1f} s)", fontsize=11)
    axs[-1].set_xlabel("time (s)")
    _fig_legend(fig, axs[:1], ncol=2)
    fig.suptitle(
        f"Acceleration along {ax_name} of {name} (the most deviated UAV) — all methods, same seed",
        fontsize=12,
    )
    return fig
