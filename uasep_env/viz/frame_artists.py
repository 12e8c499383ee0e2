"""The artists of a live frame, created once per figure; frames only update their data.

The 3D view (formation, plan, obstacles and their reachable ellipsoids), the top view and
the legend, in the colours of :mod:`uasep_env.viz.style`. matplotlib is imported inside the
functions (this module is imported by :mod:`uasep_env.viz.frames` without it).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uasep_env.viz.shapes import SPHERE_QUADS
from uasep_env.viz.style import OBSTACLE_COLOUR, PLAN_COLOUR, UAV_COLOURS

__all__ = ["MAX_LEGEND_UAVS", "build_artists"]

#: Up to this many UAVs, each has its own colour, legend entry and label.
MAX_LEGEND_UAVS = 8
_FRAME_COLOURS = UAV_COLOURS[:MAX_LEGEND_UAVS]  # not the grey of the plan
_REGION_FACE = (0.84, 0.15, 0.16, 0.10)
_REGION_EDGE = (0.84, 0.15, 0.16, 0.7)


def build_artists(
    fig: Any,
    n_uavs: int,
    n_obstacles: int,
    horizon: float,
    *,
    top_view: bool,
    elev: float,
    azim: float,
) -> dict[str, Any]:
    """Clear ``fig`` and create every artist of a frame, with empty data.

    Args:
        fig: The figure.
        n_uavs: UAVs drawn.
        n_obstacles: Obstacles drawn.
        horizon: Prediction horizon (s), for the legend.
        top_view: Draw the top view next to the 3D view.
        elev: Elevation of the 3D camera (degrees).
        azim: Azimuth of the 3D camera (degrees).

    Returns:
        ``{"ax3", "ax2" (None without top view), "plan3", "plan2", "uav": [per UAV {name:
        artist}], "obs": [per obstacle {name: artist}], "title", "status"}``.
    """
    fig.clear()
    fig.patch.set_facecolor("white")
    if top_view:
        ax3 = fig.add_axes((-0.04, 0.06, 0.66, 0.86), projection="3d")
        ax2 = fig.add_axes((0.675, 0.15, 0.31, 0.72))
    else:
        ax3 = fig.add_axes((0.02, 0.07, 0.96, 0.84), projection="3d")
        ax2 = None
    colours = _uav_colours(n_uavs)
    art: dict[str, Any] = {"ax3": ax3, "ax2": ax2, "uav": [], "obs": []}
    _build_3d(ax3, art, colours, n_obstacles, elev, azim)
    if ax2 is not None:
        _build_top(ax2, art, colours)
    _legend(fig, colours, n_obstacles, horizon)
    art["title"] = fig.text(0.5, 0.965, "", ha="center", va="center", fontsize=11)
    art["status"] = fig.text(0.5, 0.925, "", ha="center", va="center", fontsize=9)
    return art


def _build_3d(
    ax3: Any, art: dict[str, Any], colours: list[Any], n_obstacles: int, elev: float, azim: float
) -> None:
    """The 3D view's axes and artists: the plan, each UAV's, each obstacle's."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    ax3.view_init(elev=elev, azim=azim)
    ax3.set_xlabel("east (m)", labelpad=6)
    ax3.set_ylabel("north (m)", labelpad=6)
    ax3.set_zlabel("altitude (m)", labelpad=2)
    ax3.tick_params(labelsize=7, pad=1)
    for axis in (ax3.xaxis, ax3.yaxis, ax3.zaxis):
        axis.set_pane_color((0.96, 0.96, 0.97, 1.0))
        axis.label.set_size(8)
    clip = {"axlim_clip": True} if _supports_axlim_clip(ax3) else {}

    def p3(**kw: Any) -> Any:
        return ax3.plot([], [], [], **kw, **clip)[0]

    art["plan3"] = p3(color=PLAN_COLOUR, lw=1.0, ls="--", alpha=0.8)
    for c in colours:
        art["uav"].append(
            {
                "trail3": p3(color=c, lw=1.6, alpha=0.85),
                "track3": p3(color=c, lw=0.8, ls=(0, (1, 2)), alpha=0.6),
                "drop3": p3(color=c, lw=0.6, ls=":", alpha=0.7),
                "planned3": p3(marker="o", ms=8, mfc="none", mec=c, mew=1.3, ls="none"),
                "dot3": p3(marker="o", ms=6.5, color=c, mec="k", mew=0.5, ls="none"),
            }
        )
    for _ in range(n_obstacles):
        surf = Poly3DCollection(
            np.zeros((len(SPHERE_QUADS), 4, 3)),
            facecolor=OBSTACLE_COLOUR,
            edgecolor="none",
            alpha=0.07,
            **clip,
        )
        ax3.add_collection3d(surf)
        art["obs"].append(
            {
                "surf3": surf,
                "wire3": p3(color=OBSTACLE_COLOUR, lw=0.5, alpha=0.35),
                "trail3": p3(color=OBSTACLE_COLOUR, lw=1.3, alpha=0.7),
                "drop3": p3(color=OBSTACLE_COLOUR, lw=0.6, ls=":", alpha=0.7),
                "dot3": p3(marker="X", ms=9, color=OBSTACLE_COLOUR, mec="k", mew=0.5, ls="none"),
            }
        )


def _build_top(ax2: Any, art: dict[str, Any], colours: list[Any]) -> None:
    """The top view's axes and artists (north up), added to the UAVs' and obstacles' dicts."""
    from matplotlib.patches import Polygon

    ax2.set_aspect("equal", adjustable="box")
    ax2.set_xlabel("east (m)", fontsize=8)
    ax2.set_ylabel("north (m)", fontsize=8)
    ax2.tick_params(labelsize=7)
    ax2.grid(True, lw=0.4, alpha=0.5)
    ax2.set_title("top view", fontsize=9)
    art["plan2"] = ax2.plot([], [], color=PLAN_COLOUR, lw=1.0, ls="--", alpha=0.8)[0]
    labelled = len(colours) <= MAX_LEGEND_UAVS
    for i, u in enumerate(art["uav"]):
        c = colours[i]
        u["trail2"] = ax2.plot([], [], color=c, lw=1.4, alpha=0.85)[0]
        u["track2"] = ax2.plot([], [], color=c, lw=0.8, ls=(0, (1, 2)), alpha=0.6)[0]
        u["planned2"] = ax2.plot([], [], "o", ms=8, mfc="none", mec=c, mew=1.3)[0]
        u["dot2"] = ax2.plot([], [], "o", ms=6, color=c, mec="k", mew=0.5, zorder=5)[0]
        u["label2"] = (
            ax2.annotate(
                str(i),
                (0.0, 0.0),
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
                va="bottom",
                fontsize=7,
                fontweight="bold",
                color=c,
                annotation_clip=True,
            )
            if labelled
            else None
        )
    for o in art["obs"]:
        o["region2"] = ax2.add_patch(
            Polygon(
                np.zeros((3, 2)),
                closed=True,
                facecolor=_REGION_FACE,
                edgecolor=_REGION_EDGE,
                lw=0.9,
            )
        )
        o["trail2"] = ax2.plot([], [], color=OBSTACLE_COLOUR, lw=1.2, alpha=0.7)[0]
        o["dot2"] = ax2.plot([], [], "X", ms=8, color=OBSTACLE_COLOUR, mec="k", mew=0.5, zorder=5)[
            0
        ]


def _legend(fig: Any, colours: list[Any], n_obstacles: int, horizon: float) -> None:
    """The legend below the views: the UAVs, the plan and, with obstacles, their regions."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    n_uavs = len(colours)
    uav = {"marker": "o", "ls": "-", "mec": "k", "mew": 0.5, "ms": 6}
    if n_uavs <= MAX_LEGEND_UAVS:
        handles = [
            Line2D([], [], color=colours[i], lw=1.4, label=f"uav_{i}", **uav) for i in range(n_uavs)
        ]
    else:
        handles = [Line2D([], [], color=colours[0], label=f"UAVs uav_0..uav_{n_uavs - 1}", **uav)]
    handles += [
        Line2D(
            [], [], marker="o", ls="none", mfc="none", mec=PLAN_COLOUR, mew=1.3, ms=8,
            label="planned position",
        ),
        Line2D([], [], color=PLAN_COLOUR, lw=1.0, ls="--", label="plan (centre)"),
        Line2D([], [], color=PLAN_COLOUR, lw=0.8, ls=(0, (1, 2)), label="planned tracks"),
    ]  # fmt: skip
    if n_obstacles:
        handles += [
            Line2D(
                [], [], marker="X", ls="-", color=OBSTACLE_COLOUR, mec="k", mew=0.5, ms=8,
                lw=1.2, label="obstacle",
            ),
            Patch(
                facecolor=(0.84, 0.15, 0.16, 0.15),
                edgecolor=_REGION_EDGE,
                label=f"reachable set ({horizon:g} s)",
            ),
        ]  # fmt: skip
    ncol = len(handles) if len(handles) <= 9 else math.ceil(len(handles) / 2)
    fig.legend(
        handles=handles,
        loc="lower center",
        ncol=ncol,
        fontsize=8,
        frameon=False,
        bbox_to_anchor=(0.5, 0.0),
        handlelength=2.2,
        columnspacing=1.4,
    )


def _supports_axlim_clip(ax3: Any) -> bool:
    try:
        ax3.plot([], [], [], axlim_clip=True)[0].remove()
    except (TypeError, AttributeError):
        return False
    return True


def _uav_colours(n: int) -> list[Any]:
    if n <= len(_FRAME_COLOURS):
        return list(_FRAME_COLOURS[:n])
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return [cmap(x) for x in np.linspace(0.0, 0.9, n)]
