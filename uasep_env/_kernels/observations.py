"""Observation assembly: :func:`uasep_env.interface.observation._assemble` per agent."""

from __future__ import annotations

import functools
import math
from collections import namedtuple

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _gap, _norm3, _parallel, frozen
from uasep_env._kernels.ellipsoids import (
    _ROWS_PER_TASK,
    _body_offset,
    _scratch,
    _store,
    _sweep,
)


# The small store helpers are plain calls that LLVM inlines, not numba's IR inlining
# (``inline="always"``): dozens of IR copies made the observations take ~30 s of an
# evaluation's ~43 s to compile; as calls they run at the same speed (docs/speed.md).
@numba.njit(**_JIT)
def _put(row, col, value, clip):  # noqa: ANN001, ANN202
    """Store in ``out``'s dtype, then clip in it (the numpy form's cast-then-``np.clip``).

    ``clip`` has ``out``'s dtype: float32 for the observations, float64 when a test reads
    the numbers before the cast.
    """
    row[col] = value
    v = row[col]
    if v < -clip:
        row[col] = -clip
    elif v > clip:
        row[col] = clip


@numba.njit(**_JIT)
def _mean(x, e, a):  # noqa: ANN001, ANN202
    """``x[e, :, a].mean()`` as :func:`uasep_env.sim.formation._mean_over_uavs` adds it."""
    total = x[e, 0, a]
    for j in range(1, x.shape[1]):
        total += x[e, j, a]
    return total / x.shape[1]


@numba.njit(**_JIT)
def _frame(v0, v1, v2, f0, f1, f2, min_speed):  # noqa: ANN001, ANN202
    """:func:`uasep_env.sim.formation.rotation_from_velocity` of one velocity: ``(ct, st, cp, sp)``.

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
def _observe_env(e, x, scales, limit, cols, region, out):  # noqa: ANN001, ANN202
    """Environment ``e`` of :func:`uasep_env.interface.observation._assemble`, every agent.

    ``x`` is the :class:`uasep_env.interface.observation._Inputs` named tuple of arrays, ``cols``
    the
    layout's :class:`uasep_env.interface.observation_layout.Columns`: where each feature goes (-1
    when the layout lacks it), the neighbour counts and the block widths; ``limit[0]`` is the
    clip bound in ``out``'s dtype; ``region`` gets each agent's distances to the regions it
    observes (``inf`` for the others).
    """
    pos, vel = x.pos, x.vel
    # The estimated formation (eqs. 5-7): centre, mean velocity and frame, once per env.
    c0, c1, c2 = _mean(pos, e, 0), _mean(pos, e, 1), _mean(pos, e, 2)
    mv0, mv1, mv2 = _mean(vel, e, 0), _mean(vel, e, 1), _mean(vel, e, 2)
    d = x.wp_dir
    ct, st, cp, sp = _frame(mv0, mv1, mv2, d[e, 0], d[e, 1], d[e, 2], scales[4])
    frame = (c0, c1, c2, mv0, mv1, mv2, ct, st, cp, sp)
    for i in range(pos.shape[1]):
        _observe_agent(e, i, frame, x, scales, limit[0], cols, region, out)


@numba.njit(**_JIT)
def _put3(row, col, v0, v1, v2, clip):  # noqa: ANN001, ANN202
    """A 3-vector feature at ``col``, unless the layout lacks it (``col < 0``)."""
    if col >= 0:
        _put(row, col, v0, clip)
        _put(row, col + 1, v1, clip)
        _put(row, col + 2, v2, clip)


@numba.njit(**_JIT)
def _put1(row, col, v, clip):  # noqa: ANN001, ANN202
    """A scalar feature at ``col``, unless the layout lacks it (``col < 0``)."""
    if col >= 0:
        _put(row, col, v, clip)


@numba.njit(inline="always", **_JIT)
def _observe_agent(e, i, frame, x, scales, clip, cols, region, out):  # noqa: ANN001, ANN202
    """UAV ``i`` of environment ``e``; ``frame`` is the formation's, from :func:`_observe_env`.

    Every feature is written at its column of ``cols`` relative to its block, and skipped
    when that is -1.
    """
    pos, vel = x.pos, x.vel
    row = out[e, i]
    n = pos.shape[1]
    m = x.pred_center.shape[1]
    ps, vs, acs, sensing = scales[0], scales[1], scales[2], scales[3]
    c0, c1, c2, mv0, mv1, mv2, ct, st, cp, sp = frame
    p0, p1, p2 = pos[e, i, 0], pos[e, i, 1], pos[e, i, 2]
    # This UAV's slot (eq. 7).
    q0, q1, q2 = x.pattern[e, i, 0], x.pattern[e, i, 1], x.pattern[e, i, 2]
    # Rows of the rotation as formation.rotate multiplies them (the zero included).
    slot0 = c0 + ((-st * q0 + (cp * ct) * q1) + (-ct * sp) * q2)
    slot1 = c1 + ((ct * q0 + (cp * st) * q1) + (-st * sp) * q2)
    slot2 = c2 + ((0.0 * q0 + (-sp) * q1) + (-cp) * q2)
    wp_dist = _norm3(x.final_wp[e, 0] - c0, x.final_wp[e, 1] - c1, x.final_wp[e, 2] - c2)
    _put3(row, cols.slot_offset, (slot0 - p0) / ps, (slot1 - p1) / ps, (slot2 - p2) / ps, clip)
    pp, pv, ac, wd = x.plan_pos, x.plan_vel, x.accel_cmd, x.wp_dir
    v = ((pp[e, i, 0] - p0) / ps, (pp[e, i, 1] - p1) / ps, (pp[e, i, 2] - p2) / ps)
    _put3(row, cols.plan_offset, v[0], v[1], v[2], clip)
    _put3(row, cols.velocity, vel[e, i, 0] / vs, vel[e, i, 1] / vs, vel[e, i, 2] / vs, clip)
    _put3(row, cols.plan_velocity, pv[e, i, 0] / vs, pv[e, i, 1] / vs, pv[e, i, 2] / vs, clip)
    _put3(row, cols.formation_velocity, mv0 / vs, mv1 / vs, mv2 / vs, clip)
    pc = x.plan_center
    v = ((pc[e, 0] - c0) / ps, (pc[e, 1] - c1) / ps, (pc[e, 2] - c2) / ps)
    _put3(row, cols.goal_offset, v[0], v[1], v[2], clip)
    _put3(row, cols.waypoint_dir, wd[e, 0], wd[e, 1], wd[e, 2], clip)
    _put1(row, cols.waypoint_dist, wp_dist / ps, clip)
    _put3(row, cols.last_accel, ac[e, i, 0] / acs, ac[e, i, 1] / acs, ac[e, i, 2] / acs, clip)
    _put1(row, cols.progress, x.progress[e], clip)
    col = cols.self_dim

    # Nearest UAVs: the k smallest (distance, index) pairs in order, i.e. a stable argsort.
    prev_d, prev_j = -np.inf, -1
    for s in range(cols.k_uavs):
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
            j = best_j
            _uav_features(row, e, i, c, cols, x, j, best_d, ps, vs, clip)
        else:
            for a in range(cols.uav_width):
                row[c + a] = 0.0
    col += cols.k_uavs * cols.uav_width

    # Nearest obstacles by distance to their reachable region (stable, like the UAVs), the
    # distances solved beforehand (_regions_rows).
    k_o, w = cols.k_obstacles, cols.obstacle_width
    kk = min(k_o, m)
    prev_d, prev_j = -np.inf, -1
    for s in range(kk):
        best_d, best_j = np.inf, m
        for j in range(m):
            key = region[e, i, j]
            after = key > prev_d or (key == prev_d and j > prev_j)
            if after and (key < best_d or (key == best_d and j < best_j)):
                best_d, best_j = key, j
        prev_d, prev_j = best_d, best_j
        c = col + s * w
        if math.isfinite(best_d):
            _obstacle_features(row, e, i, c, cols, x, best_d, best_j, ps, vs, clip)
        else:
            for a in range(w):
                row[c + a] = 0.0
    for a in range(col + kk * w, col + k_o * w):
        row[a] = 0.0


@numba.njit(inline="always", **_JIT)
def _put_relative(row, c, col, of, j, to, e, i, scale, clip):  # noqa: ANN001, ANN202
    """``(of[e, j] - to[e, i]) / scale`` at column ``col`` of the block at ``c``.

    Unless the layout lacks the feature (``col < 0``).
    """
    if col >= 0:
        _put3(row, c + col, (of[e, j, 0] - to[e, i, 0]) / scale,
              (of[e, j, 1] - to[e, i, 1]) / scale, (of[e, j, 2] - to[e, i, 2]) / scale,
              clip)  # fmt: skip


@numba.njit(inline="always", **_JIT)
def _uav_features(row, e, i, c, cols, x, j, dist, ps, vs, clip):  # noqa: ANN001, ANN202
    """UAV ``j`` as UAV ``i`` observes it, into the block at column ``c`` (it is present)."""
    pos, vel = x.pos, x.vel
    _put_relative(row, c, cols.uav_rel_pos, pos, j, pos, e, i, ps, clip)
    _put_relative(row, c, cols.uav_rel_vel, vel, j, vel, e, i, vs, clip)
    if cols.uav_dist >= 0:
        _put(row, c + cols.uav_dist, dist / ps, clip)
    if cols.uav_mask >= 0:
        _put(row, c + cols.uav_mask, 1.0, clip)


@numba.njit(inline="always", **_JIT)
def _obstacle_features(row, e, i, c, cols, x, dist, j, ps, vs, clip):  # noqa: ANN001, ANN202
    """Obstacle ``j`` as UAV ``i`` observes it, into the block at column ``c`` (present).

    ``dist``: the UAV's distance to the obstacle's region (m).
    """
    pos, vel = x.pos, x.vel
    _put_relative(row, c, cols.obstacle_center, x.pred_center, j, pos, e, i, ps, clip)
    if cols.obstacle_axes >= 0:
        ax = x.pred_axes
        r = (ax[e, j, 0] / ps, ax[e, j, 1] / ps, ax[e, j, 2] / ps)
        _put3(row, c + cols.obstacle_axes, r[0], r[1], r[2], clip)
    if cols.obstacle_heading_cs >= 0:
        _put(row, c + cols.obstacle_heading_cs, x.cos_h[e, j], clip)
        _put(row, c + cols.obstacle_heading_cs + 1, x.sin_h[e, j], clip)
    _put_relative(row, c, cols.obstacle_rel_pos, x.obstacle_pos, j, pos, e, i, ps, clip)
    _put_relative(row, c, cols.obstacle_rel_vel, x.obstacle_vel, j, vel, e, i, vs, clip)
    if cols.obstacle_region_dist >= 0:
        _put(row, c + cols.obstacle_region_dist, dist / ps, clip)
    if cols.obstacle_mask >= 0:
        _put(row, c + cols.obstacle_mask, 1.0, clip)
    if cols.obstacle_class >= 0:  # one-hot of the aircraft class code
        code = x.aircraft_class[e, j]
        for a in range(cols.n_classes):  # the class table's length, as data
            _put(row, c + cols.obstacle_class + a, 1.0 if code == a else 0.0, clip)


# The named tuples an observation is made of arrive as plain tuples and are named again
# here: numba reads a plain tuple's type in C and a named one's in Python, about 1 us for
# the inputs and 2 us for the columns on every call (a tenth of a one-environment step).
# The fields are the reference's, in its order (tests/test_kernels.py checks them).
_Inputs = namedtuple(
    "_Inputs",
    "pos vel pattern plan_pos plan_vel accel_cmd plan_center wp_dir final_wp progress "
    "obstacle_pos obstacle_vel pred_center pred_axes cos_h sin_h heading active aircraft_class",
)
_Columns = namedtuple(
    "_Columns",
    "slot_offset plan_offset velocity plan_velocity formation_velocity goal_offset "
    "waypoint_dir waypoint_dist last_accel progress uav_rel_pos uav_rel_vel uav_dist uav_mask "
    "obstacle_center obstacle_axes obstacle_heading_cs obstacle_rel_pos obstacle_rel_vel "
    "obstacle_region_dist obstacle_mask obstacle_class k_uavs k_obstacles self_dim uav_width "
    "obstacle_width n_classes",
)


@numba.njit(inline="always", **_JIT)
def _regions_rows(e0, e1, x, sensing, cols, n_newton, work, live, gaps, region):  # noqa: ANN001, ANN202
    """``region[e, i, j]``: agent ``i``'s distance to obstacle ``j``'s region, rows ``e0:e1``.

    Solved only for the obstacles observed (present, within the sensing range; ``inf`` for
    the others), and not at all for a layout without obstacles: set up in the scratch rows
    from ``e0 * N * M`` on and solved in one sweep (:func:`~.ellipsoids._sweep`, each
    distance :func:`~.ellipsoids._nearest_one`'s bit for bit).
    """
    pos = x.pos
    n, m = pos.shape[1], x.pred_center.shape[1]
    if min(cols.k_obstacles, m) == 0:
        return
    c, ax, cos_h, sin_h = x.pred_center, x.pred_axes, x.cos_h, x.sin_h
    lo = k = e0 * n * m
    for e in range(e0, e1):
        for i in range(n):
            for j in range(m):
                if x.active[e, j] and _gap(pos, e, i, x.obstacle_pos, j) <= sensing:
                    q0, q1, q2 = _body_offset(pos, e, i, c, cos_h, sin_h, j)
                    _store(work, k, q0, q1, q2, ax[e, j, 0], ax[e, j, 1], ax[e, j, 2])
                    k += 1
                    region[e, i, j] = np.nan  # solved below
                else:
                    region[e, i, j] = np.inf
    _sweep(work, live, lo, k, n_newton, gaps)
    k = lo
    for e in range(e0, e1):
        for i in range(n):
            for j in range(m):
                if math.isnan(region[e, i, j]):
                    region[e, i, j] = gaps[k]
                    k += 1


@numba.njit(**_JIT)
def _observe_serial(xt, scales, limit, ct, region, n_newton, work, live, gaps, out):  # noqa: ANN001, ANN202
    x = _Inputs(*xt)
    cols = _Columns(*ct)
    _regions_rows(0, out.shape[0], x, scales[3], cols, n_newton, work, live, gaps, region)
    for e in range(out.shape[0]):
        _observe_env(e, x, scales, limit, cols, region, out)


@numba.njit(parallel=True, **_JIT)
def _observe_parallel(xt, scales, limit, ct, region, n_newton, work, live, gaps, out):  # noqa: ANN001, ANN202
    x = _Inputs(*xt)  # one statement each: the parallel loop looks up the definitions
    cols = _Columns(*ct)
    n_rows = out.shape[0]
    for c in numba.prange((n_rows + _ROWS_PER_TASK - 1) // _ROWS_PER_TASK):
        e0 = c * _ROWS_PER_TASK
        e1 = min(e0 + _ROWS_PER_TASK, n_rows)
        _regions_rows(e0, e1, x, scales[3], cols, n_newton, work, live, gaps, region)
        for e in range(e0, e1):
            _observe_env(e, x, scales, limit, cols, region, out)


def assemble_observations(
    inputs: tuple, layout: object, out: np.ndarray, *, min_frame_speed: float, n_newton: int
) -> None:
    """Compiled :func:`uasep_env.interface.observation._assemble`: fills ``out`` in place.

    Args:
        inputs: The :class:`uasep_env.interface.observation._Inputs` of one call.
        layout: Its :class:`uasep_env.interface.observation_layout.ObservationLayout`; its
            ``columns`` say where each feature goes (data, not compiled in).
        out: ``(E, N, dim)`` float32, C-contiguous (float64: the same numbers before the
            cast to float32, for the tests).
        min_frame_speed: :data:`uasep_env.sim.formation.MIN_FRAME_SPEED`.
        n_newton: The region solve's Newton iterations (``uasep_env.reachable.distance``'s).
    """
    scales, limit, columns = _constants(layout, min_frame_speed, out.dtype)
    # One compiled signature, whatever views the caller passes (common.frozen).
    x = tuple(map(frozen, inputs))
    fn = _observe_parallel if _parallel(out.shape[0] * out.shape[1]) else _observe_serial
    region = np.empty((*out.shape[:2], inputs.pred_center.shape[1]))  # the agents' distances
    work, live, gaps = _scratch(region.size)
    fn(x, scales, limit, columns, region, n_newton, work, live, gaps, out)


@functools.lru_cache(maxsize=32)
def _constants(layout: object, min_frame_speed: float, dtype: np.dtype) -> tuple:
    """The kernel's scales, clip bound and columns, made once a layout.

    The clip bound is in ``dtype`` (the output's); the columns are a plain tuple.
    """
    scales = np.array(
        [
            layout.pos_scale,
            layout.vel_scale,
            layout.acc_scale,
            layout.sensing_range,
            min_frame_speed,
        ]
    )
    limit = np.full(1, layout.clip, dtype=dtype)
    return frozen(scales), frozen(limit), tuple(layout.columns)
