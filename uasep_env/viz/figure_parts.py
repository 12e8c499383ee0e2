"""What the paper's figures share: figure creation, titles, episode queries, shading, legends.

matplotlib is imported lazily, inside the functions, and figures are drawn on an Agg canvas
(:class:`matplotlib.figure.Figure`, no pyplot): no window ever opens.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.metrics import trajectory_deviation
from uasep_env.runtime.atomic import atomic_output
from uasep_env.sim.geometry import obstacle_distances
from uasep_env.viz.style import COLLISION_COLOUR, OBSTACLE_COLOUR, SEPARATION_COLOUR

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from uasep_env.rollout import Episode

__all__ = ["POLICY_TITLES", "closest_approach", "most_deviated_uav"]

#: Readable titles of the built-in policies (others are shown by their label).
POLICY_TITLES: dict[str, str] = {
    "apf": "APF with trajectory prediction (proposed)",
    "motion-state-apf": "motion-state APF (previous method)",
    "traditional-apf": "traditional APF",
    "zero": "zero action",
    "random": "random actions",
}


def _title(label: str) -> str:
    return POLICY_TITLES.get(label, label)


def _slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", label).strip("-") or "policy"


def _new_figure(figsize: tuple[float, float], constrained: bool = True) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained" if constrained else None)


def _save(fig: Figure, path: Path, dpi: int) -> Path:
    with atomic_output(path) as fh:
        fig.savefig(fh, format=path.suffix[1:] or "png", dpi=dpi, facecolor="white")
    return path


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
        color=COLLISION_COLOUR,
        ls="--",
        lw=1.3,
        label=f"collision distance ({collision:g} m)",
    )
    ax.axhline(
        separation,
        color=SEPARATION_COLOUR,
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
            color=OBSTACLE_COLOUR,
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
