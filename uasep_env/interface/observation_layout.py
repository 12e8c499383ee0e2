"""The observation vector's layout: the feature table and :class:`ObservationLayout`.

Every agent gets one flat ``float32`` vector; the layout (which features of
:data:`FEATURES`, in which order, their widths and offsets) is built per config by
:meth:`ObservationLayout.from_config`, and the compiled assembly receives it as data
(:attr:`ObservationLayout.columns`). :class:`ObservationLayout` also decodes a vector back
into SI quantities and names its entries (checkpoints record the names). The reference APF
controllers act on decoded observations, so they and learned policies see exactly the same
information. Optional features (``Feature.default`` false) are added by naming them in
``observation.optional_features``: ``obstacle_class`` (below; ``docs/extending.md`` shows how
to add one).

All vectors are expressed along the NED axes (x north, y east, z down), relative to the
observing UAV. Positions are divided by ``observation.position_scale`` (m), velocities by
``uav.max_speed`` (m/s), accelerations by ``uav.max_accel`` (m/s^2); every entry is then
clipped to ``[-clip, clip]``.

==========================  ====  ======================================================
Feature                     Size  Meaning (before scaling)
==========================  ====  ======================================================
``slot_offset``             3     desired slot (eq. 7, from estimates) minus own position (m)
``plan_offset``             3     own planned position minus own position (m)
``velocity``                3     own estimated velocity (m/s)
``plan_velocity``           3     planned velocity of the formation (m/s)
``formation_velocity``      3     formation mean velocity ``v_o`` (eq. 5) (m/s)
``goal_offset``             3     planned formation centre minus the estimated centre (m)
``waypoint_dir``            3     unit direction of the planned path now
``waypoint_dist``           1     distance from the centre to the final way-point (m)
``last_accel``              3     own last commanded acceleration (m/s^2)
``progress``                1     elapsed fraction of the episode
per nearest UAV (K_u)       8     relative position (3, m), relative velocity (3, m/s),
                                  distance (1, m), presence mask (1)
per nearest obstacle (K_o)  16    reachable-ellipsoid centre relative to the UAV (3, m),
                                  semi-axes (longitudinal, lateral, vertical) (3, m),
                                  heading (cos, sin) (2), obstacle position relative to the
                                  UAV (3, m), obstacle velocity relative to the UAV (3, m/s),
                                  signed distance from the UAV to the ellipsoid (1, m),
                                  presence mask (1)
``obstacle_class``          C     optional, per nearest obstacle: its aircraft class,
                                  one-hot over :data:`uasep_env.sim.obstacles.AIRCRAFT_CLASSES`
                                  (``C`` = its length: one entry per row of the aircraft
                                  class table, ``AIRCRAFT_TABLE``), like ADS-B's emitter
                                  category
==========================  ====  ======================================================

UAVs are sorted by estimated distance, obstacles by distance to their reachable region;
absent entries (fewer than K, or beyond ``sensing_range``) are zero with mask 0.
``sensing_range`` is at most ``clip * position_scale`` (checked by the config), so the
distances of observed objects are never clipped. Nor is ``waypoint_dist`` with the
defaults (``clip * position_scale`` = 1,200 m; a default plan's final way-point starts
1,000-1,012 m from the formation centre); a plan longer than ``clip * position_scale``
(a higher ``cruise_speed`` or a longer ``episode_duration``) reads that bound until the
formation comes within it. None of the APF controllers uses it.

In the residual action modes (``action.mode``, see :mod:`uasep_env.interface.actions`) the
vector ends with one more feature, ``base_action`` (3): the base controller's normalised
command for the rest of the vector, the command the agent's action corrects. It is not clipped.
"""

from __future__ import annotations

import functools
from collections import namedtuple
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.sim.obstacles import AIRCRAFT_CLASSES

__all__ = ["FEATURES", "OPTIONAL_FEATURES", "Columns", "Feature", "ObservationLayout"]


class Feature(NamedTuple):
    """One entry of the feature table: a quantity written into the observation vector.

    Attributes:
        block: ``"self"`` (own state, once per agent), ``"uav"`` (once per observed UAV) or
            ``"obstacle"`` (once per observed obstacle).
        name: The feature's name within its block.
        size: Number of entries.
        kind: Its scale: ``"pos"`` (``position_scale``), ``"vel"`` (``max_speed``), ``"acc"``
            (``max_accel``) or ``"unit"`` (none).
        default: Whether every layout has it; ``False``: only when named in
            ``observation.optional_features``.
    """

    block: str
    name: str
    size: int
    kind: str
    default: bool = True

    @property
    def key(self) -> str:
        """The name the layout, the kernel and :meth:`ObservationLayout.decode` use."""
        return self.name if self.block == "self" else f"{self.block}_{self.name}"


#: Every feature, in vector order within its block (the blocks: own state, then ``k_uavs``
#: UAV blocks, then ``k_obstacles`` obstacle blocks). A layout is the sub-sequence of the
#: features it has; the compiled kernel receives where each one goes as data
#: (:attr:`ObservationLayout.columns`), so adding one is a row here plus its computation in
#: :func:`_assemble` and in :mod:`uasep_env._kernels.observations` (``docs/extending.md``).
FEATURES: tuple[Feature, ...] = (
    Feature("self", "slot_offset", 3, "pos"),
    Feature("self", "plan_offset", 3, "pos"),
    Feature("self", "velocity", 3, "vel"),
    Feature("self", "plan_velocity", 3, "vel"),
    Feature("self", "formation_velocity", 3, "vel"),
    Feature("self", "goal_offset", 3, "pos"),
    Feature("self", "waypoint_dir", 3, "unit"),
    Feature("self", "waypoint_dist", 1, "pos"),
    Feature("self", "last_accel", 3, "acc"),
    Feature("self", "progress", 1, "unit"),
    Feature("uav", "rel_pos", 3, "pos"),
    Feature("uav", "rel_vel", 3, "vel"),
    Feature("uav", "dist", 1, "pos"),
    Feature("uav", "mask", 1, "unit"),
    Feature("obstacle", "center", 3, "pos"),
    Feature("obstacle", "axes", 3, "pos"),
    Feature("obstacle", "heading_cs", 2, "unit"),
    Feature("obstacle", "rel_pos", 3, "pos"),
    Feature("obstacle", "rel_vel", 3, "vel"),
    Feature("obstacle", "region_dist", 1, "pos"),
    Feature("obstacle", "mask", 1, "unit"),
    Feature("obstacle", "class", len(AIRCRAFT_CLASSES), "unit", default=False),
)
_BY_KEY = {f.key: f for f in FEATURES}
_BLOCKS = ("self", "uav", "obstacle")
#: Optional features (off unless named in ``observation.optional_features``).
OPTIONAL_FEATURES: tuple[str, ...] = tuple(f.key for f in FEATURES if not f.default)

#: What the compiled kernel is told of a layout: the first column of every feature of
#: :data:`FEATURES` (own-state ones from the start of the vector, ``uav_*`` and
#: ``obstacle_*`` ones from the start of one neighbour's block; -1 when the layout lacks
#: it), the neighbour counts, the blocks' widths and the ``obstacle_class`` one-hot's width
#: (the aircraft class table's length: the kernel reads it as data, so a new class is no
#: kernel edit). One type for every layout: a new feature is a new field, never a new
#: kernel argument.
Columns = namedtuple(
    "Columns",
    [
        *(f.key for f in FEATURES),
        "k_uavs",
        "k_obstacles",
        "self_dim",
        "uav_width",
        "obstacle_width",
        "n_classes",
    ],
)


@dataclass(frozen=True, kw_only=True)
class ObservationLayout:
    """Which features, in which order and where, and their scales, for one config.

    Attributes:
        k_uavs: Nearest UAVs observed.
        k_obstacles: Nearest obstacles observed.
        pos_scale: Position divisor (m).
        vel_scale: Velocity divisor (m/s).
        acc_scale: Acceleration divisor (m/s^2).
        clip: Clip bound of the normalised entries.
        sensing_range: Range beyond which nothing is observed (m).
        base_action: Whether the vector ends with the base controller's command (a residual mode).
        features: The keys (:attr:`Feature.key`) of the features the vector has, a
            sub-sequence of :data:`FEATURES` (``None``: the default ones).
    """

    k_uavs: int
    k_obstacles: int
    pos_scale: float
    vel_scale: float
    acc_scale: float
    clip: float
    sensing_range: float
    base_action: bool = False
    features: tuple[str, ...] | None = field(default=None)

    def __post_init__(self) -> None:
        keys = _feature_keys(self.features)
        object.__setattr__(self, "features", keys)

    @classmethod
    def from_config(cls, config: EnvConfig) -> ObservationLayout:
        """The layout an environment with ``config`` produces.

        Raises:
            ValueError: If ``observation.optional_features`` names an unknown feature.
        """
        oc = config.observation
        k_u = oc.k_uavs if oc.k_uavs is not None else min(config.n_uavs - 1, 6)
        k_u = min(k_u, config.n_uavs - 1)
        k_o = oc.k_obstacles if oc.k_obstacles is not None else max(1, config.n_obstacles)
        extra = oc.optional_features
        unknown = sorted(set(extra) - set(OPTIONAL_FEATURES))
        if unknown:
            raise ValueError(
                f"invalid config value observation.optional_features={extra!r}: unknown "
                f"feature(s) {unknown}; optional features: {list(OPTIONAL_FEATURES)}"
            )
        return cls(
            k_uavs=k_u,
            k_obstacles=k_o,
            pos_scale=oc.position_scale,
            vel_scale=config.uav.max_speed,
            acc_scale=config.uav.max_accel,
            clip=oc.clip,
            sensing_range=oc.sensing_range,
            base_action=config.action.mode != "direct",
            features=tuple(f.key for f in FEATURES if f.default or f.key in extra),
        )

    def block(self, name: str) -> tuple[Feature, ...]:
        """The features of block ``name`` (``"self"``, ``"uav"``, ``"obstacle"``) it has."""
        return _block(self.features, name)  # cached: policies decode every step

    def width(self, name: str) -> int:
        """Width of one ``name`` block (one neighbour's, for ``"uav"`` and ``"obstacle"``)."""
        return sum(f.size for f in self.block(name))

    # The widths are computed once per layout (it is frozen): the APF asks for them at
    # every decision, and summing the blocks' sizes was a third of a one-environment one.
    @functools.cached_property
    def self_dim(self) -> int:
        """Width of the own-state block."""
        return self.width("self")

    @functools.cached_property
    def world_dim(self) -> int:
        """Width of what is observed of the world (everything but ``base_action``)."""
        return (
            self.self_dim
            + self.k_uavs * self.width("uav")
            + self.k_obstacles * self.width("obstacle")
        )

    @functools.cached_property
    def dim(self) -> int:
        """Width of the whole observation vector."""
        return self.world_dim + (3 if self.base_action else 0)

    @property
    def slices(self) -> dict[str, slice]:
        """The columns of each feature it has, by key (neighbour ones within one block)."""
        return dict(_slices(self.features))  # a copy: the cached one is shared

    @property
    def columns(self) -> Columns:
        """Where the kernel writes each feature (:data:`Columns`), from :attr:`slices`."""
        return _columns(self.features, self.k_uavs, self.k_obstacles)

    def _scale(self, kind: str) -> float:
        return {"pos": self.pos_scale, "vel": self.vel_scale, "acc": self.acc_scale}.get(kind, 1.0)

    def decode(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Turn observation vectors back into SI quantities.

        Args:
            obs: ``(..., dim)`` observations.

        Returns:
            A dict of arrays, by feature key: own-state features ``(..., size)``,
            ``uav_<name>`` with shape ``(..., k_uavs, size)`` and ``obstacle_<name>`` with
            shape ``(..., k_obstacles, size)``; ``base_action`` ``(..., 3)`` when the layout
            has it. Masks are bools of shape ``(..., K)``. Values that were clipped stay
            clipped.

        Raises:
            ValueError: If the last axis is not ``dim`` wide.
        """
        obs = np.asarray(obs)
        if obs.shape[-1] != self.dim:
            raise ValueError(f"observation width must be {self.dim}, got {obs.shape[-1]}")
        out: dict[str, np.ndarray] = {}
        i = 0
        for f in self.block("self"):
            out[f.key] = obs[..., i : i + f.size].astype(float) * self._scale(f.kind)
            i += f.size
        for name, k in (("uav", self.k_uavs), ("obstacle", self.k_obstacles)):
            w = self.width(name)
            block = obs[..., i : i + k * w].reshape(*obs.shape[:-1], k, w).astype(float)
            j = 0
            for f in self.block(name):
                out[f.key] = block[..., j : j + f.size] * self._scale(f.kind)
                j += f.size
            if name + "_mask" in out:
                out[name + "_mask"] = out[name + "_mask"][..., 0] > 0.5
            i += k * w
        if self.base_action:
            out["base_action"] = obs[..., i : i + 3].astype(float)
        return out

    def decode_columns(self) -> dict[str, tuple[int, int, float, int, int]]:
        """Where :meth:`decode` reads each feature: ``key: (start, size, scale, stride, count)``.

        ``start``: its first column (the first neighbour's, in the neighbour blocks);
        ``stride``: the columns from one neighbour's to the next's (0 in the own-state
        block); ``count``: 1, or the neighbours. Compiled readers of the vector (the APF's
        kernel) decode with these, as :meth:`decode` does.
        """
        return dict(_decode_columns(self))

    def feature_columns(self, key: str) -> tuple[np.ndarray, float]:
        """``(columns, scale)``: where :meth:`decode` reads feature ``key``, ``(count, size)``.

        The columns as a read-only index array (one row per neighbour; one row in the
        own-state block), and the scale the entries are multiplied by.

        Raises:
            KeyError: For a feature the layout does not have.
        """
        return _feature_columns(self, key)

    def feature_names(self) -> list[str]:
        """One name per entry of the vector (for logging, docs and checkpoints)."""
        names: list[str] = []
        for f in self.block("self"):
            names += [f"{f.name}[{c}]" for c in range(f.size)] if f.size > 1 else [f.name]
        for name, k in (("uav", self.k_uavs), ("obstacle", self.k_obstacles)):
            for slot in range(k):
                for f in self.block(name):
                    base = f"{name}{slot}.{f.name}"
                    names += [f"{base}[{c}]" for c in range(f.size)] if f.size > 1 else [base]
        if self.base_action:
            names += [f"base_action[{c}]" for c in range(3)]
        return names


def _feature_keys(features: Iterable[str] | None) -> tuple[str, ...]:
    """``features`` checked against :data:`FEATURES` and put in table order.

    Raises:
        ValueError: For an unknown key.
    """
    if features is None:
        return tuple(f.key for f in FEATURES if f.default)
    keys = set(features)
    unknown = sorted(keys - set(_BY_KEY))
    if unknown:
        raise ValueError(f"unknown observation feature(s) {unknown}; known: {list(_BY_KEY)}")
    return tuple(f.key for f in FEATURES if f.key in keys)


@functools.lru_cache(maxsize=64)
def _decode_columns(layout: ObservationLayout) -> dict[str, tuple[int, int, float, int, int]]:
    # The within-block columns of _slices, placed: the own state, then k_uavs UAV blocks,
    # then k_obstacles obstacle blocks.
    w_uav, w_obstacle = layout.width("uav"), layout.width("obstacle")
    placed = {
        "self": (0, 0, 1),
        "uav": (layout.self_dim, w_uav, layout.k_uavs),
        "obstacle": (layout.self_dim + layout.k_uavs * w_uav, w_obstacle, layout.k_obstacles),
    }
    within = _slices(layout.features)
    out: dict[str, tuple[int, int, float, int, int]] = {}
    for f in FEATURES:
        if f.key in within:
            start, stride, count = placed[f.block]
            out[f.key] = (start + within[f.key].start, f.size, layout._scale(f.kind), stride, count)
    return out


@functools.lru_cache(maxsize=256)
def _feature_columns(layout: ObservationLayout, key: str) -> tuple[np.ndarray, float]:
    start, size, scale, stride, count = _decode_columns(layout)[key]
    cols = start + (np.arange(count) * stride)[:, None] + np.arange(size)
    cols.flags.writeable = False  # shared by every caller
    return cols, scale


@functools.lru_cache(maxsize=256)
def _block(features: tuple[str, ...], name: str) -> tuple[Feature, ...]:
    return tuple(f for f in FEATURES if f.block == name and f.key in features)


@functools.lru_cache(maxsize=64)
def _slices(features: tuple[str, ...]) -> dict[str, slice]:
    out: dict[str, slice] = {}
    for block in _BLOCKS:
        col = 0
        for f in FEATURES:
            if f.block == block and f.key in features:
                out[f.key] = slice(col, col + f.size)
                col += f.size
    return out


@functools.lru_cache(maxsize=64)
def _columns(features: tuple[str, ...], k_uavs: int, k_obstacles: int) -> Columns:
    s = _slices(features)
    widths = {
        b: sum(f.size for f in FEATURES if f.block == b and f.key in features) for b in _BLOCKS
    }
    return Columns(
        *(s[f.key].start if f.key in s else -1 for f in FEATURES),
        k_uavs,
        k_obstacles,
        widths["self"],
        widths["uav"],
        widths["obstacle"],
        _BY_KEY["obstacle_class"].size,
    )
