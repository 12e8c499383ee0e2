"""Per-agent observations built from what each UAV knows (its Kalman estimates).

Every agent gets one flat ``float32`` vector; the layout is fixed by the config and
described by :class:`ObservationLayout`, which also decodes a vector back into SI
quantities. The reference APF controllers act on decoded observations, so they and
learned policies see exactly the same information.

All vectors are expressed along the NED axes (x north, y east, z down), relative to the
observing UAV. Positions are divided by ``observation.position_scale`` (m), velocities by
``uav.max_speed`` (m/s), accelerations by ``uav.max_accel`` (m/s^2); every entry is then
clipped to ``[-clip, clip]``.

=====================  ====  ==========================================================
Feature                Size  Meaning (before scaling)
=====================  ====  ==========================================================
``slot_offset``        3     desired slot (eq. 7, from estimates) minus own position (m)
``plan_offset``        3     own planned position minus own position (m)
``velocity``           3     own estimated velocity (m/s)
``plan_velocity``      3     planned velocity of the formation (m/s)
``formation_velocity`` 3     formation mean velocity ``v_o`` (eq. 5) (m/s)
``goal_offset``        3     planned formation centre minus the estimated centre (m)
``waypoint_dir``       3     unit direction of the planned path now
``waypoint_dist``      1     distance from the centre to the final way-point (m)
``last_accel``         3     own last commanded acceleration (m/s^2)
``progress``           1     elapsed fraction of the episode
per nearest UAV (K_u)  8     relative position (3, m), relative velocity (3, m/s),
                             distance (1, m), presence mask (1)
per nearest obstacle   16    reachable-ellipsoid centre relative to the UAV (3, m),
(K_o)                        semi-axes (longitudinal, lateral, vertical) (3, m),
                             heading (cos, sin) (2), obstacle position relative to the
                             UAV (3, m), obstacle velocity relative to the UAV (3, m/s),
                             signed distance from the UAV to the ellipsoid (1, m),
                             presence mask (1)
=====================  ====  ==========================================================

UAVs are sorted by estimated distance, obstacles by distance to their reachable region;
absent entries (fewer than K, or beyond ``sensing_range``) are zero with mask 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.formation import formation_center
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
    """

    k_uavs: int
    k_obstacles: int
    pos_scale: float
    vel_scale: float
    acc_scale: float
    clip: float
    sensing_range: float

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
        )

    @property
    def self_dim(self) -> int:
        """Width of the own-state block."""
        return _width(SELF_FIELDS)

    @property
    def dim(self) -> int:
        """Width of the whole observation vector."""
        return (
            self.self_dim
            + self.k_uavs * _width(UAV_FIELDS)
            + self.k_obstacles * _width(OBSTACLE_FIELDS)
        )

    def _scale(self, kind: str) -> float:
        return {"pos": self.pos_scale, "vel": self.vel_scale, "acc": self.acc_scale}.get(kind, 1.0)

    def decode(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Turn observation vectors back into SI quantities.

        Args:
            obs: ``(..., dim)`` observations.

        Returns:
            A dict of arrays: the own-state fields of :data:`SELF_FIELDS` (``(..., size)``),
            ``uav_<field>`` with shape ``(..., k_uavs, size)`` and ``obstacle_<field>`` with
            shape ``(..., k_obstacles, size)``. Masks are bools of shape ``(..., K)``.
            Values that were clipped stay clipped.

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
        return names


def build_observations(
    world: World, layout: ObservationLayout, out: np.ndarray | None = None
) -> np.ndarray:
    """Every agent's observation, ``(n_envs, n_uavs, layout.dim)`` float32.

    Args:
        world: The batched world.
        layout: The layout for the world's config.
        out: Optional preallocated output array.

    Returns:
        The observations (``out`` if given).
    """
    e, n, m = world.n_envs, world.n_uavs, world.n_obstacles
    if out is None:
        out = np.zeros((e, n, layout.dim), dtype=np.float32)
    ps, vs, acs = layout.pos_scale, layout.vel_scale, layout.acc_scale
    pos, vel = world.est_pos, world.est_vel
    center, mean_vel = formation_center(pos, vel)
    slots = world.desired_slots(estimated=True)
    plan_pos, plan_vel = world.planned()
    plan_center, _ = world.plan.center(world.time)
    last_wp = world.plan.waypoints[:, -1]
    to_end = last_wp - center
    wp_dist = np.linalg.norm(to_end, axis=-1)
    wp_dir = world.plan.heading_velocity(world.time)
    progress = np.minimum(world.time / world.config.episode_duration, 1.0)

    cols: list[np.ndarray] = [
        (slots - pos) / ps,
        (plan_pos - pos) / ps,
        vel / vs,
        plan_vel / vs,
        np.broadcast_to(mean_vel[:, None, :], (e, n, 3)) / vs,
        np.broadcast_to((plan_center - center)[:, None, :], (e, n, 3)) / ps,
        np.broadcast_to(wp_dir[:, None, :], (e, n, 3)),
        np.broadcast_to((wp_dist / ps)[:, None, None], (e, n, 1)),
        world.accel_cmd / acs,
        np.broadcast_to(progress[:, None, None], (e, n, 1)),
    ]

    k_u = layout.k_uavs
    if k_u:
        rel = pos[:, None, :, :] - pos[:, :, None, :]  # (E, N(i), N(j), 3): j relative to i
        relv = vel[:, None, :, :] - vel[:, :, None, :]
        dist = np.sqrt(np.einsum("...i,...i->...", rel, rel))
        dist_sort = np.where(np.eye(n, dtype=bool), np.inf, dist)
        order = np.argsort(dist_sort, axis=-1, kind="stable")[..., :k_u]  # (E, N, K)
        d_sel = np.take_along_axis(dist_sort, order, axis=-1)
        present = d_sel <= layout.sensing_range
        r_sel = np.take_along_axis(rel, order[..., None], axis=-2)
        v_sel = np.take_along_axis(relv, order[..., None], axis=-2)
        pm = present[..., None]
        block = np.concatenate(
            [
                np.where(pm, r_sel / ps, 0.0),
                np.where(pm, v_sel / vs, 0.0),
                np.where(pm, d_sel[..., None] / ps, 0.0),
                pm.astype(float),
            ],
            axis=-1,
        )
        cols.append(block.reshape(e, n, -1))

    k_o = layout.k_obstacles
    block_o = np.zeros((e, n, k_o, _width(OBSTACLE_FIELDS)))
    if m:
        region = world.region_distances(pos)  # estimated UAV pos vs predicted ellipsoids
        obs_rel = world.obs_est_pos[:, None, :, :] - pos[:, :, None, :]
        obs_dist = np.sqrt(np.einsum("...i,...i->...", obs_rel, obs_rel))
        active = world.obstacles.active[:, None, :]
        key = np.where(active & (obs_dist <= layout.sensing_range), region, np.inf)
        order = np.argsort(key, axis=-1, kind="stable")[..., :k_o]  # (E, N, <=K)
        kk = order.shape[-1]
        present = np.isfinite(np.take_along_axis(key, order, axis=-1))
        center_rel = world.pred_center[:, None, :, :] - pos[:, :, None, :]
        hd = world.pred_heading[:, None, :]
        feats = np.concatenate(
            [
                center_rel / ps,
                np.broadcast_to(world.pred_axes[:, None, :, :], center_rel.shape) / ps,
                np.broadcast_to(np.stack([np.cos(hd), np.sin(hd)], axis=-1), (e, n, m, 2)),
                obs_rel / ps,
                (world.obs_est_vel[:, None, :, :] - vel[:, :, None, :]) / vs,
                np.where(np.isfinite(region), region, 0.0)[..., None] / ps,
                np.ones((e, n, m, 1)),
            ],
            axis=-1,
        )
        sel = np.take_along_axis(feats, order[..., None], axis=-2)
        block_o[:, :, :kk] = np.where(present[..., None], sel, 0.0)
    cols.append(block_o.reshape(e, n, -1))

    full = np.concatenate(cols, axis=-1)
    np.clip(full, -layout.clip, layout.clip, out=full)
    out[...] = full
    return out


def global_state(world: World) -> np.ndarray:
    """The global true state, ``(n_envs, state_dim)`` float32 (for centralised critics).

    Concatenates, normalised like the observations: every UAV's true position relative to
    the planned formation centre and velocity, every obstacle's true position relative to
    that centre, its velocity and active flag, and the episode progress.
    """
    cfg = world.config
    ps, vs = cfg.observation.position_scale, cfg.uav.max_speed
    plan_center, _ = world.plan.center(world.time)
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
