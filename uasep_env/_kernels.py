"""Compiled (numba) forms of the hot numerical kernels; imported only when numba is in use.

Each kernel is the scalar, per-point transcription of a numpy function elsewhere in the
package and returns the same numbers bit for bit (``tests/test_kernels.py`` checks it): the
same operations in the same order, no ``fastmath``. The numpy forms stay the reference and
the fallback when numba is missing: each is decorated with
:func:`uasep_env._numba.compiled_twin`, which names its kernel here and the constants the
kernel receives as keyword arguments. This module imports nothing of the package.

* :func:`nearest_on_ellipsoids` -- :func:`uasep_env.reachable.distance._nearest` (the body
  frame solve with the heading rotation around it);
* :func:`pairwise_distances` -- the same solve for every point against every ellipsoid of
  its batch row (:func:`uasep_env.reachable.distance._pairwise`), without broadcast copies,
  and :func:`region_distances`, the same from precomputed cosines and sines with the
  inactive regions at ``inf`` (:func:`uasep_env.reachable.distance.region_distances`);
* :func:`separations` -- :func:`uasep_env.geometry.nearest_separations`;
* :func:`assemble_observations` -- :func:`uasep_env.observation._assemble`;
* :func:`reward_terms` -- :func:`uasep_env.rewards._weighted_terms`;
* :func:`plan_now` -- :func:`uasep_env.formation.planned_state`.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@numba.njit(inline="always", **_JIT)
def _newton_terms(sig, off, cq):  # noqa: ANN001, ANN202
    """``w^2`` and ``w^2 / s`` of one axis at multiplier ``sig`` (0 where ``s <= 0``)."""
    s = sig + off
    if s > 0.0:
        w = cq / s
        w2 = w * w
        return w2, w2 / s
    return 0.0, 0.0


@numba.njit(inline="always", **_JIT)
def _nearest_one(q0, q1, q2, a0, a1, a2, n_newton):  # noqa: ANN001, ANN202
    """Nearest point of one ellipsoid, body frame: ``(x0, x1, x2, dist, n0, n1, n2)``.

    Scalars only (no temporary arrays): allocation would dominate the arithmetic. Inlined,
    so that a caller that keeps only the distance does not compute the rest.
    """
    g0 = -1.0 if q0 < 0.0 else 1.0
    g1 = -1.0 if q1 < 0.0 else 1.0
    g2 = -1.0 if q2 < 0.0 else 1.0
    qa0, qa1, qa2 = abs(q0), abs(q1), abs(q2)
    scale = max(max(a0, a1, a2), max(qa0, qa1, qa2))
    if not scale > 0.0:
        scale = 1.0
    qs0, qs1, qs2 = qa0 / scale, qa1 / scale, qa2 / scale
    b0, b1, b2 = a0 / scale, a1 / scale, a2 / scale
    m = 0
    am = b0
    if b1 < am:
        m, am = 1, b1
    if b2 < am:
        m, am = 2, b2
    am2 = am * am
    off0, off1, off2 = b0 * b0 - am2, b1 * b1 - am2, b2 * b2 - am2
    cq0, cq1, cq2 = b0 * qs0, b1 * qs1, b2 * qs2
    sig = max(cq0 - b0 * b0 + am2, cq1 - b1 * b1 + am2, cq2 - b2 * b2 + am2)
    bmax = max(b0, b1, b2)
    sig = max(sig, math.sqrt(cq0 * cq0 + cq1 * cq1 + cq2 * cq2) - bmax * bmax + am * am)
    sig_lo = max(sig, 0.0)
    r0 = qs0 / b0 if b0 > 0.0 else (np.inf if qs0 > 0.0 else 0.0)
    r1 = qs1 / b1 if b1 > 0.0 else (np.inf if qs1 > 0.0 else 0.0)
    r2 = qs2 / b2 if b2 > 0.0 else (np.inf if qs2 > 0.0 else 0.0)
    level = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    guess = am * am * (level if math.isfinite(level) else 0.0) if am > 0.0 else 0.0
    sig = max(sig_lo, guess)
    for _ in range(n_newton):
        w20, w2s0 = _newton_terms(sig, off0, cq0)
        w21, w2s1 = _newton_terms(sig, off1, cq1)
        w22, w2s2 = _newton_terms(sig, off2, cq2)
        f2 = w20 + w21 + w22
        g = w2s0 + w2s1 + w2s2
        if m == 0:
            f2r, gr = f2 - w20, g - w2s0
        elif m == 1:
            f2r, gr = f2 - w21, g - w2s1
        else:
            f2r, gr = f2 - w22, g - w2s2
        f = math.sqrt(f2)
        fr = math.sqrt(max(f2r, 0.0))
        step = f2 * (f - 1.0) / g if g > 0.0 else 0.0
        step_r = f2r * (fr - 1.0) / gr if (gr > 0.0 and fr > 1.0) else -np.inf
        nxt = max(sig_lo, sig + max(step, step_r))
        if nxt == sig:
            break  # a fixed point: the remaining iterations would not change a bit
        sig = nxt
    s0, s1, s2 = sig + off0, sig + off1, sig + off2
    w0 = cq0 / s0 if s0 > 0.0 and m != 0 else 0.0
    w1 = cq1 / s1 if s1 > 0.0 and m != 1 else 0.0
    w2 = cq2 / s2 if s2 > 0.0 and m != 2 else 0.0
    rest = w0 * w0 + w1 * w1 + w2 * w2
    shrink = 1.0 / math.sqrt(max(rest, 1.0)) if rest > 1.0 else 1.0
    w0, w1, w2 = w0 * shrink, w1 * shrink, w2 * shrink
    wm = math.sqrt(max(1.0 - rest, 0.0))
    if m == 0:
        w0 = wm
    elif m == 1:
        w1 = wm
    else:
        w2 = wm
    x0, x1, x2 = b0 * w0, b1 * w1, b2 * w2
    n0 = w0 * am / b0 if b0 > 0.0 else 0.0
    n1 = w1 * am / b1 if b1 > 0.0 else 0.0
    n2 = w2 * am / b2 if b2 > 0.0 else 0.0
    if am <= 0.0:
        pole = 1.0 if rest < 1.0 else 0.0
        if m == 0:
            n0 = pole
        elif m == 1:
            n1 = pole
        else:
            n2 = pole
    e0, e1, e2 = qs0 - x0, qs1 - x1, qs2 - x2
    dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    inside = level < 1.0
    ngn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if (inside or dist <= 1e-12) and ngn > 0.0:
        d0, d1, d2 = n0 / ngn, n1 / ngn, n2 / ngn
    else:
        den = dist if dist > 0.0 else 1.0
        d0, d1, d2 = e0 / den, e1 / den, e2 / den
    if not math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) > 0.0:
        d0 = 1.0 if m == 0 else 0.0
        d1 = 1.0 if m == 1 else 0.0
        d2 = 1.0 if m == 2 else 0.0
    signed = (-dist if inside else dist) * scale
    return (
        x0 * scale * g0,
        x1 * scale * g1,
        x2 * scale * g2,
        signed,
        d0 * g0,
        d1 * g1,
        d2 * g2,
    )


@numba.njit(inline="always", **_JIT)
def _solve_point(k, points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out):  # noqa: ANN001, ANN202
    """Point ``k`` of a flat batch: rotate into the body frame, solve, rotate back."""
    cp = cos_h[k]
    sp = sin_h[k]
    d0 = points[k, 0] - centers[k, 0]
    d1 = points[k, 1] - centers[k, 1]
    d2 = points[k, 2] - centers[k, 2]
    q0 = d0 * cp + d1 * sp
    q1 = -d0 * sp + d1 * cp
    x0, x1, x2, dist, n0, n1, n2 = _nearest_one(
        q0, q1, d2, axes[k, 0], axes[k, 1], axes[k, 2], n_newton
    )
    d_out[k] = dist
    x_out[k, 0] = x0 * cp - x1 * sp
    x_out[k, 1] = x0 * sp + x1 * cp
    x_out[k, 2] = x2
    n_out[k, 0] = n0 * cp - n1 * sp
    n_out[k, 1] = n0 * sp + n1 * cp
    n_out[k, 2] = n2


# Two loops, not one function compiled twice: numba's disk cache keys on the function only.
@numba.njit(**_JIT)
def _serial(points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out):  # noqa: ANN001, ANN202
    for k in range(points.shape[0]):
        _solve_point(k, points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out)


@numba.njit(parallel=True, **_JIT)
def _parallel_loop(points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out):  # noqa: ANN001, ANN202
    for k in numba.prange(points.shape[0]):
        _solve_point(k, points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out)


#: Points per call above which the loop is spread over the cores (thread start-up costs).
PARALLEL_MIN = 2048
# numba's OpenMP layer (GNU) kills a forked child that runs a parallel loop after its
# parent has run one; forked children (multiprocessing workers) use the serial loops.
_forked = [False]
os.register_at_fork(after_in_child=lambda: _forked.__setitem__(0, True))


def _parallel(size: int) -> bool:
    """Whether a loop over ``size`` items is spread over the cores."""
    return size >= PARALLEL_MIN and not _forked[0]


def nearest_on_ellipsoids(
    points: np.ndarray,
    centers: np.ndarray,
    axes: np.ndarray,
    headings: np.ndarray,
    *,
    n_newton: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest surface points (offsets from the centres, NED), signed distances, normals.

    Args:
        points: ``(..., 3)`` positions (m).
        centers: ``(..., 3)`` ellipsoid centres (m).
        axes: ``(..., 3)`` semi-axes (m), already validated.
        headings: ``(...)`` headings (rad); the four broadcast together.
        n_newton: Newton iterations (the numpy form's).

    Returns:
        ``(offset, distance, normal)``: ``(..., 3)`` nearest point minus the centre, NED (m);
        ``(...)`` signed distance (m); ``(..., 3)`` unit outward normal, NED.
    """
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64)
    ax = np.asarray(axes, dtype=np.float64)
    psi = np.asarray(headings, dtype=np.float64)
    shape = np.broadcast_shapes(p.shape[:-1], c.shape[:-1], ax.shape[:-1], psi.shape)
    k = int(np.prod(shape))
    flat = (k, 3)
    p = np.broadcast_to(p, (*shape, 3)).reshape(flat)
    c = np.broadcast_to(c, (*shape, 3)).reshape(flat)
    ax = np.broadcast_to(ax, (*shape, 3)).reshape(flat)
    psi = np.broadcast_to(psi, shape).reshape(-1)
    x = np.empty((k, 3))
    d = np.empty(k)
    n = np.empty((k, 3))
    fn = _parallel_loop if _parallel(k) else _serial
    # numpy's cos/sin, not libm's: the rotation must match the numpy form to the last bit.
    fn(p, c, ax, np.cos(psi), np.sin(psi), n_newton, x, d, n)
    return x.reshape(*shape, 3), d.reshape(shape), n.reshape(*shape, 3)


@numba.njit(inline="always", **_JIT)
def _pair_distance(k, points, centers, axes, cos_h, sin_h, active, n_newton, out):  # noqa: ANN001, ANN202
    """Pair ``k`` of the flat ``(E, N, M)`` grid: point ``(e, i)`` against ellipsoid ``(e, j)``.

    ``inf`` where the ellipsoid is not ``active``.
    """
    n, m = points.shape[1], centers.shape[1]
    e = k // (n * m)
    i = (k // m) % n
    j = k % m
    if not active[e, j]:
        out[e, i, j] = np.inf
        return
    cp = cos_h[e, j]
    sp = sin_h[e, j]
    d0 = points[e, i, 0] - centers[e, j, 0]
    d1 = points[e, i, 1] - centers[e, j, 1]
    d2 = points[e, i, 2] - centers[e, j, 2]
    q0 = d0 * cp + d1 * sp
    q1 = -d0 * sp + d1 * cp
    res = _nearest_one(q0, q1, d2, axes[e, j, 0], axes[e, j, 1], axes[e, j, 2], n_newton)
    out[e, i, j] = res[3]


@numba.njit(**_JIT)
def _pairs_serial(points, centers, axes, cos_h, sin_h, active, n_newton, out):  # noqa: ANN001, ANN202
    for k in range(out.size):
        _pair_distance(k, points, centers, axes, cos_h, sin_h, active, n_newton, out)


@numba.njit(parallel=True, **_JIT)
def _pairs_parallel(points, centers, axes, cos_h, sin_h, active, n_newton, out):  # noqa: ANN001, ANN202
    for k in numba.prange(out.size):
        _pair_distance(k, points, centers, axes, cos_h, sin_h, active, n_newton, out)


def pairwise_distances(
    points: np.ndarray,
    centers: np.ndarray,
    axes: np.ndarray,
    headings: np.ndarray,
    *,
    n_newton: int,
) -> np.ndarray:
    """Signed distance of every point to every ellipsoid of the same batch row.

    Args:
        points: ``(E, N, 3)`` positions (m).
        centers: ``(E, M, 3)`` ellipsoid centres (m).
        axes: ``(E, M, 3)`` semi-axes (m), already validated.
        headings: ``(E, M)`` headings (rad).
        n_newton: Newton iterations (the numpy form's).

    Returns:
        ``(E, N, M)`` signed distances (m), as :func:`nearest_on_ellipsoids` on the pairs.
    """
    on = np.ones(headings.shape, dtype=bool)
    cos_h, sin_h = np.cos(headings), np.sin(headings)
    return _region_loop(points, centers, axes, cos_h, sin_h, on, n_newton)


def region_distances(
    points: np.ndarray,
    centers: np.ndarray,
    axes: np.ndarray,
    headings: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    active: np.ndarray,
    *,
    n_newton: int,
) -> np.ndarray:
    """:func:`pairwise_distances` from the headings' cosines and sines, ``inf`` where inactive.

    The world keeps the cosines and sines of its regions' headings (numpy's, the same
    numbers as :func:`pairwise_distances` computes), so a step does not compute them again;
    ``headings`` is the numpy form's input and is not read here.

    Args:
        points: ``(E, N, 3)`` positions (m).
        centers: ``(E, M, 3)`` ellipsoid centres (m).
        axes: ``(E, M, 3)`` semi-axes (m), already validated.
        headings: ``(E, M)`` headings (rad), unused.
        cos_h: ``(E, M)`` cosines of the headings.
        sin_h: ``(E, M)`` sines of the headings.
        active: ``(E, M)`` bool; inactive ellipsoids give ``inf``.
        n_newton: Newton iterations (the numpy form's).

    Returns:
        ``(E, N, M)`` signed distances (m).
    """
    del headings
    return _region_loop(points, centers, axes, cos_h, sin_h, active, n_newton)


def _region_loop(
    points: np.ndarray,
    centers: np.ndarray,
    axes: np.ndarray,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    active: np.ndarray,
    n_newton: int,
) -> np.ndarray:
    e, n, _ = points.shape
    out = np.empty((e, n, centers.shape[1]))
    fn = _pairs_parallel if _parallel(out.size) else _pairs_serial
    c = np.ascontiguousarray
    fn(c(points), c(centers), c(axes), c(cos_h), c(sin_h), c(active), n_newton, out)
    return out


# ---------------------------------------------------------------------------- separations
@numba.njit(inline="always", **_JIT)
def _sq3(a, b, c):  # noqa: ANN001, ANN202
    """Squared norm in the order numpy's ``einsum("...i,...i")`` adds (two SIMD lanes)."""
    return (a * a + c * c) + b * b


@numba.njit(inline="always", **_JIT)
def _dist3(a, b, c):  # noqa: ANN001, ANN202
    """Euclidean norm as numpy's ``sqrt(einsum("...i,...i"))``."""
    return math.sqrt(_sq3(a, b, c))


@numba.njit(inline="always", **_JIT)
def _gap(p, e, i, q, j):  # noqa: ANN001, ANN202
    """Distance from ``p[e, i]`` to ``q[e, j]`` (3-vectors), as :func:`_dist3`."""
    return _dist3(q[e, j, 0] - p[e, i, 0], q[e, j, 1] - p[e, i, 1], q[e, j, 2] - p[e, i, 2])


@numba.njit(inline="always", **_JIT)
def _separation_row(k, uav_pos, obs_pos, active, d_uav, d_obs):  # noqa: ANN001, ANN202
    n, m = uav_pos.shape[1], obs_pos.shape[1]
    e = k // n
    i = k % n
    best = np.inf
    for j in range(n):
        if j != i:
            best = min(best, _gap(uav_pos, e, i, uav_pos, j))
    d_uav[e, i] = best
    best = np.inf
    for j in range(m):
        if active[e, j]:
            best = min(best, _gap(uav_pos, e, i, obs_pos, j))
    d_obs[e, i] = best


@numba.njit(**_JIT)
def _separations_serial(uav_pos, obs_pos, active, d_uav, d_obs):  # noqa: ANN001, ANN202
    for k in range(d_uav.size):
        _separation_row(k, uav_pos, obs_pos, active, d_uav, d_obs)


@numba.njit(parallel=True, **_JIT)
def _separations_parallel(uav_pos, obs_pos, active, d_uav, d_obs):  # noqa: ANN001, ANN202
    for k in numba.prange(d_uav.size):
        _separation_row(k, uav_pos, obs_pos, active, d_uav, d_obs)


def separations(
    uav_pos: np.ndarray, obs_pos: np.ndarray, active: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled :meth:`uasep_env.world.World.separations`: nearest UAV and obstacle distances.

    Args:
        uav_pos: ``(E, N, 3)`` positions (m).
        obs_pos: ``(E, M, 3)`` obstacle positions (m).
        active: ``(E, M)`` bool, which obstacles count.

    Returns:
        ``(E, N)`` distance to the nearest other UAV and to the nearest active obstacle (m),
        ``inf`` where there is none.
    """
    e, n, _ = uav_pos.shape
    d_uav = np.empty((e, n))
    d_obs = np.empty((e, n))
    fn = _separations_parallel if _parallel(d_uav.size) else _separations_serial
    c = np.ascontiguousarray
    fn(c(uav_pos), c(obs_pos), c(active), d_uav, d_obs)
    return d_uav, d_obs


# ---------------------------------------------------------------------------- observations
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
def _norm3(a, b, c):  # noqa: ANN001, ANN202
    """Euclidean norm in the order ``np.linalg.norm(axis=-1)`` adds (left to right)."""
    return math.sqrt((a * a + b * b) + c * c)


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


# ---------------------------------------------------------------------------- rewards
@numba.njit(inline="always", **_JIT)
def _reward_agent(k, x, c, weights, own, terms):  # noqa: ANN001, ANN202
    """Agent ``k`` (flat over env and UAV) of :func:`uasep_env.rewards._weighted_terms`.

    ``x`` is the :class:`uasep_env.rewards._Inputs` named tuple, ``c`` the
    :class:`uasep_env.rewards._Constants` one. Terms in
    :data:`uasep_env.rewards.REWARD_TERMS` order.
    """
    n = x.uav_pos.shape[1]
    e = k // n
    i = k % n
    max_acc, d_sep, d_obs_sep = c.max_accel, c.separation_distance, c.obstacle_separation
    d_col, dev_scale = c.collision_distance, c.deviation_scale
    region_cap, max_steps = c.region_cap, c.max_steps
    d_uav, d_obs = x.min_uav_dist[e, i], x.min_obs_dist[e, i]
    d_region = np.inf
    for j in range(x.region.shape[2]):
        d_region = min(d_region, x.region[e, i, j])
    t = max(0.0, 1.0 - d_uav / d_sep)
    terms[0, e, i] = -(t * t)
    t = max(0.0, 1.0 - d_obs / d_obs_sep)
    terms[1, e, i] = -(t * t)
    terms[2, e, i] = -min(region_cap, max(0.0, 1.0 - d_region / d_obs_sep))
    dev = _norm3(
        x.uav_pos[e, i, 0] - x.plan_pos[e, i, 0],
        x.uav_pos[e, i, 1] - x.plan_pos[e, i, 1],
        x.uav_pos[e, i, 2] - x.plan_pos[e, i, 2],
    )
    terms[3, e, i] = -(dev / (dev + dev_scale))
    a0, a1, a2 = x.cmd[e, i, 0], x.cmd[e, i, 1], x.cmd[e, i, 2]
    u0, u1, u2 = a0 / max_acc, a1 / max_acc, a2 / max_acc
    terms[4, e, i] = -_sq3(u0, u1, u2) / 3.0
    u0 = (a0 - x.prev_cmd[e, i, 0]) / max_acc
    u1 = (a1 - x.prev_cmd[e, i, 1]) / max_acc
    u2 = (a2 - x.prev_cmd[e, i, 2]) / max_acc
    terms[5, e, i] = -_sq3(u0, u1, u2) / 3.0
    hit = False  # any UAV of the environment (the collision ends everyone's episode)
    for j in range(n):
        hit = hit or x.min_uav_dist[e, j] < d_col or x.min_obs_dist[e, j] < d_col
    terms[6, e, i] = -max_steps if hit else -0.0
    terms[7, e, i] = 1.0
    total = 0.0
    for t_idx in range(terms.shape[0]):
        total += weights[t_idx] * terms[t_idx, e, i]
    own[e, i] = total


@numba.njit(**_JIT)
def _rewards_serial(x, c, weights, own, terms):  # noqa: ANN001, ANN202
    for k in range(own.size):
        _reward_agent(k, x, c, weights, own, terms)


@numba.njit(parallel=True, **_JIT)
def _rewards_parallel(x, c, weights, own, terms):  # noqa: ANN001, ANN202
    for k in numba.prange(own.size):
        _reward_agent(k, x, c, weights, own, terms)


def reward_terms(
    inputs: tuple, constants: tuple, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled reward terms and their weighted sum (before any team sharing).

    Args:
        inputs: The :class:`uasep_env.rewards._Inputs` of one call.
        constants: The :class:`uasep_env.rewards._Constants` of one call.
        weights: One weight per term, in :data:`uasep_env.rewards.REWARD_TERMS` order.

    Returns:
        ``(own, terms)``: ``(E, N)`` weighted sums and ``(T, E, N)`` unweighted terms.
    """
    x = type(inputs)(*(np.ascontiguousarray(a) for a in inputs))
    e, n = x.min_uav_dist.shape
    own = np.empty((e, n))
    terms = np.empty((len(weights), e, n))
    fn = _rewards_parallel if _parallel(own.size) else _rewards_serial
    fn(x, constants, weights, own, terms)
    return own, terms


# ---------------------------------------------------------------------------- the plan
@numba.njit(**_JIT)
def _plan_rows(time, speed, length, cum, waypoints, direction, offsets, center, d_out, pos, vel):  # noqa: ANN001, ANN202
    for e in range(time.shape[0]):
        t = time[e]
        s = min(speed[e] * max(t, 0.0), length[e])
        # Segment index: how many inner way-points lie at or before s, at most the last.
        idx = 0
        for k in range(1, cum.shape[1] - 1):
            if cum[e, k] <= s:
                idx += 1
        idx = min(idx, direction.shape[1] - 1)
        along = s - cum[e, idx]
        moving = speed[e] * t < length[e]
        for a in range(3):
            d = direction[e, idx, a]
            c = waypoints[e, idx, a] + along * d
            v = speed[e] * d if moving else 0.0
            center[e, a] = c
            d_out[e, a] = d
            for i in range(pos.shape[1]):
                pos[e, i, a] = c + offsets[e, idx, i, a]
                vel[e, i, a] = v


def plan_now(
    plan: object, time: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.formation.planned_state`: the plan at ``time``.

    Args:
        plan: The :class:`uasep_env.formation.PlannedTrajectory` (its arrays are read).
        time: ``(E,)`` times (s).
        offsets: ``(E, W - 1, N, 3)`` slots rotated along each segment (m).

    Returns:
        ``(E, 3)`` planned centre (m) and direction, ``(E, N, 3)`` planned UAV positions (m)
        and velocities (m/s).
    """
    e, _, n, _ = offsets.shape
    center, d = np.empty((e, 3)), np.empty((e, 3))
    pos, vel = np.empty((e, n, 3)), np.empty((e, n, 3))
    _plan_rows(
        time, plan.cruise_speed, plan.length, plan.cum, plan.waypoints, plan.direction,
        offsets, center, d, pos, vel,
    )  # fmt: skip
    return center, d, pos, vel
