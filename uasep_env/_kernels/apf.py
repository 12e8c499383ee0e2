"""The paper's APF decision: :func:`uasep_env.policies.apf._apf_actions`, one UAV at a time.

The observation vector decoded as ``ObservationLayout.decode`` does (its columns from
``decode_columns``), then the attraction (eqs. 19-22), the obstacle repulsion with its entry
prediction (eqs. 23-25), the inner repulsion (eqs. 26-30) and the bounds (eq. 4), in the
numpy form's order. The regions' headings come in as numpy's cosines and sines of numpy's
``arctan2`` (the numpy form's), and every 3-vector dot product adds as numpy's ``einsum``
does (:func:`_dot3`).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _maximum, frozen
from uasep_env._kernels.ellipsoids import _WORK, _converge, _finished, _nearest_one, _store

#: The features the APF reads, in the order of the kernel's column and scale arrays.
_KEYS = (
    "goal_offset",
    "slot_offset",
    "plan_velocity",
    "velocity",
    "formation_velocity",
    "uav_rel_pos",
    "uav_rel_vel",
    "uav_mask",
    "obstacle_center",
    "obstacle_axes",
    "obstacle_heading_cs",
    "obstacle_mask",
)
#: The gains the kernel reads, in the order of its gain array.
_GAINS = (
    "k_goal",
    "goal_saturation",
    "k_slot",
    "k_vel",
    "k_damp",
    "k_obstacle",
    "obstacle_safe_min",
    "obstacle_time",
    "alpha",
    "beta",
    "inner_safe_min",
    "k_safe",
    "max_repulsion",
)


# Positions in those arrays, by name (numba reads module integers as constants).
_GOAL = _KEYS.index("goal_offset")
_SLOT = _KEYS.index("slot_offset")
_PLAN_VEL = _KEYS.index("plan_velocity")
_VEL = _KEYS.index("velocity")
_FORMATION_VEL = _KEYS.index("formation_velocity")
_UAV_POS = _KEYS.index("uav_rel_pos")
_UAV_VEL = _KEYS.index("uav_rel_vel")
_UAV_MASK = _KEYS.index("uav_mask")
_CENTER = _KEYS.index("obstacle_center")
_AXES = _KEYS.index("obstacle_axes")
_OBSTACLE_MASK = _KEYS.index("obstacle_mask")
_K_GOAL = _GAINS.index("k_goal")
_GOAL_SAT = _GAINS.index("goal_saturation")
_K_SLOT = _GAINS.index("k_slot")
_K_VEL = _GAINS.index("k_vel")
_K_DAMP = _GAINS.index("k_damp")
_K_OBSTACLE = _GAINS.index("k_obstacle")
_OBSTACLE_SAFE_MIN = _GAINS.index("obstacle_safe_min")
_OBSTACLE_TIME = _GAINS.index("obstacle_time")
_ALPHA = _GAINS.index("alpha")
_BETA = _GAINS.index("beta")
_INNER_SAFE_MIN = _GAINS.index("inner_safe_min")
_K_SAFE = _GAINS.index("k_safe")
_MAX_REPULSION = _GAINS.index("max_repulsion")


@numba.njit(inline="always", **_JIT)
def _max0(y):  # noqa: ANN001, ANN202
    """``np.maximum(0.0, y)``: NaN stays NaN."""
    return 0.0 if y <= 0.0 else y


@numba.njit(inline="always", **_JIT)
def _dot3(a0, a1, a2, b0, b1, b2):  # noqa: ANN001, ANN202
    """``einsum("...i,...i")`` of two 3-vectors, in the order numpy adds (two SIMD lanes)."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@numba.njit(inline="always", **_JIT)
def _capped(f0, f1, f2, cap):  # noqa: ANN001, ANN202
    """``apf._cap_norm`` of one vector."""
    s = cap / _maximum(math.sqrt(_dot3(f0, f1, f2, f0, f1, f2)), 1e-12)
    if not s < 1.0:  # np.minimum(1.0, s): NaN stays NaN
        s = 1.0 if s >= 1.0 else s
    return f0 * s, f1 * s, f2 * s


@numba.njit(inline="always", **_JIT)
def _summed(k, t0, t1, t2, f0, f1, f2):  # noqa: ANN001, ANN202
    """The sum over the neighbours as ``sum(axis=-2)`` adds: the first force, then each next."""
    if k == 0:
        return f0, f1, f2
    return t0 + f0, t1 + f1, t2 + f2


@numba.njit(**_JIT)
def _read3(obs, b, col, k, stride, scale):  # noqa: ANN001, ANN202
    """A decoded 3-vector feature (neighbour ``k``'s in its block)."""
    c = col + k * stride
    return obs[b, c] * scale, obs[b, c + 1] * scale, obs[b, c + 2] * scale


@numba.njit(**_JIT)
def _will_enter(v0, v1, v2, c0, c1, c2, a0, a1, a2, cp, sp, times, safe_min, n_newton):  # noqa: ANN001, ANN202
    """Whether the straight-line flight comes within ``safe_min`` of the region.

    The least distance over the sampled times, NaN if any is (``np.min``), below
    ``safe_min``.
    """
    least = np.inf
    for s in range(times.shape[0]):
        t = times[s]
        e0 = v0 * t - c0
        e1 = v1 * t - c1
        e2 = v2 * t - c2
        q0 = e0 * cp + e1 * sp
        q1 = -e0 * sp + e1 * cp
        dist = _nearest_one(q0, q1, e2, a0, a1, a2, n_newton)[3]
        if dist != dist:
            return False
        if s == 0 or dist < least:
            least = dist
    return least < safe_min


@numba.njit(inline="always", **_JIT)
def _region(obs, b, k, cols, scales, stride, cos_h, sin_h):  # noqa: ANN001, ANN202
    """Region ``k`` of row ``b``, and the UAV (at the origin) in its body frame.

    ``(c0, c1, c2, a0, a1, a2, cp, sp, q0, q1, q2)``: the centre, the semi-axes (at least
    1 mm), the heading's cosine and sine, the UAV's offset.
    """
    c0, c1, c2 = _read3(obs, b, cols[_CENTER], k, stride, scales[_CENTER])
    a0, a1, a2 = _read3(obs, b, cols[_AXES], k, stride, scales[_AXES])
    a0, a1, a2 = _maximum(a0, 1e-3), _maximum(a1, 1e-3), _maximum(a2, 1e-3)
    cp, sp = cos_h[b, k], sin_h[b, k]
    d0, d1, d2 = 0.0 - c0, 0.0 - c1, 0.0 - c2
    q0 = d0 * cp + d1 * sp
    q1 = -d0 * sp + d1 * cp
    return c0, c1, c2, a0, a1, a2, cp, sp, q0, q1, d2


@numba.njit(**_JIT)
def _solve_regions(obs, cols, scales, n_obs, stride, cos_h, sin_h, n_newton, work, live):  # noqa: ANN001, ANN202
    """Every row's solve against each region, converged in one sweep.

    ``work[b * n_obs + k]`` is row ``b``'s against region ``k`` (:func:`~.ellipsoids._store`,
    :func:`~.ellipsoids._converge`); :func:`_obstacles` finishes it as
    :func:`_nearest_one` would, bit for bit.
    """
    k = 0
    for b in range(obs.shape[0]):
        for j in range(n_obs):
            _, _, _, a0, a1, a2, _, _, q0, q1, q2 = _region(obs, b, j, cols, scales, stride,
                                                             cos_h, sin_h)  # fmt: skip
            _store(work, k, q0, q1, q2, a0, a1, a2)
            k += 1
    _converge(work, live, 0, k, n_newton)


@numba.njit(**_JIT)
def _obstacles(obs, b, cols, scales, n_obs, stride, cos_h, sin_h, v, vh, speed, g, times, n_newton, work):  # noqa: ANN001, ANN202, E501  # fmt: skip
    """The obstacle repulsion of row ``b`` (eqs. 23-25), summed over the obstacles."""
    t0 = t1 = t2 = 0.0
    for k in range(n_obs):
        c0, c1, c2, a0, a1, a2, cp, sp, q0, q1, q2 = _region(obs, b, k, cols, scales, stride,
                                                             cos_h, sin_h)  # fmt: skip
        present = obs[b, cols[_OBSTACLE_MASK] + k * stride] * scales[_OBSTACLE_MASK] > 0.5
        # The UAV at the origin: its distance to the region and the outward normal.
        _, _, _, dist, m0, m1, m2 = _finished(work, b * n_obs + k)
        # The signs _nearest_one puts back, as it does (a product, not a negation).
        m0 = m0 * (-1.0 if q0 < 0.0 else 1.0)
        m1 = m1 * (-1.0 if q1 < 0.0 else 1.0)
        m2 = m2 * (-1.0 if q2 < 0.0 else 1.0)
        n0 = m0 * cp - m1 * sp
        n1 = m0 * sp + m1 * cp
        n2 = m2
        cos_delta = _dot3(-n0, -n1, -n2, vh[0], vh[1], vh[2])
        approach = speed * cos_delta if cos_delta > 0.0 else 0.0
        r_safe = g[_OBSTACLE_SAFE_MIN] + g[_OBSTACLE_TIME] * approach
        dd = _maximum(dist, 0.5)
        active = present and dist < r_safe
        if active:
            active = _will_enter(v[0], v[1], v[2], c0, c1, c2, a0, a1, a2, cp, sp, times,
                                 g[_OBSTACLE_SAFE_MIN], n_newton)  # fmt: skip
        mag = g[_K_OBSTACLE] * (1.0 / dd - 1.0 / r_safe) if active else 0.0
        f0, f1, f2 = _capped(mag * n0, mag * n1, mag * n2, g[_MAX_REPULSION])
        t0, t1, t2 = _summed(k, t0, t1, t2, f0, f1, f2)
    return t0, t1, t2


@numba.njit(**_JIT)
def _inner(obs, b, cols, scales, n_uav, stride, g):  # noqa: ANN001, ANN202
    """The inner repulsion of row ``b`` (eqs. 26-30), summed over the neighbours."""
    t0 = t1 = t2 = 0.0
    for k in range(n_uav):
        r0, r1, r2 = _read3(obs, b, cols[_UAV_POS], k, stride, scales[_UAV_POS])
        w0, w1, w2 = _read3(obs, b, cols[_UAV_VEL], k, stride, scales[_UAV_VEL])
        present = obs[b, cols[_UAV_MASK] + k * stride] * scales[_UAV_MASK] > 0.5
        r0, r1, r2 = -r0, -r1, -r2  # from the neighbour towards this UAV
        d = math.sqrt(_dot3(r0, r1, r2, r0, r1, r2))
        inv = _maximum(d, 1e-9)
        u0, u1, u2 = r0 / inv, r1 / inv, r2 / inv
        closing = _max0(_dot3(w0, w1, w2, u0, u1, u2))
        r_inner = 2.0 * g[_INNER_SAFE_MIN] + g[_K_SAFE] * closing
        dd = _maximum(d, 0.1)
        mag = 1.0 / dd - 1.0 / r_inner if (d < r_inner and present) else 0.0
        if not closing > 0.0:
            w0 = w1 = w2 = 0.0
        f0, f1, f2 = _capped(
            mag * (g[_ALPHA] * u0 + g[_BETA] * w0),
            mag * (g[_ALPHA] * u1 + g[_BETA] * w1),
            mag * (g[_ALPHA] * u2 + g[_BETA] * w2),
            g[_MAX_REPULSION],
        )
        t0, t1, t2 = _summed(k, t0, t1, t2, f0, f1, f2)
    return t0, t1, t2


@numba.njit(**_JIT)
def _clip1(x):  # noqa: ANN001, ANN202
    """``np.clip(x, -1, 1)`` (NaN stays NaN)."""
    if x < -1.0:
        return -1.0
    if x > 1.0:
        return 1.0
    return x


@numba.njit(**_JIT)
def _apf_rows(
    obs: np.ndarray,
    cols: np.ndarray,
    scales: np.ndarray,
    n_uav: int,
    uav_stride: int,
    n_obs: int,
    obs_stride: int,
    cos_h: np.ndarray,
    sin_h: np.ndarray,
    g: np.ndarray,
    times: np.ndarray,
    n_newton: int,
    max_speed: float,
    max_accel: float,
    dt: float,
    v: np.ndarray,
    vh: np.ndarray,
    work: np.ndarray,
    live: np.ndarray,
    out: np.ndarray,
) -> None:
    _solve_regions(obs, cols, scales, n_obs, obs_stride, cos_h, sin_h, n_newton, work, live)
    for b in range(obs.shape[0]):
        # Eqs. 19-22 (policies.nominal.plan_tracking).
        x0, x1, x2 = _read3(obs, b, cols[_GOAL], 0, 0, scales[_GOAL])
        x0, x1, x2 = _capped(x0, x1, x2, g[_GOAL_SAT])
        s0, s1, s2 = _read3(obs, b, cols[_SLOT], 0, 0, scales[_SLOT])
        p0, p1, p2 = _read3(obs, b, cols[_PLAN_VEL], 0, 0, scales[_PLAN_VEL])
        v[0], v[1], v[2] = _read3(obs, b, cols[_VEL], 0, 0, scales[_VEL])
        f0, f1, f2 = _read3(obs, b, cols[_FORMATION_VEL], 0, 0, scales[_FORMATION_VEL])
        kg, ks, kv, kd = g[_K_GOAL], g[_K_SLOT], g[_K_VEL], g[_K_DAMP]
        a0 = ((kg * x0 + ks * s0) + kv * (p0 - v[0])) - kd * (v[0] - f0)
        a1 = ((kg * x1 + ks * s1) + kv * (p1 - v[1])) - kd * (v[1] - f1)
        a2 = ((kg * x2 + ks * s2) + kv * (p2 - v[2])) - kd * (v[2] - f2)
        speed = math.sqrt(_dot3(v[0], v[1], v[2], v[0], v[1], v[2]))
        den = _maximum(speed, 1e-9)
        vh[0], vh[1], vh[2] = v[0] / den, v[1] / den, v[2] / den
        o0, o1, o2 = _obstacles(obs, b, cols, scales, n_obs, obs_stride, cos_h, sin_h, v, vh,
                                speed, g, times, n_newton, work)  # fmt: skip
        i0, i1, i2 = _inner(obs, b, cols, scales, n_uav, uav_stride, g)
        a0, a1, a2 = (a0 + o0) + i0, (a1 + o1) + i1, (a2 + o2) + i2
        # Eq. 4 and the acceleration bound (policies.nominal.bounded_action).
        along = _dot3(a0, a1, a2, vh[0], vh[1], vh[2])
        limit = (max_speed - speed) / dt
        excess = _max0(along - _maximum(limit, 0.0))
        out[b, 0] = _clip1((a0 - excess * vh[0]) / max_accel)
        out[b, 1] = _clip1((a1 - excess * vh[1]) / max_accel)
        out[b, 2] = _clip1((a2 - excess * vh[2]) / max_accel)


# What depends only on the layout or the gains, made once for each (both are frozen
# dataclasses): a decision batch at one environment is a few dozen microseconds.
@functools.lru_cache(maxsize=32)
def _columns(layout: object) -> tuple:
    """The layout as the kernel reads it.

    The columns and scales of :data:`_KEYS`, the neighbour counts and strides, and the
    regions' heading columns with their scale.
    """
    where = layout.decode_columns()  # type: ignore[attr-defined]
    cols = frozen(np.array([where[k][0] for k in _KEYS], dtype=np.int64))
    scales = frozen(np.array([where[k][2] for k in _KEYS]))
    _, _, _, uav_stride, n_uav = where["uav_mask"]
    _, _, _, obs_stride, n_obs = where["obstacle_mask"]
    cs_cols, cs_scale = layout.feature_columns("obstacle_heading_cs")  # type: ignore[attr-defined]
    return cols, scales, n_uav, uav_stride, n_obs, obs_stride, cs_cols, cs_scale


@functools.lru_cache(maxsize=32)
def _gains(gains: object) -> np.ndarray:
    """The gains of :data:`_GAINS`, in order."""
    return frozen(np.array([getattr(gains, k) for k in _GAINS]))


def apf_actions(
    observations: np.ndarray,
    layout: object,
    gains: object,
    max_speed: float,
    max_accel: float,
    dt: float,
    *,
    samples: np.ndarray,
    n_newton: int,
) -> np.ndarray:
    """Compiled :func:`uasep_env.policies.apf._apf_actions`: normalised actions ``(..., 3)``.

    In float64 (the caller casts to float32), checked by the caller (the width, the
    regions' semi-axes).

    Args:
        observations: ``(..., dim)`` observations of ``layout``.
        layout: Their :class:`~uasep_env.interface.observation.ObservationLayout`.
        gains: The :class:`~uasep_env.policies.apf.APFGains`.
        max_speed: ``V_max`` (m/s).
        max_accel: The per-axis bound (m/s^2).
        dt: The step duration (s).
        samples: The fractions of the horizon the entry prediction checks.
        n_newton: Newton iterations of the distance solve.
    """
    obs = np.asarray(observations)
    dim = layout.dim  # type: ignore[attr-defined]
    cols, scales, n_uav, uav_stride, n_obs, obs_stride, cs_cols, cs_scale = _columns(layout)
    lead = obs.shape[:-1]
    flat = np.ascontiguousarray(obs.reshape(-1, dim), dtype=np.float64)
    # The regions' headings: numpy's arctan2, then numpy's cosines and sines (the numpy
    # form's distance solve).
    cs = flat[:, cs_cols] * cs_scale
    heading = np.arctan2(cs[..., 1], cs[..., 0])
    times = samples * gains.horizon  # type: ignore[attr-defined]
    out = np.empty((flat.shape[0], 3))
    scratch = np.empty((2, 3))  # the velocity and its direction
    work = np.empty((flat.shape[0] * n_obs, _WORK))  # each region's solve
    live = np.empty(flat.shape[0] * n_obs, dtype=np.int64)
    _apf_rows(frozen(flat), cols, scales, n_uav, uav_stride, n_obs, obs_stride,
              frozen(np.cos(heading)), frozen(np.sin(heading)), _gains(gains), frozen(times),
              n_newton, float(max_speed), float(max_accel), float(dt), scratch[0], scratch[1],
              work, live, out)  # fmt: skip
    return out.reshape(*lead, 3)
