"""The reference minimum-area enclosing ellipse of a reachable set (slow; offline and tests).

:func:`optimal_shape` is what the shape table of :mod:`uasep_env.reachable.fit` holds, at its
grid nodes (``tools/build_reachable_table.py``), and what the tests compare the fit with.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from uasep_env.reachable.fit import _golden_max
from uasep_env.reachable.sets import FloatArray, _front_unit

__all__ = ["optimal_shape"]


def _boundary_points_unit(
    phi: FloatArray, kappa: FloatArray, swept: bool, m: int
) -> tuple[FloatArray, FloatArray]:
    """Boundary points (x >= 0 half) of the set scaled by ``v t + r``; ``kappa = r/(v t + r)``.

    Three runs of ``m`` points: the front curve (S2), the arc about ``F(phi)`` (S4) and, for
    the swept set with ``phi < pi``, the arc about the origin. Shapes ``(..., 3 m)``.
    """
    phi = phi[..., None]
    kap = kappa[..., None]
    lim = np.minimum(phi, np.pi)
    s = np.linspace(0.0, 1.0, m)
    a_front = lim * s
    end = np.where(swept & (phi < np.pi), 0.5 * (np.pi + phi), np.pi)
    a_corner = lim + (end - lim) * s
    a_origin = end + (np.pi - end) * s
    fx, fy = _front_unit(a_front, phi)
    cx, cy = _front_unit(np.broadcast_to(lim, a_corner.shape), phi)
    ox = np.where(swept & (phi < np.pi), 0.0, cx[..., -1:])
    oy = np.where(swept & (phi < np.pi), 0.0, cy[..., -1:])
    ox, oy = np.broadcast_to(ox, a_origin.shape), np.broadcast_to(oy, a_origin.shape)
    a = np.concatenate([a_front, a_corner, a_origin], axis=-1)
    x0 = np.concatenate([fx, cx, ox], axis=-1)
    y0 = np.concatenate([fy, cy, oy], axis=-1)
    x = (1.0 - kap) * x0 + kap * np.sin(a)
    y = (1.0 - kap) * y0 + kap * np.cos(a)
    return np.where(np.abs(x) < 1e-13, 0.0, x), y


def optimal_shape(
    phi: ArrayLike, kappa: ArrayLike, swept: bool, m: int = 160, iters: int = 48
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Reference minimum-area enclosing ellipse ``(c, A, B)`` of the set scaled by ``v t + r``.

    Slow, for building the shape table and for tests. For a fixed centre ``c`` the problem in
    ``(P, Q) = (1/A^2, 1/B^2)`` is concave (maximise ``log P + log Q`` subject to the linear
    constraints ``P x_k^2 + Q (y_k - c)^2 <= 1`` at sampled boundary points), solved by golden
    section on ``Q``; ``c`` is found by a scan plus golden section. Inner approximation: the
    result encloses the sampled points, not necessarily the whole set.

    Args:
        phi: ``w_max t`` (rad).
        kappa: ``r / (v t + r)`` in ``[0, 1]``.
        swept: Swept (True) or terminal (False) set.
        m: Points per boundary piece.
        iters: Golden-section iterations.

    Returns:
        ``(c, A, B)`` in units of ``v t + r``.
    """
    phi = np.asarray(phi, dtype=np.float64)
    kappa = np.asarray(kappa, dtype=np.float64)
    phi, kappa = np.broadcast_arrays(phi, kappa)
    x, y = _boundary_points_unit(phi, kappa, swept, m)
    x2 = x * x

    def inner(c: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        e = (y - c[..., None]) ** 2
        qmax = 1.0 / np.maximum(np.max(np.where(x2 == 0.0, e, 0.0), axis=-1), 1e-300)
        safe = np.where(x2 > 0.0, x2, 1.0)

        def p_of(q: FloatArray) -> FloatArray:
            val = np.where(x2 > 0.0, (1.0 - e * q[..., None]) / safe, np.inf)
            return np.min(val, axis=-1)

        def obj(tq: FloatArray) -> FloatArray:
            q = tq * qmax
            p = p_of(q)
            ok = (p > 0.0) & (q > 0.0)
            return np.where(
                ok, np.log(np.where(ok, p, 1.0)) + np.log(np.where(ok, q, 1.0)), -np.inf
            )

        tq = _golden_max(obj, np.zeros_like(c), np.ones_like(c), iters)
        q = tq * qmax
        return obj(tq), q, p_of(q)

    lo = np.min(y, axis=-1)
    hi = np.max(y, axis=-1)
    n_scan = 24
    cs = lo[..., None] + (hi - lo)[..., None] * (np.arange(1, n_scan) / n_scan)
    vals = np.stack([inner(cs[..., k])[0] for k in range(n_scan - 1)], axis=-1)
    k = np.argmax(vals, axis=-1)
    step = (hi - lo) / n_scan
    cbest = np.take_along_axis(cs, k[..., None], axis=-1)[..., 0]
    c = _golden_max(lambda cc: inner(cc)[0], cbest - step, cbest + step, iters)
    _, q, p = inner(c)
    return c, 1.0 / np.sqrt(p), 1.0 / np.sqrt(q)
