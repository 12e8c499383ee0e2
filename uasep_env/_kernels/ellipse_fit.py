"""The enclosing ellipse's search and fit: :func:`uasep_env.reachable.fit._fit_certified`.

Only arithmetic and square roots (no trigonometry: the nodes' sines and cosines come in),
so the numbers are numpy's on any CPU.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _maximum, frozen


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
def _nodes_row(th, sn, cs, vt, phi, ip, omc, sc, r, swept, c2, s2, d2, h):  # noqa: ANN001, ANN202
    """One row of ``_Nodes``: squared cosines and sines, squared spacings over 8, support.

    The support is ``sets._h_unit_of``'s, in its order: ``reach`` where the direction can be
    reached, else the corner's (at least 0 for the swept set).
    """
    k = th.shape[0]
    for j in range(k):
        a, sa, ca = th[j], sn[j], cs[j]
        c2[j] = ca * ca
        s2[j] = sa * sa
        if a <= phi:
            unit = 1.0 - (a - sa) * ip
        else:
            unit = sa * omc + ca * sc
            if swept:
                unit = _maximum(unit, 0.0)
        h[j] = r + vt * unit
        if j + 1 < k:
            d = th[j + 1] - a
            d2[j] = d * d / 8.0


@numba.njit(**_JIT)
def _fit_rows(
    th: np.ndarray,
    sin: np.ndarray,
    cos: np.ndarray,
    vt: np.ndarray,
    phi: np.ndarray,
    ip: np.ndarray,
    omc: np.ndarray,
    sc: np.ndarray,
    r: np.ndarray,
    c0: np.ndarray,
    half: np.ndarray,
    lat0: np.ndarray,
    lon0: np.ndarray,
    eps_abs: np.ndarray,
    swept: bool,
    iters: int,
    c_out: np.ndarray,
    lat_out: np.ndarray,
    lon_out: np.ndarray,
    ok_out: np.ndarray,
    scratch: np.ndarray,
) -> None:
    k = cos.shape[1]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c2i, s2i, d2i, hi, rho, delta = (
        scratch[0], scratch[1], scratch[2, : k - 1], scratch[3], scratch[4], scratch[5]
    )  # fmt: skip
    for i in range(cos.shape[0]):
        ci = cos[i]
        ri, ei, lat_g, lon = r[i], eps_abs[i], lat0[i], lon0[i]
        _nodes_row(th[i], sin[i], ci, vt[i], phi[i], ip[i], omc[i], sc[i], ri, swept,
                   c2i, s2i, d2i, hi)  # fmt: skip
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
    th: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    vt: np.ndarray,
    phi: np.ndarray,
    ip: np.ndarray,
    omc: np.ndarray,
    sc: np.ndarray,
    r: np.ndarray,
    c: np.ndarray,
    half: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    eps_abs: np.ndarray,
    swept: bool,
    *,
    golden_iters: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.reachable.fit._fit_certified`: ``(c, A, B, certified)``.

    Args:
        th: ``(R, K)`` the certificate nodes, ascending.
        cos: ``(R, K)`` their cosines.
        sin: ``(R, K)`` their sines.
        vt: ``(R,)`` the distance flown (m).
        phi: ``(R,)`` the largest turn (rad).
        ip: ``(R,)`` ``1 / phi`` (0 for a straight line).
        omc: ``(R,)`` ``(1 - cos phi) / phi``.
        sc: ``(R,)`` ``sin(phi) / phi``.
        r: ``(R,)`` the radius (m).
        c: ``(R,)`` the start centre (m).
        half: ``(R,)`` the half-width of its search (m).
        lat: ``(R,)`` the start lateral axis (m).
        lon: ``(R,)`` the start longitudinal axis (m).
        eps_abs: ``(R,)`` the rounding margin (m).
        swept: The swept set (else the terminal one).
        golden_iters: Iterations of the centre's search.
    """
    rows = cos.shape[0]
    c_out, lat_out, lon_out = np.empty(rows), np.empty(rows), np.empty(rows)
    ok = np.empty(rows, dtype=np.bool_)
    # One row's squared cosines, squared sines, spacings, support, and the margins' rho and
    # delta.
    scratch = np.empty((6, cos.shape[1]))
    inputs = (th, sin, cos, vt, phi, ip, omc, sc, r, c, half, lat, lon, eps_abs)
    _fit_rows(*(frozen(np.asarray(a, dtype=np.float64)) for a in inputs), bool(swept),
              golden_iters, c_out, lat_out, lon_out, ok, scratch)  # fmt: skip
    return c_out, lat_out, lon_out, ok
