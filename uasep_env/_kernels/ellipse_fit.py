"""The enclosing ellipse's search and fit: :func:`uasep_env.reachable.fit._fit_certified`.

Only arithmetic and square roots (no trigonometry: the nodes' sines and cosines come in),
so the numbers are numpy's on any CPU. ``_maximum`` is ``np.maximum``'s scalar rule (``x``
unless ``y`` is larger, NaN if either is).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, frozen


@numba.njit(inline="always", **_JIT)
def _maximum(x, y):  # noqa: ANN001, ANN202
    return x if (x >= y or x != x) else y


@numba.njit(**_JIT)
def _margins_row(c2, s2, d2, lat, lon, r, eps, rho, out):  # noqa: ANN001, ANN202
    """``_margins`` of one row into ``out`` (``rho``: scratch of the same length)."""
    k = c2.shape[0]
    a2 = lat * lat
    b2 = lon * lon
    ab = a2 * b2
    for j in range(k):
        den = a2 * s2[j]
        den = den + b2 * c2[j]
        den = _maximum(den, 1e-300)
        rho[j] = ab / (math.sqrt(den) * den)
    prev = 0.0
    for j in range(k - 1):
        m = _maximum(rho[j + 1], rho[j]) - r
        m = _maximum(m, 0.0) * d2[j]
        if j == 0:
            out[0] = m + eps
        else:
            out[j] = _maximum(m, prev) + eps
        prev = m
    out[k - 1] = prev + eps


@numba.njit(**_JIT)
def _axes_row(cos, c2, s2, h, delta, c, lon):  # noqa: ANN001, ANN202
    """``_axes_for`` of one row: ``(A, B)``."""
    k = h.shape[0]
    b = _maximum(lon, (h[0] + delta[0]) - c)
    b = _maximum(b, (h[k - 1] + delta[k - 1]) + c)
    bb = b * b
    most = 0.0
    for j in range(1, k - 1):
        need = (h[j] - c * cos[j]) + delta[j]
        need = _maximum(need, 0.0)
        need = need * need
        need = need - bb * c2[j]
        need = need * (1.0 / s2[j])
        most = need if j == 1 else _maximum(most, need)
    return math.sqrt(_maximum(most, 0.0)), b


@numba.njit(**_JIT)
def _fit_rows(
    cos: np.ndarray,
    c2: np.ndarray,
    s2: np.ndarray,
    d2: np.ndarray,
    h: np.ndarray,
    c0: np.ndarray,
    half: np.ndarray,
    lat0: np.ndarray,
    lon0: np.ndarray,
    r: np.ndarray,
    eps_abs: np.ndarray,
    iters: int,
    c_out: np.ndarray,
    lat_out: np.ndarray,
    lon_out: np.ndarray,
    ok_out: np.ndarray,
    rho: np.ndarray,
    delta: np.ndarray,
) -> None:
    k = cos.shape[1]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    for i in range(cos.shape[0]):
        ci, c2i, s2i, d2i, hi = cos[i], c2[i], s2[i], d2[i], h[i]
        ri, ei, lat_g, lon = r[i], eps_abs[i], lat0[i], lon0[i]
        # The centre: golden-section search on the area, margins at the start's axes.
        _margins_row(c2i, s2i, d2i, lat_g, lon, ri, ei, rho, delta)
        for j in range(k):
            delta[j] = 1.25 * delta[j]
        a = c0[i] - half[i]
        b = c0[i] + half[i]
        p1 = b - g * (b - a)
        p2 = a + g * (b - a)
        x, y = _axes_row(ci, c2i, s2i, hi, delta, p1, lon)
        f1 = -(x * y)
        x, y = _axes_row(ci, c2i, s2i, hi, delta, p2, lon)
        f2 = -(x * y)
        for _ in range(iters):
            right = f1 < f2
            if right:
                a = p1
                new = a + g * (b - a)
            else:
                b = p2
                new = b - g * (b - a)
            x, y = _axes_row(ci, c2i, s2i, hi, delta, new, lon)
            fn = -(x * y)
            if right:
                p1, p2, f1, f2 = p2, new, f2, fn
            else:
                p1, p2, f1, f2 = new, p1, fn, f1
        c = 0.5 * (a + b)
        # The axes, twice, each with the margins of the previous ones plus 25 %.
        lat = lat_g
        for _ in range(2):
            _margins_row(c2i, s2i, d2i, _maximum(lat, 1e-3 * lat_g), lon, ri, ei, rho, delta)
            for j in range(k):
                delta[j] = 1.25 * delta[j]
            lat, lon = _axes_row(ci, c2i, s2i, hi, delta, c, lon)
        # The certificate.
        _margins_row(c2i, s2i, d2i, lat, lon, ri, ei, rho, delta)
        ok = True
        for j in range(k):
            he = c * ci[j] + math.sqrt(lat * lat * s2i[j] + lon * lon * c2i[j])
            if not he - hi[j] >= delta[j]:
                ok = False
        c_out[i], lat_out[i], lon_out[i], ok_out[i] = c, lat, lon, ok


def fit_ellipse(
    cos: np.ndarray,
    c2: np.ndarray,
    s2: np.ndarray,
    d2: np.ndarray,
    h: np.ndarray,
    c: np.ndarray,
    half: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    r: np.ndarray,
    eps_abs: np.ndarray,
    *,
    golden_iters: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.reachable.fit._fit_certified`: ``(c, A, B, certified)``.

    Args:
        cos: ``(R, K)`` the certificate nodes' cosines.
        c2: ``(R, K)`` their squares.
        s2: ``(R, K)`` the squared sines.
        d2: ``(R, K - 1)`` the squared node spacings over 8.
        h: ``(R, K)`` the set's support at the nodes (m).
        c: ``(R,)`` the start centre (m).
        half: ``(R,)`` the half-width of its search (m).
        lat: ``(R,)`` the start lateral axis (m).
        lon: ``(R,)`` the start longitudinal axis (m).
        r: ``(R,)`` the radius (m).
        eps_abs: ``(R,)`` the rounding margin (m).
        golden_iters: Iterations of the centre's search.
    """
    rows = cos.shape[0]
    c_out, lat_out, lon_out = np.empty(rows), np.empty(rows), np.empty(rows)
    ok = np.empty(rows, dtype=np.bool_)
    scratch = np.empty((2, cos.shape[1]))  # the margins' rho and delta of one row
    inputs = (cos, c2, s2, d2, h, c, half, lat, lon, r, eps_abs)
    _fit_rows(*(frozen(np.asarray(a, dtype=np.float64)) for a in inputs), golden_iters,
              c_out, lat_out, lon_out, ok, scratch[0], scratch[1])  # fmt: skip
    return c_out, lat_out, lon_out, ok
