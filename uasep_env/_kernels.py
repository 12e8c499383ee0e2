"""Compiled (numba) forms of the hot numerical kernels; imported only when numba is in use.

Each kernel is the scalar, per-point transcription of a numpy function elsewhere in the
package and returns the same numbers bit for bit (``tests/test_kernels.py`` checks it): the
same operations in the same order, no ``fastmath``. The numpy forms stay the reference and
the fallback when numba is missing (see :mod:`uasep_env._numba`).

* :func:`nearest_on_ellipsoids` -- :func:`uasep_env.reachable._nearest_body` with the
  heading rotation of :func:`uasep_env.reachable.distance_to_ellipsoid` around it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env import _numba

_N_NEWTON = 8  # must equal uasep_env.reachable._N_NEWTON (checked by the tests)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _nearest_one(q0, q1, q2, a0, a1, a2, n_newton, out):  # noqa: ANN001, ANN202
    """Nearest point of one ellipsoid (body frame); writes x(3), dist, normal(3) to ``out``."""
    qv = (q0, q1, q2)
    av = (a0, a1, a2)
    sg = np.empty(3)
    qa = np.empty(3)
    for i in range(3):
        sg[i] = -1.0 if qv[i] < 0.0 else 1.0
        qa[i] = abs(qv[i])
    scale = max(max(a0, a1, a2), max(qa[0], qa[1], qa[2]))
    if not scale > 0.0:
        scale = 1.0
    qs = np.empty(3)
    a = np.empty(3)
    for i in range(3):
        qs[i] = qa[i] / scale
        a[i] = av[i] / scale
    m = 0
    for i in range(1, 3):
        if a[i] < a[m]:
            m = i
    am = a[m]
    off = np.empty(3)
    cq = np.empty(3)
    for i in range(3):
        off[i] = a[i] * a[i] - am * am
        cq[i] = a[i] * qs[i]
    sig = max(cq[0] - a[0] * a[0] + am * am, cq[1] - a[1] * a[1] + am * am)
    sig = max(sig, cq[2] - a[2] * a[2] + am * am)
    amax = max(a[0], a[1], a[2])
    sig = max(sig, math.sqrt(cq[0] * cq[0] + cq[1] * cq[1] + cq[2] * cq[2]) - amax**2 + am**2)
    sig_lo = max(sig, 0.0)
    rr = 0.0
    for i in range(3):
        if a[i] > 0.0:
            ratio = qs[i] / a[i]
        elif qs[i] > 0.0:
            ratio = np.inf
        else:
            ratio = 0.0
        rr = rr + ratio * ratio if i else ratio * ratio
    level = math.sqrt(rr)
    guess = am * am * (level if math.isfinite(level) else 0.0) if am > 0.0 else 0.0
    sig = max(sig_lo, guess)
    w = np.empty(3)
    w2 = np.empty(3)
    w2s = np.empty(3)
    for _ in range(n_newton):
        for i in range(3):
            s = sig + off[i]
            if s > 0.0:
                w[i] = cq[i] / s
                w2[i] = w[i] * w[i]
                w2s[i] = w2[i] / s
            else:
                w[i] = 0.0
                w2[i] = 0.0
                w2s[i] = 0.0
        f2 = w2[0] + w2[1] + w2[2]
        g = w2s[0] + w2s[1] + w2s[2]
        f2r = f2 - w2[m]
        gr = g - w2s[m]
        f = math.sqrt(f2)
        fr = math.sqrt(max(f2r, 0.0))
        step = f2 * (f - 1.0) / g if g > 0.0 else 0.0
        step_r = f2r * (fr - 1.0) / gr if (gr > 0.0 and fr > 1.0) else -np.inf
        sig = max(sig_lo, sig + max(step, step_r))
    for i in range(3):
        s = sig + off[i]
        w[i] = cq[i] / s if s > 0.0 else 0.0
    w[m] = 0.0
    rest = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
    shrink = 1.0 / math.sqrt(max(rest, 1.0)) if rest > 1.0 else 1.0
    for i in range(3):
        w[i] = w[i] * shrink
    w[m] = math.sqrt(max(1.0 - rest, 0.0))
    x = np.empty(3)
    ng = np.empty(3)
    diff = np.empty(3)
    for i in range(3):
        x[i] = a[i] * w[i]
        ng[i] = w[i] * am / a[i] if a[i] > 0.0 else 0.0
        diff[i] = qs[i] - x[i]
    if am <= 0.0:
        ng[m] = 1.0 if rest < 1.0 else 0.0
    dist = math.sqrt(diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2])
    inside = level < 1.0
    ngn = math.sqrt(ng[0] * ng[0] + ng[1] * ng[1] + ng[2] * ng[2])
    dirn = np.empty(3)
    if (inside or dist <= 1e-12) and ngn > 0.0:
        for i in range(3):
            dirn[i] = ng[i] / ngn
    else:
        den = dist if dist > 0.0 else 1.0
        for i in range(3):
            dirn[i] = diff[i] / den
    dn = math.sqrt(dirn[0] * dirn[0] + dirn[1] * dirn[1] + dirn[2] * dirn[2])
    if not dn > 0.0:
        for i in range(3):
            dirn[i] = 1.0 if i == m else 0.0
    for i in range(3):
        out[i] = x[i] * scale * sg[i]
        out[4 + i] = dirn[i] * sg[i]
    out[3] = (-dist if inside else dist) * scale


def _loop(points, centers, axes, cos_h, sin_h, n_newton, x_out, d_out, n_out):  # noqa: ANN001, ANN202
    """Every point of a flat batch: rotate into the body frame, solve, rotate back."""
    for k in numba.prange(points.shape[0]):
        buf = np.empty(7)
        cp = cos_h[k]
        sp = sin_h[k]
        d0 = points[k, 0] - centers[k, 0]
        d1 = points[k, 1] - centers[k, 1]
        d2 = points[k, 2] - centers[k, 2]
        q0 = d0 * cp + d1 * sp
        q1 = -d0 * sp + d1 * cp
        _nearest_one(q0, q1, d2, axes[k, 0], axes[k, 1], axes[k, 2], n_newton, buf)
        d_out[k] = buf[3]
        x_out[k, 0] = buf[0] * cp - buf[1] * sp
        x_out[k, 1] = buf[0] * sp + buf[1] * cp
        x_out[k, 2] = buf[2]
        n_out[k, 0] = buf[4] * cp - buf[5] * sp
        n_out[k, 1] = buf[4] * sp + buf[5] * cp
        n_out[k, 2] = buf[6]


_serial = numba.njit(cache=True, nogil=True, error_model="numpy")(_loop)
_parallel = _numba.jit(parallel=True)
_parallel_loop = _parallel(_loop) if _parallel is not None else _serial
#: Points per call above which the loop is spread over the cores (thread start-up costs).
PARALLEL_MIN = 2048


def nearest_on_ellipsoids(
    points: np.ndarray, centers: np.ndarray, axes: np.ndarray, headings: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest surface points (body-frame offsets rotated to NED), signed distances, normals.

    Args:
        points: ``(K, 3)`` float64 positions (m).
        centers: ``(K, 3)`` ellipsoid centres (m).
        axes: ``(K, 3)`` semi-axes (m), already validated.
        headings: ``(K,)`` headings (rad).

    Returns:
        ``(offset, distance, normal)``: ``(K, 3)`` nearest point minus the centre, NED (m);
        ``(K,)`` signed distance (m); ``(K, 3)`` unit outward normal, NED.
    """
    k = points.shape[0]
    x = np.empty((k, 3))
    d = np.empty(k)
    n = np.empty((k, 3))
    fn = _parallel_loop if k >= PARALLEL_MIN else _serial
    # numpy's cos/sin, not libm's: the rotation must match the numpy form to the last bit.
    fn(points, centers, axes, np.cos(headings), np.sin(headings), _N_NEWTON, x, d, n)
    return x, d, n
