"""Per-agent observations built from what each UAV knows (its Kalman estimates).

Every agent gets one flat ``float32`` vector; the layout is fixed by the config and
described by :class:`ObservationLayout`, which also decodes a vector back into SI
quantities. The reference APF controllers act on decoded observations, so they and
learned policies see exactly the same information.

All vectors are expressed along the NED axes (x north, y east, z down), relative to the
observing UAV. Positions are divided by ``observation.position_scale`` (m), velocities by
``uav.max_speed`` (m/s), accelerations by ``uav.max_accel`` (m/s^2); every entry is then
clipped to ``[-clip, clip]``.

======================  ====  ==========================================================
Feature                 Size  Meaning (before scaling)
======================  ====  ==========================================================
``slot_offset``         3     desired slot (eq. 7, from estimates) minus own position (m)
``plan_offset``         3     own planned position minus own position (m)
``velocity``            3     own estimated velocity (m/s)
``plan_velocity``       3     planned velocity of the formation (m/s)
``formation_velocity``  3     formation mean velocity ``v_o`` (eq. 5) (m/s)
``goal_offset``         3     planned formation centre minus the estimated centre (m)
``waypoint_dir``        3     unit direction of the planned path now
``waypoint_dist``       1     distance from the centre to the final way-point (m)
``last_accel``          3     own last commanded acceleration (m/s^2)
``progress``            1     elapsed fraction of the episode
per nearest UAV (K_u)   8     relative position (3, m), relative velocity (3, m/s),
                              distance (1, m), presence mask (1)
per nearest obstacle    16    reachable-ellipsoid centre relative to the UAV (3, m),
(K_o)                         semi-axes (longitudinal, lateral, vertical) (3, m),
                              heading (cos, sin) (2), obstacle position relative to the
                              UAV (3, m), obstacle velocity relative to the UAV (3, m/s),
                              signed distance from the UAV to the ellipsoid (1, m),
                              presence mask (1)
======================  ====  ==========================================================

UAVs are sorted by estimated distance, obstacles by distance to their reachable region;
absent entries (fewer than K, or beyond ``sensing_range``) are zero with mask 0.
``sensing_range`` is at most ``clip * position_scale`` (checked by the config), so the
distances of observed objects are never clipped. Nor is ``waypoint_dist`` with the
defaults (``clip * position_scale`` = 1,200 m; a default plan's final way-point starts
1,000-1,012 m from the formation centre); a plan longer than ``clip * position_scale``
(a higher ``cruise_speed`` or a longer ``episode_duration``) reads that bound until the
formation comes within it. None of the APF controllers uses it.

In the ``residual_apf`` action mode (``action.mode``, see :mod:`uasep_env.actions`) the
vector ends with one more feature, ``base_action`` (3): the APF's normalised command for
the rest of the vector, the command the agent's action corrects. It is not clipped.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config import EnvConfig
from uasep_env.formation import MIN_FRAME_SPEED, formation_center, slot_positions
from uasep_env.world import World

__all__ = ["ObservationLayout", "build_observations", "global_state", "state_dim"]

SELF_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("slot_offset", 3, "pos"),
    ("plan_offset", 3, "pos"),
    ("velocity", 3, "vel"),
    ("plan_velocity", 3, "vel"),
    ("formation_velocity", 3, "vel"),
    ("goal_offset", 3, "pos"),
    ("waypoint_dir", 3, "unit"),
    ("waypoint_dist", 1, "pos"),
    ("last_accel", 3, "acc"),
    ("progress", 1, "unit"),
)
UAV_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("rel_pos", 3, "pos"),
    ("rel_vel", 3, "vel"),
    ("dist", 1, "pos"),
    ("mask", 1, "unit"),
)
OBSTACLE_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("center", 3, "pos"),
    ("axes", 3, "pos"),
    ("heading_cs", 2, "unit"),
    ("rel_pos", 3, "pos"),
    ("rel_vel", 3, "vel"),
    ("region_dist", 1, "pos"),
    ("mask", 1, "unit"),
)


def _width(spec: tuple[tuple[str, int, str], ...]) -> int:
    return sum(size for _, size, _ in spec)


def _slices(spec: tuple[tuple[str, int, str], ...], prefix: str = "") -> dict[str, slice]:
    """The columns of each field of ``spec``, from the start of its block."""
    out, col = {}, 0
    for name, size, _ in spec:
        out[prefix + name] = slice(col, col + size)
        col += size
    return out


# Where each feature is written, derived from the tables above: the one source of the layout
# for the numpy assembly and the compiled kernel. Own-state fields count from the start of
# the vector, ``uav_*`` and ``obstacle_*`` fields from the start of one neighbour's block.
_FIELD_COLUMNS = {
    **_slices(SELF_FIELDS),
    **_slices(UAV_FIELDS, "uav_"),
    **_slices(OBSTACLE_FIELDS, "obstacle_"),
}
Columns = namedtuple("Columns", [*_FIELD_COLUMNS, "uav_width", "obstacle_width"])
#: The first column of every feature and the neighbour blocks' widths, for the kernel.
COLUMNS = Columns(
    *(cols.start for cols in _FIELD_COLUMNS.values()), _width(UAV_FIELDS), _width(OBSTACLE_FIELDS)
)


@dataclass(frozen=True)
class ObservationLayout:
    """Offsets and scales of the observation vector for one config.

    Attributes:
        k_uavs: Nearest UAVs observed.
        k_obstacles: Nearest obstacles observed.
        pos_scale: Position divisor (m).
        vel_scale: Velocity divisor (m/s).
        acc_scale: Acceleration divisor (m/s^2).
        clip: Clip bound of the normalised entries.
        sensing_range: Range beyond which nothing is observed (m).
        base_action: Whether the vector ends with the APF's command (``residual_apf``).
    """

    k_uavs: int
    k_obstacles: int
    pos_scale: float
    vel_scale: float
    acc_scale: float
    clip: float
    sensing_range: float
    base_action: bool = False

    @classmethod
    def from_config(cls, config: EnvConfig) -> ObservationLayout:
        """The layout an environment with ``config`` produces."""
        oc = config.observation
        k_u = oc.k_uavs if oc.k_uavs is not None else min(config.n_uavs - 1, 6)
        k_u = min(k_u, config.n_uavs - 1)
        k_o = oc.k_obstacles if oc.k_obstacles is not None else max(1, config.n_obstacles)
        return cls(
            k_uavs=k_u,
            k_obstacles=k_o,
            pos_scale=oc.position_scale,
            vel_scale=config.uav.max_speed,
            acc_scale=config.uav.max_accel,
            clip=oc.clip,
            sensing_range=oc.sensing_range,
            base_action=config.action.mode == "residual_apf",
        )

    @property
    def self_dim(self) -> int:
        """Width of the own-state block."""
        return _width(SELF_FIELDS)

    @property
    def world_dim(self) -> int:
        """Width of what is observed of the world (everything but ``base_action``)."""
        return (
            self.self_dim
            + self.k_uavs * _width(UAV_FIELDS)
            + self.k_obstacles * _width(OBSTACLE_FIELDS)
        )

    @property
    def dim(self) -> int:
        """Width of the whole observation vector."""
        return self.world_dim + (3 if self.base_action else 0)

    def _scale(self, kind: str) -> float:
        return {"pos": self.pos_scale, "vel": self.vel_scale, "acc": self.acc_scale}.get(kind, 1.0)

    def decode(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Turn observation vectors back into SI quantities.

        Args:
            obs: ``(..., dim)`` observations.

        Returns:
            A dict of arrays: the own-state fields of :data:`SELF_FIELDS` (``(..., size)``),
            ``uav_<field>`` with shape ``(..., k_uavs, size)`` and ``obstacle_<field>`` with
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
        for name, size, kind in SELF_FIELDS:
            out[name] = obs[..., i : i + size].astype(float) * self._scale(kind)
            i += size
        for prefix, spec, k in (
            ("uav_", UAV_FIELDS, self.k_uavs),
            ("obstacle_", OBSTACLE_FIELDS, self.k_obstacles),
        ):
            w = _width(spec)
            block = obs[..., i : i + k * w].reshape(*obs.shape[:-1], k, w).astype(float)
            j = 0
            for name, size, kind in spec:
                out[prefix + name] = block[..., j : j + size] * self._scale(kind)
                j += size
            out[prefix + "mask"] = out[prefix + "mask"][..., 0] > 0.5
            i += k * w
        if self.base_action:
            out["base_action"] = obs[..., i : i + 3].astype(float)
        return out

    def feature_names(self) -> list[str]:
        """One name per entry of the vector (for logging and docs)."""
        names: list[str] = []
        for name, size, _ in SELF_FIELDS:
            names += [f"{name}[{c}]" for c in range(size)] if size > 1 else [name]
        for prefix, spec, k in (
            ("uav", UAV_FIELDS, self.k_uavs),
            ("obstacle", OBSTACLE_FIELDS, self.k_obstacles),
        ):
            for slot in range(k):
                for name, size, _ in spec:
                    base = f"{prefix}{slot}.{name}"
                    names += [f"{base}[{c}]" for c in range(size)] if size > 1 else [base]
        if self.base_action:
            names += [f"base_action[{c}]" for c in range(3)]
        return names


class _Inputs(NamedTuple):
    """What an observation is assembled from: the world's estimates plus derived geometry.

    Shapes: ``E`` environments, ``N`` UAVs, ``M`` obstacles. Obstacle fields are empty
    (``M = 0`` rows are never read) when no obstacle is observed.
    """

    pos: np.ndarray  # (E, N, 3) estimated UAV positions (m)
    vel: np.ndarray  # (E, N, 3) estimated UAV velocities (m/s)
    pattern: np.ndarray  # (E, N, 3) the formation pattern, formation frame (m)
    plan_pos: np.ndarray  # (E, N, 3) planned positions (m)
    plan_vel: np.ndarray  # (E, N, 3) planned velocities (m/s)
    accel_cmd: np.ndarray  # (E, N, 3) last commanded accelerations (m/s^2)
    plan_center: np.ndarray  # (E, 3) planned centre (m)
    wp_dir: np.ndarray  # (E, 3) unit direction of the planned path
    final_wp: np.ndarray  # (E, 3) the plan's final way-point (m)
    progress: np.ndarray  # (E,) elapsed fraction of the episode
    region: np.ndarray  # (E, N, M) signed distance to each reachable ellipsoid (m), inf if off
    obs_pos: np.ndarray  # (E, M, 3) estimated obstacle positions (m)
    obs_vel: np.ndarray  # (E, M, 3) estimated obstacle velocities (m/s)
    pred_center: np.ndarray  # (E, M, 3) ellipsoid centres (m)
    pred_axes: np.ndarray  # (E, M, 3) ellipsoid semi-axes (m)
    cos_h: np.ndarray  # (E, M) cosine of the ellipsoid heading
    sin_h: np.ndarray  # (E, M) sine of the ellipsoid heading
    active: np.ndarray  # (E, M) bool, obstacle present


def build_observations(
    world: World,
    layout: ObservationLayout,
    out: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """Every agent's observation of the world, ``(n_envs, n_uavs, layout.world_dim)`` float32.

    The plan and the distances to the reachable ellipsoids come from the world; the
    estimated formation geometry (eqs. 5-7) and the per-agent assembly (relative vectors,
    neighbour sorting, masks, scaling, clipping) are :func:`_assemble` (compiled when numba
    is in use, the same numbers bit for bit).

    Args:
        world: The batched world.
        layout: The layout for the world's config.
        out: Optional preallocated output array.
        rows: Only these environments (an index array): ``out`` is then
            ``(len(rows), N, dim)``, one row per index.

    Returns:
        The observations (``out`` if given).
    """
    e = world.n_envs if rows is None else len(rows)
    if out is None:
        out = np.empty((e, world.n_uavs, layout.world_dim), dtype=np.float32)
    _assemble(_gather_inputs(world, layout, rows), layout, out)
    return out


def _gather_inputs(
    world: World, layout: ObservationLayout, rows: np.ndarray | None = None
) -> _Inputs:
    """The world's arrays an observation is made of (the formation geometry is derived).

    All environments, or the ``rows`` (an index array) only.
    """
    r = slice(None) if rows is None else rows
    pos = world.est_pos[r]
    progress = np.minimum(world.time[r] / world.config.episode_duration, 1.0)
    m = world.n_obstacles if layout.k_obstacles else 0
    # Estimated UAV positions against the predicted ellipsoids (none if none is observed).
    region = world.region_distances(pos, rows) if m else np.zeros((*pos.shape[:2], 0))
    return _Inputs(
        pos,
        world.est_vel[r],
        world.slots[r],
        world.plan_pos[r],
        world.plan_vel[r],
        world.accel_cmd[r],
        world.plan_center[r],
        world.plan_dir[r],
        world.plan.waypoints[r, -1],
        progress,
        region,
        world.obs_est_pos[r, :m],
        world.obs_est_vel[r, :m],
        world.pred_center[r, :m],
        world.pred_axes[r, :m],
        world.pred_cos[r, :m],
        world.pred_sin[r, :m],
        world.obstacles.active[r, :m],
    )


@compiled_twin("assemble_observations", columns=COLUMNS, min_frame_speed=MIN_FRAME_SPEED)
def _assemble(x: _Inputs, layout: ObservationLayout, out: np.ndarray) -> None:
    """The assembly of :func:`build_observations`: fills ``out`` in place.

    Every column comes from :data:`COLUMNS`.
    """
    e, n, _ = x.pos.shape
    m = x.region.shape[-1]
    ps, vs, acs = layout.pos_scale, layout.vel_scale, layout.acc_scale
    pos, vel = x.pos, x.vel
    # The formation as the UAVs estimate it (eqs. 5-7).
    center, mean_vel = formation_center(pos, vel)
    slots = slot_positions(center, mean_vel, x.wp_dir, x.pattern)
    wp_dist = np.linalg.norm(x.final_wp - center, axis=-1)

    # Own state; broadcast fields are shared by the formation.
    c, f = COLUMNS, _FIELD_COLUMNS
    out[..., f["slot_offset"]] = (slots - pos) / ps
    out[..., f["plan_offset"]] = (x.plan_pos - pos) / ps
    out[..., f["velocity"]] = vel / vs
    out[..., f["plan_velocity"]] = x.plan_vel / vs
    out[..., f["formation_velocity"]] = (mean_vel / vs)[:, None, :]
    out[..., f["goal_offset"]] = ((x.plan_center - center) / ps)[:, None, :]
    out[..., f["waypoint_dir"]] = x.wp_dir[:, None, :]
    out[..., c.waypoint_dist] = (wp_dist / ps)[:, None]
    out[..., f["last_accel"]] = x.accel_cmd / acs
    out[..., c.progress] = x.progress[:, None]
    col = layout.self_dim

    k_u = layout.k_uavs
    if k_u:
        rel = pos[:, None, :, :] - pos[:, :, None, :]  # (E, N(i), N(j), 3): j relative to i
        dist = np.sqrt(np.einsum("...i,...i->...", rel, rel))
        dist[:, np.arange(n), np.arange(n)] = np.inf  # never one's own neighbour
        order = np.argsort(dist, axis=-1, kind="stable")[..., :k_u]  # (E, N, K)
        # Flat index of pair (e, i, order) in (E * N * N) and of UAV (e, order) in (E * N).
        pair = (np.arange(e * n) * n).reshape(e, n, 1) + order
        other = (np.arange(e) * n).reshape(e, 1, 1) + order
        d_sel = dist.reshape(-1)[pair]
        present = (d_sel <= layout.sensing_range)[..., None]
        w = c.uav_width
        block = np.reshape(out[..., col : col + k_u * w], (e, n, k_u, w), copy=False)
        block[..., f["uav_rel_pos"]] = np.where(present, rel.reshape(-1, 3)[pair] / ps, 0.0)
        relv = vel.reshape(-1, 3)[other] - vel[:, :, None, :]
        block[..., f["uav_rel_vel"]] = np.where(present, relv / vs, 0.0)
        block[..., c.uav_dist] = np.where(present[..., 0], d_sel / ps, 0.0)
        block[..., c.uav_mask] = present[..., 0]
        col += k_u * w

    k_o = layout.k_obstacles
    w = c.obstacle_width
    block = np.reshape(out[..., col : col + k_o * w], (e, n, k_o, w), copy=False)
    kk = min(k_o, m)
    block[:, :, kk:] = 0.0
    if kk:
        region = x.region
        obs_rel = x.obs_pos[:, None, :, :] - pos[:, :, None, :]  # (E, N, M, 3)
        obs_dist = np.sqrt(np.einsum("...i,...i->...", obs_rel, obs_rel))
        active = x.active[:, None, :]
        key = np.where(active & (obs_dist <= layout.sensing_range), region, np.inf)
        order = (
            np.argsort(key, axis=-1, kind="stable")[..., :kk]
            if m > 1
            else np.zeros((e, n, 1), dtype=np.intp)
        )
        pair = (np.arange(e * n) * m).reshape(e, n, 1) + order  # into (E * N * M)
        ob = (np.arange(e) * m).reshape(e, 1, 1) + order  # into (E * M)
        present = np.isfinite(key.reshape(-1)[pair])[..., None]
        reg = region.reshape(-1)[pair]
        feats = {
            "center": (x.pred_center.reshape(-1, 3)[ob] - pos[:, :, None, :]) / ps,
            "axes": x.pred_axes.reshape(-1, 3)[ob] / ps,
            "heading_cs": np.stack([x.cos_h.reshape(-1)[ob], x.sin_h.reshape(-1)[ob]], axis=-1),
            "rel_pos": obs_rel.reshape(-1, 3)[pair] / ps,
            "rel_vel": (x.obs_vel.reshape(-1, 3)[ob] - vel[:, :, None, :]) / vs,
            "region_dist": (np.where(np.isfinite(reg), reg, 0.0) / ps)[..., None],
        }
        for name, value in feats.items():
            block[:, :, :kk, f["obstacle_" + name]] = np.where(present, value, 0.0)
        block[:, :, :kk, c.obstacle_mask] = present[..., 0]

    np.clip(out, -layout.clip, layout.clip, out=out)


def global_state(world: World) -> np.ndarray:
    """The global true state, ``(n_envs, state_dim)`` float32 (for centralised critics).

    Concatenates, normalised like the observations: every UAV's true position relative to
    the planned formation centre and velocity, every obstacle's true position relative to
    that centre, its velocity and active flag, and the episode progress.
    """
    cfg = world.config
    ps, vs = cfg.observation.position_scale, cfg.uav.max_speed
    plan_center = world.plan_center
    e = world.n_envs
    parts = [
        ((world.uav_pos - plan_center[:, None, :]) / ps).reshape(e, -1),
        (world.uav_vel / vs).reshape(e, -1),
    ]
    if world.n_obstacles:
        ob = world.obstacles
        parts += [
            ((ob.pos - plan_center[:, None, :]) / ps).reshape(e, -1),
            (world.obstacle_velocities() / vs).reshape(e, -1),
            ob.active.astype(float).reshape(e, -1),
        ]
    parts.append(np.minimum(world.time / cfg.episode_duration, 1.0)[:, None])
    state = np.concatenate(parts, axis=-1)
    return np.clip(state, -cfg.observation.clip, cfg.observation.clip).astype(np.float32)


def state_dim(config: EnvConfig) -> int:
    """Width of :func:`global_state` for ``config``."""
    return config.n_uavs * 6 + config.n_obstacles * 7 + 1
