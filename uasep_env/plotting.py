"""The paper's figures (section 4, figures 7-14) from recorded episodes, headless.

:func:`plot_paper_figures` writes, for each policy's episode:

* ``trajectory_3d_<policy>.png`` (figure 7): the UAVs' 3D trajectories with their planned
  trajectories, the obstacle's trajectory and its predicted reachable ellipsoid at the moment
  of closest approach, with a plan view and an altitude profile around the encounter;
* ``obstacle_distance_<policy>.png`` (figure 8): UAV-obstacle centre distances and the
  distances to the obstacle's predicted reachable region, with the collision distance;
* ``uav_distance_<policy>.png`` (figure 9): UAV-UAV distances with the collision and
  separation distances;
* ``deviation_<policy>.png`` (figures 10-11): deviation from the planned trajectory per axis
  (x north, y east, z down) and per UAV, with the conflict-resolution timeline;
* ``velocity_acceleration_<policy>.png`` (figures 12-14): velocity and acceleration per axis
  and per UAV;

and ``acceleration_z_comparison.png``: the vertical acceleration of the most deviated UAV under
every policy on one axes.

Frames: the simulator is NED (x north, y east, z down). 3D and plan views show east on the
horizontal axis, north on the vertical one and altitude ``-z``; time series keep the NED
components and say so in their labels. UAVs are named ``uav_0 ..`` (the paper's UAV1..UAV3
are ``uav_0..uav_2``; the middle UAV of the paper scenario is ``uav_2``).

matplotlib is imported lazily, inside the functions, and figures are drawn on an Agg canvas
(:class:`matplotlib.figure.Figure`, no pyplot): no window ever opens.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.metrics import (
    ConflictTimeline,
    conflict_timelines,
    obstacle_distances,
    trajectory_deviation,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from uasep_env.rollout import Episode

__all__ = [
    "POLICY_TITLES",
    "closest_approach",
    "ellipsoid_surface",
    "most_deviated_uav",
    "plot_acceleration_comparison",
    "plot_deviation",
    "plot_obstacle_distances",
    "plot_paper_figures",
    "plot_trajectory_3d",
    "plot_uav_distances",
    "plot_velocity_acceleration",
]

#: Readable titles of the built-in policies (others are shown by their label).
POLICY_TITLES: dict[str, str] = {
    "apf": "APF with trajectory prediction (proposed)",
    "motion-state-apf": "motion-state APF (previous method)",
    "traditional-apf": "traditional APF",
    "zero": "zero action",
    "random": "random actions",
}

_UAV_COLOURS = (
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
    "tab:gray",
)
_POLICY_STYLES = (
    ("tab:blue", "-"),
    ("tab:green", "--"),
    ("tab:red", "-."),
    ("tab:purple", ":"),
    ("tab:orange", "-"),
    ("tab:brown", "--"),
)
_OBSTACLE_COLOUR = "tab:red"
_COLLISION_COLOUR = "red"
_SEPARATION_COLOUR = "darkorange"
_AXES = ("x", "y", "z")
_AXIS_NAMES = {"x": "x (north)", "y": "y (east)", "z": "z (down)"}
_DPI = 130


def _colour(i: int) -> str:
    return _UAV_COLOURS[i % len(_UAV_COLOURS)]


def _title(label: str) -> str:
    return POLICY_TITLES.get(label, label)


def _slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", label).strip("-") or "policy"


def _new_figure(figsize: tuple[float, float], constrained: bool = True) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained" if constrained else None)


def _save(fig: Figure, path: Path, dpi: int) -> Path:
    fig.savefig(path, dpi=dpi, facecolor="white")
    return path


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------


def ellipsoid_surface(
    center: np.ndarray, axes: np.ndarray, heading: float, n_lon: int = 33, n_lat: int = 17
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid of points on a heading-aligned ellipsoid, in plot coordinates.

    Args:
        center: ``(3,)`` centre (m, NED).
        axes: ``(3,)`` semi-axes (longitudinal along the heading, lateral to the right,
            vertical) (m).
        heading: Heading (rad from north towards east).
        n_lon: Grid points around the vertical axis.
        n_lat: Grid points from pole to pole.

    Returns:
        ``(east, north, altitude)`` arrays of shape ``(n_lat, n_lon)`` (m).
    """
    u = np.linspace(0.0, 2.0 * math.pi, n_lon)
    v = np.linspace(0.0, math.pi, n_lat)
    lon = axes[0] * np.outer(np.sin(v), np.cos(u))
    lat = axes[1] * np.outer(np.sin(v), np.sin(u))
    vert = axes[2] * np.outer(np.cos(v), np.ones_like(u))
    ch, sh = math.cos(heading), math.sin(heading)
    north = center[0] + lon * ch - lat * sh
    east = center[1] + lon * sh + lat * ch
    return east, north, -(center[2] + vert)


def _ellipse_outline(
    center: np.ndarray, axes: np.ndarray, heading: float, n: int = 97
) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal section through the centre, as ``(east, north)``."""
    u = np.linspace(0.0, 2.0 * math.pi, n)
    lon, lat = axes[0] * np.cos(u), axes[1] * np.sin(u)
    ch, sh = math.cos(heading), math.sin(heading)
    return center[1] + lon * sh + lat * ch, center[0] + lon * ch - lat * sh


def _obstacle_dist(episode: Episode) -> np.ndarray:
    """(T, N, M) UAV-obstacle centre distances, NaN where the obstacle is inactive."""
    r = episode.record
    d = obstacle_distances(r.uav_pos, r.obstacle_pos, r.obstacle_active)
    return np.where(np.isfinite(d), d, np.nan)


def _nearest(values: np.ndarray) -> np.ndarray:
    """(T, N, M) -> (T, N, 1): minimum over the finite values of the last axis, else NaN."""
    low = np.where(np.isfinite(values), values, np.inf).min(axis=2, keepdims=True)
    return np.where(np.isfinite(low), low, np.nan)


def closest_approach(episode: Episode) -> list[tuple[int, int, float]]:
    """Sample of closest approach between the formation and each obstacle.

    Args:
        episode: The episode.

    Returns:
        Per obstacle ever active: ``(obstacle index, sample index, distance)`` where the
        distance is the smallest UAV-obstacle centre distance (m) over UAVs and time.
    """
    d = _obstacle_dist(episode)
    out = []
    for m in range(d.shape[2]):
        dm = d[:, :, m]
        if not np.isfinite(dm).any():
            continue
        per_t = np.nanmin(np.where(np.isfinite(dm), dm, np.inf), axis=1)
        k = int(np.argmin(per_t))
        out.append((m, k, float(per_t[k])))
    return out


def most_deviated_uav(episodes: Episode | Sequence[Episode]) -> int:
    """Index of the UAV with the largest deviation from its plan after ``settle_time``.

    Args:
        episodes: One episode, or several (e.g. one per policy on the same seed): the UAV
            with the largest deviation in any of them.

    Returns:
        The UAV index.
    """
    eps = [episodes] if not isinstance(episodes, Sequence) else list(episodes)
    best = np.zeros(eps[0].record.n_uavs)
    for ep in eps:
        r = ep.record
        dev = np.linalg.norm(trajectory_deviation(r)[r.settled_mask()], axis=-1)
        if dev.size:
            best = np.maximum(best, dev.max(axis=0))
    return int(np.argmax(best))


def _threshold_lines(ax: Axes, collision: float, separation: float) -> None:
    """The collision (red dashed) and loss-of-separation (dotted) distances (m)."""
    ax.axhline(
        collision,
        color=_COLLISION_COLOUR,
        ls="--",
        lw=1.3,
        label=f"collision distance ({collision:g} m)",
    )
    ax.axhline(
        separation,
        color=_SEPARATION_COLOUR,
        ls=":",
        lw=1.3,
        label=f"separation distance ({separation:g} m)",
    )


def _shade_settle(ax: Axes, episode: Episode, label: bool = False) -> None:
    """Grey band over the forming-up period excluded from deviation statistics."""
    r = episode.record
    if r.settle_time > r.time[0]:
        ax.axvspan(
            r.time[0],
            r.settle_time,
            color="0.9",
            zorder=0,
            label="forming up (excluded from statistics)" if label else None,
        )


def _shade_region(ax: Axes, episode: Episode, label: bool = False) -> None:
    """Light red bands where some UAV is inside an obstacle's predicted reachable region."""
    r = episode.record
    inside = (
        ((r.region_distance < 0.0) & r.obstacle_active[:, None, :]).any(axis=(1, 2))
        if r.n_obstacles
        else np.zeros(r.n_steps, dtype=bool)
    )
    if not inside.any():
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
    t = r.time
    first = True
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        ax.axvspan(
            t[a] - 0.5 * r.dt,
            t[b - 1] + 0.5 * r.dt,
            color=_OBSTACLE_COLOUR,
            alpha=0.08,
            lw=0,
            zorder=0,
            label="a UAV inside the predicted region" if label and first else None,
        )
        first = False


def _fig_legend(fig: Figure, axes: Sequence[Axes], ncol: int = 6) -> None:
    """One legend below the axes, with every labelled artist of ``axes`` once."""
    from matplotlib.patches import Patch

    handles: dict[str, Any] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    # lines and markers first, shaded spans last
    handles = dict(sorted(handles.items(), key=lambda kv: isinstance(kv[1], Patch)))
    if handles:  # as many columns as fit in the figure's width
        per_row = fig.get_figwidth() * 72.0 / (9 * 0.6)
        widest = max(len(lab) for lab in handles) + 6
        ncol = max(1, min(ncol, int(per_row // widest)))
        fig.legend(
            list(handles.values()),
            list(handles),
            loc="outside lower center",
            ncol=min(ncol, len(handles)),
            fontsize=9,
            frameon=False,
        )


def _finish_time_axes(axes: Sequence[Axes], episode: Episode) -> None:
    t = episode.record.time
    for ax in axes:
        ax.set_xlim(t[0], t[-1])
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")


# --------------------------------------------------------------------------------------------
# Figure 7: trajectories
# --------------------------------------------------------------------------------------------


def plot_trajectory_3d(episode: Episode, label: str = "") -> Figure:
    """Figure 7: 3D trajectories, planned trajectories, obstacle and reachable ellipsoid.

    Top left: the whole flight in 3D (east, north, altitude), with the UAVs' positions (dots),
    the obstacle (red dot) and its predicted reachable ellipsoid at the moment of closest
    approach. Top right: plan view at that moment, zoomed on the formation and the region
    (the arrow gives the obstacle's direction). Bottom: altitude over time, with the
    ellipsoid's vertical extent at closest approach.

    Args:
        episode: The episode.
        label: Policy label (for the title).

    Returns:
        The figure (Agg canvas).
    """
    import mpl_toolkits.mplot3d  # noqa: F401  (registers the 3d projection)

    r = episode.record
    n, m_obs = r.n_uavs, r.n_obstacles
    pos, plan, t = r.uav_pos, r.planned_pos, r.time
    obs = np.where(r.obstacle_active[..., None], r.obstacle_pos, np.nan)
    approaches = closest_approach(episode)
    k_star = approaches[0][1] if approaches else r.n_steps - 1

    fig = _new_figure((14.0, 10.0), constrained=False)
    gs = fig.add_gridspec(
        2,
        2,
        width_ratios=(1.5, 1.0),
        height_ratios=(2.2, 1.0),
        left=0.06,
        right=0.97,
        bottom=0.12,
        top=0.91,
        wspace=0.08,
        hspace=0.18,
    )
    ax = fig.add_subplot(gs[0, 0], projection="3d")
    top = fig.add_subplot(gs[0, 1])
    side = fig.add_subplot(gs[1, :])

    def enu(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return p[..., 1], p[..., 0], -p[..., 2]

    for i in range(n):
        c = _colour(i)
        ax.plot(*enu(plan[:, i]), color=c, lw=1.0, ls="--", alpha=0.6)
        ax.plot(*enu(pos[:, i]), color=c, lw=1.6, label=r.names[i])
        ax.scatter(*enu(pos[0, i]), color=c, marker="^", s=25)
        ax.scatter(*enu(pos[k_star, i]), color=c, edgecolor="k", s=40, depthshade=False)
        top.plot(plan[:, i, 1], plan[:, i, 0], color=c, lw=1.0, ls="--", alpha=0.6)
        top.plot(pos[:, i, 1], pos[:, i, 0], color=c, lw=1.6, label=r.names[i])
        top.scatter(pos[k_star, i, 1], pos[k_star, i, 0], color=c, edgecolor="k", s=40, zorder=5)
        side.plot(t, -plan[:, i, 2], color=c, lw=1.0, ls="--", alpha=0.6)
        side.plot(t, -pos[:, i, 2], color=c, lw=1.6, label=r.names[i])
    ax.plot(*enu(pos[k_star]), color="0.4", lw=0.8, ls=":")  # formation at t*
    ax.plot([], [], color="0.4", lw=1.0, ls="--", label="planned")
    top.plot([], [], color="0.4", lw=1.0, ls="--", label="planned")
    side.plot([], [], color="0.4", lw=1.0, ls="--", label="planned")

    zoom_pts = []
    for j, (m, k, _dist) in enumerate(approaches):
        lab = "obstacle" if m_obs == 1 else f"obstacle {m}"
        first = j == 0
        ax.plot(
            *enu(obs[:, m]),
            color=_OBSTACLE_COLOUR,
            lw=1.2,
            ls=":",
            label="obstacle trajectory" if first else None,
        )
        ax.scatter(
            *enu(obs[k, m]),
            color=_OBSTACLE_COLOUR,
            s=60,
            depthshade=False,
            label=f"{lab} at closest approach" if first else None,
        )
        top.plot(
            obs[:, m, 1],
            obs[:, m, 0],
            color=_OBSTACLE_COLOUR,
            lw=1.2,
            ls=":",
            label="obstacle trajectory" if first else None,
        )
        top.scatter(obs[k, m, 1], obs[k, m, 0], color=_OBSTACLE_COLOUR, s=60, zorder=6)
        step = obs[min(k + 1, r.n_steps - 1), m] - obs[max(k - 1, 0), m]
        if np.all(np.isfinite(step[:2])) and np.hypot(step[0], step[1]) > 0:
            head = obs[k, m, :2] + 15.0 * step[:2] / np.hypot(step[0], step[1])
            top.annotate(
                "",
                xy=(head[1], head[0]),
                xytext=(obs[k, m, 1], obs[k, m, 0]),
                arrowprops={"arrowstyle": "->", "color": _OBSTACLE_COLOUR, "lw": 1.5},
                zorder=7,
            )
        side.plot(
            t,
            -obs[:, m, 2],
            color=_OBSTACLE_COLOUR,
            lw=1.2,
            ls=":",
            label="obstacle trajectory" if first else None,
        )
        centre = episode.pred_center[k, m]
        axes_m = episode.obstacle_axes[m]
        heading = float(episode.pred_heading[k, m])
        ex, ny, alt = ellipsoid_surface(centre, axes_m, heading)
        ax.plot_surface(ex, ny, alt, color=_OBSTACLE_COLOUR, alpha=0.18, linewidth=0, shade=False)
        ax.plot_wireframe(
            ex, ny, alt, color=_OBSTACLE_COLOUR, alpha=0.35, linewidth=0.4, rstride=4, cstride=4
        )
        oe, on = _ellipse_outline(centre, axes_m, heading)
        top.fill(oe, on, color=_OBSTACLE_COLOUR, alpha=0.15, lw=0)
        top.plot(
            oe,
            on,
            color=_OBSTACLE_COLOUR,
            lw=1.0,
            label=f"reachable region at t = {t[k]:.1f} s" if first else None,
        )
        side.errorbar(
            t[k],
            -centre[2],
            yerr=axes_m[2],
            color=_OBSTACLE_COLOUR,
            capsize=4,
            lw=1.2,
            label="reachable region (vertical extent)" if first else None,
        )
        side.axvline(t[k], color="0.5", lw=0.8, ls=":")
        zoom_pts.append(np.stack([on, oe], axis=-1))
        zoom_pts.append(pos[k, :, :2])
        zoom_pts.append(obs[k, m, None, :2])

    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_zlabel("altitude (m)")
    ax.set_box_aspect((1.0, 1.6, 0.7), zoom=1.2)
    ax.view_init(elev=22.0, azim=-60.0)
    ax.set_title("3D trajectories", fontsize=11)

    top.set_xlabel("east (m)")
    top.set_ylabel("north (m)")
    top.set_aspect("equal", adjustable="box")
    if zoom_pts:  # a square window on the formation and the region at closest approach
        mid = pos[k_star, :, :2].mean(axis=0)
        zp = np.concatenate([z for z in zoom_pts if z.size])
        zp = zp[np.all(np.isfinite(zp), axis=1)]
        half = 1.2 * float(np.abs(zp - mid).max()) + 10.0
        top.set_xlim(mid[1] - half, mid[1] + half)
        top.set_ylim(mid[0] - half, mid[0] + half)
        top.set_title(f"plan view at closest approach (t = {t[k_star]:.1f} s)", fontsize=11)
    else:
        top.set_title("plan view", fontsize=11)
    top.grid(True, alpha=0.3)

    side.set_xlabel("time (s)")
    side.set_ylabel("altitude (m)")
    side.set_xlim(t[0], t[-1])
    side.grid(True, alpha=0.3)
    side.set_title("altitude over time", fontsize=11)

    handles: dict[str, Any] = {}
    for a in (ax, top, side):
        for h, lab in zip(*a.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    fig.legend(
        list(handles.values()),
        list(handles),
        loc="lower center",
        ncol=min(6, len(handles)),
        fontsize=9,
        frameon=False,
    )

    if approaches:
        m, k, dist = approaches[0]
        i_near = int(np.nanargmin(_obstacle_dist(episode)[k, :, m]))
        sub = (
            f"closest approach t = {t[k]:.1f} s: {r.names[i_near]} – obstacle "
            f"{dist:.1f} m; ellipsoid semi-axes "
            f"{', '.join(f'{a:.0f}' for a in episode.obstacle_axes[m])} m"
        )
    else:
        sub = "no active obstacle"
    fig.suptitle(f"Collision avoidance of the formation — {_title(label)}\n{sub}", fontsize=12)
    return fig


# --------------------------------------------------------------------------------------------
# Figures 8-9: safety distances
# --------------------------------------------------------------------------------------------


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
        for i in range(r.n_uavs):
            ax.plot(r.time, d[:, i, 0], color=_colour(i), lw=1.4, label=r.names[i])
            bx.plot(r.time, reg[:, i, 0], color=_colour(i), lw=1.4, label=r.names[i])
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
    diff = r.uav_pos[:, :, None, :] - r.uav_pos[:, None, :, :]
    dd = np.linalg.norm(diff, axis=-1)
    fig = _new_figure((11.0, 5.5))
    ax = fig.subplots()
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if len(pairs) <= 10:
        for p, (i, j) in enumerate(pairs):
            ax.plot(
                r.time,
                dd[:, i, j],
                color=_UAV_COLOURS[p % len(_UAV_COLOURS)],
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
                color=_colour(i),
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
        for i in range(r.n_uavs):
            ax.plot(
                r.time, dev[:, i, a], color=_colour(i), lw=1.4, label=r.names[i] if a == 0 else None
            )
        _timeline_lines(ax, tl, r.names[worst], label=a == 0)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel(f"{_AXIS_NAMES[_AXES[a]]} deviation (m)")
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
        for i in range(r.n_uavs):
            vax.plot(
                r.time,
                r.uav_vel[:, i, a],
                color=_colour(i),
                lw=1.2,
                label=r.names[i] if a == 0 else None,
            )
            aax.plot(r.time, r.uav_acc[:, i, a], color=_colour(i), lw=1.2)
        if accel_limit is not None:
            for s in (-1.0, 1.0):
                aax.axhline(
                    s * accel_limit,
                    color="0.4",
                    ls="--",
                    lw=0.9,
                    label="acceleration bound" if (a == 0 and s > 0) else None,
                )
        vax.set_ylabel(f"v {_AXIS_NAMES[_AXES[a]]} (m/s)")
        aax.set_ylabel(f"a {_AXIS_NAMES[_AXES[a]]} (m/s²)")
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
    ax_name = _AXIS_NAMES[_AXES[axis]]
    approaches = closest_approach(eps[0])
    fig = _new_figure((11.0, 7.5 if approaches else 5.0))
    axs = fig.subplots(2, 1, height_ratios=(1.0, 1.0)) if approaches else [fig.subplots()]
    t_lo = min(float(ep.record.time[0]) for ep in eps)
    t_hi = max(float(ep.record.time[-1]) for ep in eps)
    for ax in axs:
        for p, (label, ep) in enumerate(episodes_by_policy.items()):
            r = ep.record
            colour, ls = _POLICY_STYLES[p % len(_POLICY_STYLES)]
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


# --------------------------------------------------------------------------------------------
# The set
# --------------------------------------------------------------------------------------------


def plot_paper_figures(
    episodes_by_policy: Mapping[str, Episode],
    out_dir: str | Path,
    *,
    dpi: int = _DPI,
    accel_limit: float | None = None,
) -> list[Path]:
    """Write the paper's figure set (figures 7-14 and a comparison) as PNG files.

    Args:
        episodes_by_policy: ``policy label -> episode`` (ideally the same seed for all).
        out_dir: Output folder (created).
        dpi: Resolution.
        accel_limit: Per-axis acceleration bound drawn on the acceleration plots (m/s^2).

    Returns:
        The files written, per policy ``trajectory_3d_``, ``obstacle_distance_``,
        ``uav_distance_``, ``deviation_`` and ``velocity_acceleration_<policy>.png``, then
        ``acceleration_z_comparison.png``.

    Raises:
        ValueError: If ``episodes_by_policy`` is empty.
    """
    if not episodes_by_policy:
        raise ValueError("episodes_by_policy: need at least one episode")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for label, ep in episodes_by_policy.items():
        slug = _slug(label)
        figures: list[tuple[str, Any]] = [
            ("trajectory_3d", plot_trajectory_3d),
            ("obstacle_distance", plot_obstacle_distances),
            ("uav_distance", plot_uav_distances),
            ("deviation", plot_deviation),
        ]
        for stem, fn in figures:
            written.append(_save(fn(ep, label), out / f"{stem}_{slug}.png", dpi))
        fig = plot_velocity_acceleration(ep, label, accel_limit=accel_limit)
        written.append(_save(fig, out / f"velocity_acceleration_{slug}.png", dpi))
    fig = plot_acceleration_comparison(episodes_by_policy)
    written.append(_save(fig, out / "acceleration_z_comparison.png", dpi))
    return written
