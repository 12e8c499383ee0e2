"""The paper's figure set from recorded episodes: :mod:`uasep_env.viz` under its former name.

Kept so that ``from uasep_env.plotting import plot_paper_figures`` (and the other names of
``__all__``) keeps working; see :mod:`uasep_env.viz.figures`.
"""

from __future__ import annotations

from uasep_env.viz.figure_parts import POLICY_TITLES, closest_approach, most_deviated_uav
from uasep_env.viz.figures import plot_paper_figures
from uasep_env.viz.series_figures import (
    plot_acceleration_comparison,
    plot_deviation,
    plot_obstacle_distances,
    plot_uav_distances,
    plot_velocity_acceleration,
)
from uasep_env.viz.shapes import ellipsoid_surface
from uasep_env.viz.trajectory_figure import plot_trajectory_3d

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
