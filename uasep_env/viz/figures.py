"""The paper's figure set (section 4, figures 7-14) from recorded episodes, headless.

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

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uasep_env.viz.figure_parts import _save, _slug
from uasep_env.viz.series_figures import (
    plot_acceleration_comparison,
    plot_deviation,
    plot_obstacle_distances,
    plot_uav_distances,
    plot_velocity_acceleration,
)
from uasep_env.viz.trajectory_figure import plot_trajectory_3d

if TYPE_CHECKING:
    from uasep_env.rollout import Episode

__all__ = ["plot_paper_figures"]

_DPI = 130


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
