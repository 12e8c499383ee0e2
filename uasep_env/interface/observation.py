"""Per-agent observations built from what each UAV knows (its Kalman estimates).

Every agent gets one flat ``float32`` vector; which features it holds, in which order, and
their scales are the config's :class:`~uasep_env.interface.observation_layout.ObservationLayout`
(the feature table, :data:`~uasep_env.interface.observation_layout.FEATURES`, is documented in
:mod:`uasep_env.interface.observation_layout`). This module computes them:
:func:`build_observations` (the numpy reference, with a bit-identical compiled twin in
:mod:`uasep_env._kernels.observations`) and the centralised critics' :func:`global_state`.
"""

from __future__ import annotations

import operator
from typing import NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config import EnvConfig
from uasep_env.interface.observation_layout import FEATURES, Feature, ObservationLayout
from uasep_env.reachable.distance import _N_NEWTON, region_distances
from uasep_env.sim.formation import MIN_FRAME_SPEED, formation_center, slot_positions
from uasep_env.sim.obstacles import AIRCRAFT_CLASSES
from uasep_env.sim.world import World

__all__ = [
    "FEATURES",
    "Feature",
    "ObservationLayout",
    "build_observations",
    "global_state",
    "state_dim",
]


class _Inputs(NamedTuple):
    """What an observation is assembled from: the world's estimates plus derived geometry.

    Shapes: ``E`` environments, ``N`` UAVs, ``M`` obstacles. Obstacle fields are empty
    (``M = 0`` rows are never read) when no obstacle is observed. Built in one place,
    :func:`_gather_inputs`, by keyword.
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
    obstacle_pos: np.ndarray  # (E, M, 3) estimated obstacle positions (m)
    obstacle_vel: np.ndarray  # (E, M, 3) estimated obstacle velocities (m/s)
    pred_center: np.ndarray  # (E, M, 3) ellipsoid centres (m)
    pred_axes: np.ndarray  # (E, M, 3) ellipsoid semi-axes (m)
    cos_h: np.ndarray  # (E, M) cosine of the ellipsoid heading
    sin_h: np.ndarray  # (E, M) sine of the ellipsoid heading
    heading: np.ndarray  # (E, M) the ellipsoid heading (rad)
    active: np.ndarray  # (E, M) bool, obstacle present
    aircraft_class: np.ndarray  # (E, M) int64 class code (uasep_env.sim.obstacles.AIRCRAFT_CLASSES)


def build_observations(
    world: World,
    layout: ObservationLayout,
    out: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """Every agent's observation of the world, ``(n_envs, n_uavs, layout.world_dim)`` float32.

    The plan and the predicted ellipsoids come from the world; the estimated positions'
    distances to the ellipsoids, the estimated formation geometry (eqs. 5-7) and the
    per-agent assembly (relative vectors, neighbour sorting, masks, scaling, clipping) are
    :func:`_assemble` (compiled when numba is in use, the same numbers bit for bit).

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


#: The world's state arrays an observation reads (:meth:`World.frozen_inputs` names), and
#: whether each has a row per obstacle (cut to the observed ones).
_STATE = {
    "est_pos": False, "est_vel": False, "slots": False, "accel_cmd": False, "time": False,
    "obstacle_est_pos": True, "obstacle_est_vel": True, "pred_center": True,
    "pred_axes": True, "pred_cos": True, "pred_sin": True, "pred_heading": True,
    "obstacles.active": True, "obstacles.aircraft_class": True,
}  # fmt: skip


def _gather_inputs(
    world: World, layout: ObservationLayout, rows: np.ndarray | None = None
) -> _Inputs:
    """The world's arrays an observation is made of (the formation geometry is derived).

    All environments, or the ``rows`` (an index array) only.
    """
    m = world.n_obstacles if layout.k_obstacles else 0
    r = slice(None) if rows is None else rows
    plan = world._plan_arrays()
    if rows is None and m == world.n_obstacles:
        s = world.frozen_inputs()  # every row of every array: views made once
    else:
        s = {}
        for name, per_obstacle in _STATE.items():
            a = operator.attrgetter(name)(world)
            s[name] = a[r, :m] if per_obstacle else a[r]
        plan = tuple(a[r] for a in plan)
    center, direction, plan_pos, plan_vel = plan
    return _Inputs(
        pos=s["est_pos"],
        vel=s["est_vel"],
        pattern=s["slots"],
        plan_pos=plan_pos,
        plan_vel=plan_vel,
        accel_cmd=s["accel_cmd"],
        plan_center=center,
        wp_dir=direction,
        final_wp=world.plan.waypoints[r, -1],
        progress=np.minimum(s["time"] / world.config.episode_duration, 1.0),
        obstacle_pos=s["obstacle_est_pos"],
        obstacle_vel=s["obstacle_est_vel"],
        pred_center=s["pred_center"],
        pred_axes=s["pred_axes"],
        cos_h=s["pred_cos"],
        sin_h=s["pred_sin"],
        heading=s["pred_heading"],
        active=s["obstacles.active"],
        aircraft_class=s["obstacles.aircraft_class"],
    )


def _view(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` reshaped to ``shape`` as a view (writes go to ``a``).

    ``np.reshape(..., copy=False)`` says the same but needs numpy >= 2.1; a plain reshape
    may silently copy, so the view is checked.
    """
    view = a.reshape(shape)
    if view.size and not np.may_share_memory(view, a):  # pragma: no cover - never copies
        raise RuntimeError(f"cannot reshape {a.shape} to {shape} without a copy")
    return view


def _write(block: np.ndarray, cols: dict[str, slice], values: dict[str, object]) -> None:
    """``block[..., cols[key]] = value`` for each computed feature the layout has."""
    for key, value in values.items():
        if key in cols:
            block[..., cols[key]] = value


@compiled_twin("assemble_observations", min_frame_speed=MIN_FRAME_SPEED, n_newton=_N_NEWTON)
def _assemble(x: _Inputs, layout: ObservationLayout, out: np.ndarray) -> None:
    """The assembly of :func:`build_observations`: fills ``out`` in place.

    Every feature of the layout is computed here, keyed by its :attr:`Feature.key`, and
    written where :attr:`ObservationLayout.slices` puts it; the rest are skipped. ``out`` is
    float32; a float64 ``out`` holds the same numbers before the cast (cast-then-clip and
    clip-then-cast agree), which the tests compare with the compiled twin's, bit for bit.
    """
    e, n, _ = x.pos.shape
    m = x.pred_center.shape[1]
    ps, vs, acs = layout.pos_scale, layout.vel_scale, layout.acc_scale
    pos, vel = x.pos, x.vel
    cols = layout.slices
    # The formation as the UAVs estimate it (eqs. 5-7).
    center, mean_vel = formation_center(pos, vel)
    slots = slot_positions(center, mean_vel, x.wp_dir, x.pattern)
    wp_dist = np.linalg.norm(x.final_wp - center, axis=-1)

    # Own state; broadcast fields are shared by the formation.
    own = {
        "slot_offset": (slots - pos) / ps,
        "plan_offset": (x.plan_pos - pos) / ps,
        "velocity": vel / vs,
        "plan_velocity": x.plan_vel / vs,
        "formation_velocity": (mean_vel / vs)[:, None, :],
        "goal_offset": ((x.plan_center - center) / ps)[:, None, :],
        "waypoint_dir": x.wp_dir[:, None, :],
        "waypoint_dist": (wp_dist / ps)[:, None, None],
        "last_accel": x.accel_cmd / acs,
        "progress": x.progress[:, None, None],
    }
    _write(out, cols, own)
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
        w = layout.width("uav")
        block = _view(out[..., col : col + k_u * w], (e, n, k_u, w))
        relv = vel.reshape(-1, 3)[other] - vel[:, :, None, :]
        uavs = {
            "uav_rel_pos": np.where(present, rel.reshape(-1, 3)[pair] / ps, 0.0),
            "uav_rel_vel": np.where(present, relv / vs, 0.0),
            "uav_dist": np.where(present, d_sel[..., None] / ps, 0.0),
            "uav_mask": present,
        }
        _write(block, cols, uavs)
        col += k_u * w

    k_o = layout.k_obstacles
    w = layout.width("obstacle")
    block = _view(out[..., col : col + k_o * w], (e, n, k_o, w))
    kk = min(k_o, m)
    block[:, :, kk:] = 0.0
    if kk:
        # The estimated positions against the predicted ellipsoids (the compiled twin solves
        # only the pairs it observes: within the sensing range of the obstacle's estimate).
        region = region_distances.reference(
            pos, x.pred_center, x.pred_axes, x.heading, x.cos_h, x.sin_h, x.active
        )
        ob_rel = x.obstacle_pos[:, None, :, :] - pos[:, :, None, :]  # (E, N, M, 3)
        ob_dist = np.sqrt(np.einsum("...i,...i->...", ob_rel, ob_rel))
        active = x.active[:, None, :]
        key = np.where(active & (ob_dist <= layout.sensing_range), region, np.inf)
        order = (
            np.argsort(key, axis=-1, kind="stable")[..., :kk]
            if m > 1
            else np.zeros((e, n, 1), dtype=np.intp)
        )
        pair = (np.arange(e * n) * m).reshape(e, n, 1) + order  # into (E * N * M)
        ob = (np.arange(e) * m).reshape(e, 1, 1) + order  # into (E * M)
        present = np.isfinite(key.reshape(-1)[pair])[..., None]
        reg = region.reshape(-1)[pair]
        heading = np.stack([x.cos_h.reshape(-1)[ob], x.sin_h.reshape(-1)[ob]], axis=-1)
        feats = {
            "obstacle_center": (x.pred_center.reshape(-1, 3)[ob] - pos[:, :, None, :]) / ps,
            "obstacle_axes": x.pred_axes.reshape(-1, 3)[ob] / ps,
            "obstacle_heading_cs": heading,
            "obstacle_rel_pos": ob_rel.reshape(-1, 3)[pair] / ps,
            "obstacle_rel_vel": (x.obstacle_vel.reshape(-1, 3)[ob] - vel[:, :, None, :]) / vs,
            "obstacle_region_dist": (np.where(np.isfinite(reg), reg, 0.0) / ps)[..., None],
        }
        if "obstacle_class" in cols:  # one-hot of the class code (optional feature)
            code = x.aircraft_class.reshape(-1)[ob]
            feats["obstacle_class"] = code[..., None] == np.arange(len(AIRCRAFT_CLASSES))
        feats = {k: np.where(present, v, 0.0) for k, v in feats.items()}
        feats["obstacle_mask"] = present
        _write(block[:, :, :kk], cols, feats)

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
