"""Observation assembly: :func:`uasep_env.observation._assemble` per agent."""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _gap, _norm3, _parallel


@numba.njit(inline="always", **_JIT)
def _put(out, e, i, col, value, clip):  # noqa: ANN001, ANN202
    """Store as float32, then clip in float32 (the numpy form's cast-then-``np.clip``)."""
    v = np.float32(value)
    if v < -clip:
        v = -clip
    elif v > clip:
        v = clip
    out[e, i, col] = v


@numba.njit(inline="always", **_JIT)
def _mean(x, e, a):  # noqa: ANN001, ANN202
    """``x[e, :, a].mean()`` as :func:`uasep_env.formation._mean_over_uavs` adds it."""
    total = x[e, 0, a]
    for j in range(1, x.shape[1]):
        total += x[e, j, a]
    return total / x.shape[1]


@numba.njit(**_JIT)
def _frame(v0, v1, v2, f0, f1, f2, min_speed):  # noqa: ANN001, ANN202
    """:func:`uasep_env.formation.rotation_from_velocity` of one velocity: ``(ct, st, cp, sp)``.

    ``f`` is the fallback used below ``min_speed``.
    """
    if not _norm3(v0, v1, v2) >= min_speed:
        v0, v1, v2 = f0, f1, f2
    horiz = math.hypot(v0, v1)
    level = horiz > 1e-9
    ct = v0 / horiz if level else 1.0
    st = v1 / horiz if level else 0.0
    h = max(horiz, 1e-12)
    if not level and abs(v2) <= 1e-9:
        return ct, st, 1.0, 0.0
    r = math.hypot(h, v2)
    return ct, st, h / r, -v2 / r


@numba.njit(inline="always", **_JIT)
def _observe_env(e, x, scales, cols, k_u, k_o, self_dim, out):  # noqa: ANN001, ANN202
    """Environment ``e`` of :func:`uasep_env.observation._assemble`, every agent.

    ``x`` is the :class:`uasep_env.observation._Inputs` named tuple of arrays, ``cols`` the
    :data:`uasep_env.observation.COLUMNS` named tuple of column offsets.
    """
    pos, vel = x.pos, x.vel
    # The estimated formation (eqs. 5-7): centre, mean velocity and frame, once per env.
    c0, c1, c2 = _mean(pos, e, 0), _mean(pos, e, 1), _mean(pos, e, 2)
    mv0, mv1, mv2 = _mean(vel, e, 0), _mean(vel, e, 1), _mean(vel, e, 2)
    d = x.wp_dir
    ct, st, cp, sp = _frame(mv0, mv1, mv2, d[e, 0], d[e, 1], d[e, 2], scales[5])
    frame = (c0, c1, c2, mv0, mv1, mv2, ct, st, cp, sp)
    for i in range(pos.shape[1]):
        _observe_agent(e, i, frame, x, scales, cols, k_u, k_o, self_dim, out)


@numba.njit(inline="always", **_JIT)
def _observe_agent(e, i, frame, x, scales, cols, k_u, k_o, self_dim, out):  # noqa: ANN001, ANN202
    """UAV ``i`` of environment ``e``; ``frame`` is the formation's, from :func:`_observe_env`."""
    pos, vel = x.pos, x.vel
    n = pos.shape[1]
    m = x.region.shape[2]
    ps, vs, acs, sensing, clip = scales[0], scales[1], scales[2], scales[3], np.float32(scales[4])
    c0, c1, c2, mv0, mv1, mv2, ct, st, cp, sp = frame
    # This UAV's slot (eq. 7).
    p0, p1, p2 = x.pattern[e, i, 0], x.pattern[e, i, 1], x.pattern[e, i, 2]
    # Rows of the rotation as formation.rotate multiplies them (the zero included).
    slot0 = c0 + ((-st * p0 + (cp * ct) * p1) + (-ct * sp) * p2)
    slot1 = c1 + ((ct * p0 + (cp * st) * p1) + (-st * sp) * p2)
    slot2 = c2 + ((0.0 * p0 + (-sp) * p1) + (-cp) * p2)
    wp_dist = _norm3(x.final_wp[e, 0] - c0, x.final_wp[e, 1] - c1, x.final_wp[e, 2] - c2)
    slot = cols.slot_offset
    _put(out, e, i, slot, (slot0 - pos[e, i, 0]) / ps, clip)
    _put(out, e, i, slot + 1, (slot1 - pos[e, i, 1]) / ps, clip)
    _put(out, e, i, slot + 2, (slot2 - pos[e, i, 2]) / ps, clip)
    fv = cols.formation_velocity
    _put(out, e, i, fv, mv0 / vs, clip)
    _put(out, e, i, fv + 1, mv1 / vs, clip)
    _put(out, e, i, fv + 2, mv2 / vs, clip)
    goal = cols.goal_offset
    _put(out, e, i, goal, (x.plan_center[e, 0] - c0) / ps, clip)
    _put(out, e, i, goal + 1, (x.plan_center[e, 1] - c1) / ps, clip)
    _put(out, e, i, goal + 2, (x.plan_center[e, 2] - c2) / ps, clip)
    for a in range(3):
        p = pos[e, i, a]
        _put(out, e, i, cols.plan_offset + a, (x.plan_pos[e, i, a] - p) / ps, clip)
        _put(out, e, i, cols.velocity + a, vel[e, i, a] / vs, clip)
        _put(out, e, i, cols.plan_velocity + a, x.plan_vel[e, i, a] / vs, clip)
        _put(out, e, i, cols.waypoint_dir + a, x.wp_dir[e, a], clip)
        _put(out, e, i, cols.last_accel + a, x.accel_cmd[e, i, a] / acs, clip)
    _put(out, e, i, cols.waypoint_dist, wp_dist / ps, clip)
    _put(out, e, i, cols.progress, x.progress[e], clip)
    col = self_dim

    # Nearest UAVs: the k smallest (distance, index) pairs in order, i.e. a stable argsort.
    prev_d, prev_j = -np.inf, -1
    for s in range(k_u):
        best_d, best_j = np.inf, n
        for j in range(n):
            if j == i:
                continue
            d = _gap(pos, e, i, pos, j)
            after = d > prev_d or (d == prev_d and j > prev_j)
            if after and (d < best_d or (d == best_d and j < best_j)):
                best_d, best_j = d, j
        if best_j == n:  # only oneself left (an infinite distance): stable order puts it here
            best_d, best_j = np.inf, i
        prev_d, prev_j = best_d, best_j
        c = col + s * cols.uav_width
        if best_d <= sensing:
            for a in range(3):
                rel_p = (pos[e, best_j, a] - pos[e, i, a]) / ps
                _put(out, e, i, c + cols.uav_rel_pos + a, rel_p, clip)
                rel_v = (vel[e, best_j, a] - vel[e, i, a]) / vs
                _put(out, e, i, c + cols.uav_rel_vel + a, rel_v, clip)
            _put(out, e, i, c + cols.uav_dist, best_d / ps, clip)
            _put(out, e, i, c + cols.uav_mask, 1.0, clip)
        else:
            for a in range(cols.uav_width):
                out[e, i, c + a] = 0.0
    col += k_u * cols.uav_width

    # Nearest obstacles by distance to their reachable region (stable, like the UAVs).
    kk = min(k_o, m)
    prev_d, prev_j = -np.inf, -1
    for s in range(kk):
        best_d, best_j = np.inf, m
        for j in range(m):
            key = np.inf
            if x.active[e, j] and _gap(pos, e, i, x.obs_pos, j) <= sensing:
                key = x.region[e, i, j]
            after = key > prev_d or (key == prev_d and j > prev_j)
            if after and (key < best_d or (key == best_d and j < best_j)):
                best_d, best_j = key, j
        prev_d, prev_j = best_d, best_j
        c = col + s * cols.obstacle_width
        if math.isfinite(best_d):
            j = best_j
            for a in range(3):
                v = (x.pred_center[e, j, a] - pos[e, i, a]) / ps
                _put(out, e, i, c + cols.obstacle_center + a, v, clip)
                _put(out, e, i, c + cols.obstacle_axes + a, x.pred_axes[e, j, a] / ps, clip)
                v = (x.obs_pos[e, j, a] - pos[e, i, a]) / ps
                _put(out, e, i, c + cols.obstacle_rel_pos + a, v, clip)
                v = (x.obs_vel[e, j, a] - vel[e, i, a]) / vs
                _put(out, e, i, c + cols.obstacle_rel_vel + a, v, clip)
            _put(out, e, i, c + cols.obstacle_heading_cs, x.cos_h[e, j], clip)
            _put(out, e, i, c + cols.obstacle_heading_cs + 1, x.sin_h[e, j], clip)
            _put(out, e, i, c + cols.obstacle_region_dist, x.region[e, i, j] / ps, clip)
            _put(out, e, i, c + cols.obstacle_mask, 1.0, clip)
        else:
            for a in range(cols.obstacle_width):
                out[e, i, c + a] = 0.0
    for a in range(col + kk * cols.obstacle_width, col + k_o * cols.obstacle_width):
        out[e, i, a] = 0.0


@numba.njit(**_JIT)
def _observe_serial(x, scales, cols, k_u, k_o, self_dim, out):  # noqa: ANN001, ANN202
    for e in range(out.shape[0]):
        _observe_env(e, x, scales, cols, k_u, k_o, self_dim, out)


@numba.njit(parallel=True, **_JIT)
def _observe_parallel(x, scales, cols, k_u, k_o, self_dim, out):  # noqa: ANN001, ANN202
    for e in numba.prange(out.shape[0]):
        _observe_env(e, x, scales, cols, k_u, k_o, self_dim, out)


def assemble_observations(
    inputs: tuple,
    layout: object,
    out: np.ndarray,
    *,
    columns: tuple,
    min_frame_speed: float,
) -> None:
    """Compiled :func:`uasep_env.observation._assemble`: fills ``out`` in place.

    Args:
        inputs: The :class:`uasep_env.observation._Inputs` of one call.
        layout: Its :class:`uasep_env.observation.ObservationLayout`.
        out: ``(E, N, dim)`` float32, C-contiguous.
        columns: :data:`uasep_env.observation.COLUMNS`, where each feature is written.
        min_frame_speed: :data:`uasep_env.formation.MIN_FRAME_SPEED`.
    """
    scales = np.array(
        [
            layout.pos_scale,
            layout.vel_scale,
            layout.acc_scale,
            layout.sensing_range,
            layout.clip,
            min_frame_speed,
        ]
    )
    # Contiguous arrays only: one compiled signature, whatever views the caller passes.
    x = type(inputs)(*(np.ascontiguousarray(a) for a in inputs))
    fn = _observe_parallel if _parallel(out.shape[0] * out.shape[1]) else _observe_serial
    fn(x, scales, columns, layout.k_uavs, layout.k_obstacles, layout.self_dim, out)
