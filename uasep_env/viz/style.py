"""Colours and labels shared by the live frames and the recorded figures."""

from __future__ import annotations

from uasep_env.sim.dynamics import AXES

__all__ = [
    "AXIS_NAMES",
    "COLLISION_COLOUR",
    "OBSTACLE_COLOUR",
    "PLAN_COLOUR",
    "POLICY_STYLES",
    "SEPARATION_COLOUR",
    "UAV_COLOURS",
    "uav_colour",
]

#: One colour per UAV (matplotlib's tab10 without red, the obstacles'); grey last, so that
#: the live frames, which draw the plan in grey, use the first eight.
UAV_COLOURS = (
    "#1f77b4",  # tab:blue
    "#ff7f0e",  # tab:orange
    "#2ca02c",  # tab:green
    "#9467bd",  # tab:purple
    "#8c564b",  # tab:brown
    "#e377c2",  # tab:pink
    "#bcbd22",  # tab:olive
    "#17becf",  # tab:cyan
    "#7f7f7f",  # tab:gray
)
OBSTACLE_COLOUR = "#d62728"  # tab:red
PLAN_COLOUR = "0.35"
COLLISION_COLOUR = "red"
SEPARATION_COLOUR = "darkorange"
#: Colour and line style of each policy when several share one axes.
POLICY_STYLES = (
    ("tab:blue", "-"),
    ("tab:green", "--"),
    ("tab:red", "-."),
    ("tab:purple", ":"),
    ("tab:orange", "-"),
    ("tab:brown", "--"),
)
#: Axis labels of the NED components.
AXIS_NAMES = dict(zip(AXES, ("x (north)", "y (east)", "z (down)"), strict=True))


def uav_colour(i: int) -> str:
    """The colour of UAV ``i`` (the palette repeats beyond its length)."""
    return UAV_COLOURS[i % len(UAV_COLOURS)]
