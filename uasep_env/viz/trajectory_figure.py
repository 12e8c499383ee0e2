"""Figure 7 of the paper: 3D and planned trajectories, the obstacle and its reachable ellipsoid."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.viz.figure_parts import _new_figure, _obstacle_dist, _title, closest_approach
from uasep_env.viz.shapes import ellipse_outline, ellipsoid_surface, enu
from uasep_env.viz.style import OBSTACLE_COLOUR, uav_colour

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from uasep_env.metrics import EpisodeRecord
    from uasep_env.rollout import Episode

__all__ = ["plot_trajectory_3d"]


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
    t = r.time
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

    _draw_uavs(ax, top, side, r, k_star)
    zoom_pts: list[np.ndarray] = []
    for j, (m, k, _dist) in enumerate(approaches):
        zoom_pts += _draw_encounter(ax, top, side, episode, obs, m, k, first=j == 0)
    _finish_views(ax, top, side, r, k_star, zoom_pts)

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


def _draw_uavs(ax: Axes, top: Axes, side: Axes, r: EpisodeRecord, k_star: int) -> None:
    """Each UAV's flown and planned track in the three views, its position at ``k_star``."""
    n, pos, plan, t = r.n_uavs, r.uav_pos, r.planned_pos, r.time
    for i in range(n):
        c = uav_colour(i)
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


def _draw_encounter(
    ax: Axes,
    top: Axes,
    side: Axes,
    episode: Episode,
    obs: np.ndarray,
    m: int,
    k: int,
    first: bool,
) -> list[np.ndarray]:
    """Obstacle ``m``'s track and its reachable ellipsoid at sample ``k`` in the three views.

    Returns:
        The plan-view points (north, east) the zoom must show: the region's outline, the
        UAVs and the obstacle at ``k``.
    """
    r, t = episode.record, episode.record.time
    lab = "obstacle" if r.n_obstacles == 1 else f"obstacle {m}"
    ax.plot(
        *enu(obs[:, m]),
        color=OBSTACLE_COLOUR,
        lw=1.2,
        ls=":",
        label="obstacle trajectory" if first else None,
    )
    ax.scatter(
        *enu(obs[k, m]),
        color=OBSTACLE_COLOUR,
        s=60,
        depthshade=False,
        label=f"{lab} at closest approach" if first else None,
    )
    top.plot(
        obs[:, m, 1],
        obs[:, m, 0],
        color=OBSTACLE_COLOUR,
        lw=1.2,
        ls=":",
        label="obstacle trajectory" if first else None,
    )
    top.scatter(obs[k, m, 1], obs[k, m, 0], color=OBSTACLE_COLOUR, s=60, zorder=6)
    step = obs[min(k + 1, r.n_steps - 1), m] - obs[max(k - 1, 0), m]
    if np.all(np.isfinite(step[:2])) and np.hypot(step[0], step[1]) > 0:
        head = obs[k, m, :2] + 15.0 * step[:2] / np.hypot(step[0], step[1])
        top.annotate(
            "",
            xy=(head[1], head[0]),
            xytext=(obs[k, m, 1], obs[k, m, 0]),
            arrowprops={"arrowstyle": "->", "color": OBSTACLE_COLOUR, "lw": 1.5},
            zorder=7,
        )
    side.plot(
        t,
        -obs[:, m, 2],
        color=OBSTACLE_COLOUR,
        lw=1.2,
        ls=":",
        label="obstacle trajectory" if first else None,
    )
    centre = episode.pred_center[k, m]
    axes_m = episode.obstacle_axes[m]
    heading = float(episode.pred_heading[k, m])
    ex, ny, alt = ellipsoid_surface(centre, axes_m, heading)
    ax.plot_surface(ex, ny, alt, color=OBSTACLE_COLOUR, alpha=0.18, linewidth=0, shade=False)
    ax.plot_wireframe(
        ex, ny, alt, color=OBSTACLE_COLOUR, alpha=0.35, linewidth=0.4, rstride=4, cstride=4
    )
    oe, on = ellipse_outline(centre, axes_m, heading)
    top.fill(oe, on, color=OBSTACLE_COLOUR, alpha=0.15, lw=0)
    top.plot(
        oe,
        on,
        color=OBSTACLE_COLOUR,
        lw=1.0,
        label=f"reachable region at t = {t[k]:.1f} s" if first else None,
    )
    side.errorbar(
        t[k],
        -centre[2],
        yerr=axes_m[2],
        color=OBSTACLE_COLOUR,
        capsize=4,
        lw=1.2,
        label="reachable region (vertical extent)" if first else None,
    )
    side.axvline(t[k], color="0.5", lw=0.8, ls=":")
    return [np.stack([on, oe], axis=-1), r.uav_pos[k, :, :2], obs[k, m, None, :2]]


def _finish_views(
    ax: Axes, top: Axes, side: Axes, r: EpisodeRecord, k_star: int, zoom_pts: list[np.ndarray]
) -> None:
    """Labels, camera, limits and titles; the plan view zoomed on ``zoom_pts`` when any."""
    pos, t = r.uav_pos, r.time
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
