"""The enclosing ellipse's start, nodes, search and fit (:mod:`uasep_env.reachable.fit`).

:func:`ellipse_start` (``_ellipse_start``), :func:`node_arguments` (``_node_arguments``),
:func:`ellipse_nodes` (``_ellipse_nodes``) and :func:`fit_ellipse` (``_fit_certified``).
Arithmetic, square roots, and sines and cosines: the C library's, which numpy's are
(``common.sin_cos_agree``, checked once; where they are not, the three kernels that take
them decline). The arctangents, logarithms and powers come in, numpy's (they are not the C
library's on every CPU).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels import common
from uasep_env._kernels.common import _JIT, _maximum, _minimum, frozen


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


@numba.njit(inline="always", **_JIT)
def _h_unit(a, sa, ca, phi, ip, omc, sc, swept):  # noqa: ANN001, ANN202
    """``sets._h_unit_of`` in one direction ``a``, in its order.

    ``reach`` where ``a`` can be reached, else the corner's (at least 0 for the swept set).
    """
    if a <= phi:
        return 1.0 - (a - sa) * ip
    unit = sa * omc + ca * sc
    return _maximum(unit, 0.0) if swept else unit


@numba.njit(**_JIT)
def _nodes_row(th, sn, cs, vt, phi, ip, omc, sc, r, swept, c2, s2, d2, h):  # noqa: ANN001, ANN202
    """One row of ``_Nodes``: squared cosines and sines, squared spacings over 8, support.

    The support is ``sets._h_unit_of``'s (:func:`_h_unit`).
    """
    k = th.shape[0]
    for j in range(k):
        a, sa, ca = th[j], sn[j], cs[j]
        c2[j] = ca * ca
        s2[j] = sa * sa
        h[j] = r + vt * _h_unit(a, sa, ca, phi, ip, omc, sc, swept)
        if j + 1 < k:
            d = th[j + 1] - a
            d2[j] = d * d / 8.0


@numba.njit(**_JIT)
def _fit_rows(
    inputs: tuple[np.ndarray, ...],
    swept: bool,
    iters: int,
    c_out: np.ndarray,
    lat_out: np.ndarray,
    lon_out: np.ndarray,
    ok_out: np.ndarray,
    scratch: np.ndarray,
) -> None:
    """Every row of :func:`fit_ellipse` (its fourteen arrays, ``inputs``) into the outputs."""
    th, cos, sin, vt, phi, ip, omc, sc, r, c0, half, lat0, lon0, eps_abs = inputs
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
    inputs = (th, cos, sin, vt, phi, ip, omc, sc, r, c, half, lat, lon, eps_abs)
    _fit_rows(tuple(frozen(np.asarray(a, dtype=np.float64)) for a in inputs), bool(swept),
              golden_iters, c_out, lat_out, lon_out, ok, scratch)  # fmt: skip
    return c_out, lat_out, lon_out, ok


@numba.njit(**_JIT)
def _start_rows(  # noqa: ANN202
    vt, phi, r, atan, logr, swept,  # noqa: ANN001
    u0, du, l0, dl, corners, dirs, dsin, dcos, tiny_y, eps_rel, step, c_search,  # noqa: ANN001
    out,  # noqa: ANN001
):  # fmt: skip
    """Every row of ``_ellipse_start`` into ``out`` ``(12, R)``, in its order."""
    na, nl = corners.shape[0] + 1, corners.shape[1] + 1
    for i in range(vt.shape[0]):
        v, p, rr = vt[i], phi[i], r[i]
        scale = v + rr
        eps = rr / v if v > 0.0 else math.inf
        u = math.sqrt(atan[i] * (2.0 / math.pi) if math.isfinite(eps) else 1.0)
        ip = 1.0 / p if p > 1e-200 else 0.0
        hs = math.sin(0.5 * p)
        omc = 2.0 * (hs * hs) * ip
        y = math.pi * (p / math.pi)
        y = y if y != 0.0 else tiny_y
        sc = math.sin(y) / y
        # The shape table, interpolated in its cell (np.clip: NaN stays NaN).
        lr = logr[i] if math.isfinite(eps) else math.inf
        fa = _minimum(_maximum((u - u0) / du, 0.0), na - 1.0)
        fl = _minimum(_maximum((lr - l0) / dl, 0.0), nl - 1.0)
        if fl != fl:
            fl = 0.0
        i0 = min(int(fa), na - 2)
        j0 = min(int(fl), nl - 2)
        ta, tl = fa - i0, fl - j0
        ua, ul = 1 - ta, 1 - tl
        k = corners[i0, j0]
        f0 = k[0, 0] * ua * ul + k[1, 0] * ta * ul + k[2, 0] * ua * tl + k[3, 0] * ta * tl
        f1 = k[0, 1] * ua * ul + k[1, 1] * ta * ul + k[2, 1] * ua * tl + k[3, 1] * ta * tl
        f2 = k[0, 2] * ua * ul + k[1, 2] * ta * ul + k[2, 2] * ua * tl + k[3, 2] * ta * tl
        # The set's supports ahead, behind and to the side.
        h0 = rr + v * _h_unit(dirs[0], dsin[0], dcos[0], p, ip, omc, sc, swept)
        hpi = rr + v * _h_unit(dirs[1], dsin[1], dcos[1], p, ip, omc, sc, swept)
        hx = rr + v * _h_unit(dirs[2], dsin[2], dcos[2], p, ip, omc, sc, swept)
        ext = h0 + hpi
        lat = f2 * hx
        lon = f1 * ext
        lat_g = _maximum(lat, 1e-9 * scale)
        lon_g = _maximum(lon, 1e-9 * scale)
        t_lo = _minimum(0.2 * _minimum(lat_g, lon_g) / _maximum(lat_g, lon_g), step)
        out[0, i] = f0 * ext - hpi
        out[1, i] = lon
        out[2, i] = lat
        out[3, i] = c_search * ext
        out[4, i] = eps_rel * scale
        out[5, i] = lat_g
        out[6, i] = lon_g
        out[7, i] = t_lo
        out[8, i] = step / t_lo
        out[9, i] = ip
        out[10, i] = omc
        out[11, i] = sc


def ellipse_start(
    vt: np.ndarray,
    phi: np.ndarray,
    r: np.ndarray,
    atan: np.ndarray,
    logr: np.ndarray,
    swept: bool,
    *,
    tab_u: tuple[float, float],
    tab_logr: tuple[float, float],
    corners: tuple[np.ndarray, np.ndarray],
    directions: tuple[np.ndarray, np.ndarray, np.ndarray],
    constants: tuple[float, float, float, float],
) -> tuple[np.ndarray, ...]:
    """Compiled :func:`uasep_env.reachable.fit._ellipse_start`: twelve ``(R,)`` arrays.

    Declines (``NotImplemented``) where numpy's sines are not the C library's.

    ``tab_u``, ``tab_logr``: the shape table's first node and spacing on each axis;
    ``corners``: its cells' corners (swept, terminal); ``directions``: the extents'
    directions with their sines and cosines; ``constants``: ``sinc``'s guard for 0, the
    relative rounding margin, the nodes' largest spacing and the centre search's half-width.
    """
    if not common.sin_cos_agree():
        return NotImplemented
    out = np.empty((12, vt.shape[0]))
    inputs = (vt, phi, r, atan, logr)
    _start_rows(*(frozen(np.asarray(a, dtype=np.float64)) for a in inputs), bool(swept),
                *tab_u, *tab_logr, corners[0] if swept else corners[1], *directions,
                *constants, out)  # fmt: skip
    return tuple(out)


@numba.njit(inline="always", **_JIT)
def _before(a, b):  # noqa: ANN001, ANN202
    """``a`` sorts before ``b`` as in ``np.sort`` (NaN last)."""
    return a < b or (b != b and a == a)


@numba.njit(**_JIT)
def _nodes_rows(th, phi, swept, n_cert, uniform, out, cos, sin, tmp):  # noqa: ANN001, ANN202
    """Each row of ``_ellipse_nodes``: the nodes gathered, three set exactly, then sorted.

    Sorted by runs of 16 put in order by insertion, then merged pairwise through ``tmp``
    (equal values are equal bits here, so any sort gives ``np.sort``'s row); then their
    cosines and sines.
    """
    k, n_uni = th.shape[1], uniform.shape[0]
    size = out.shape[1]
    for i in range(th.shape[0]):
        row = out[i]
        for j in range(k):
            row[j] = th[i, j]
        for j in range(n_uni):
            row[k + j] = uniform[j]
        p = phi[i]
        row[size - 1] = 0.5 * (math.pi + p) if (swept and p < math.pi) else 0.5 * math.pi
        row[0] = 0.0
        row[n_cert // 2] = 0.5 * math.pi
        row[n_cert] = math.pi
        for lo in range(0, size, 16):
            for j in range(lo + 1, min(lo + 16, size)):
                x = row[j]
                m = j
                while _before(x, row[m - 1]):
                    row[m] = row[m - 1]
                    m -= 1
                    if m == lo:
                        break
                row[m] = x
        width = 16
        src, dst = row, tmp
        flips = 0
        while True:
            if width >= size:
                break
            for lo in range(0, size, 2 * width):
                mid, hi = min(lo + width, size), min(lo + 2 * width, size)
                a, b = lo, mid
                for m in range(lo, hi):
                    if b >= hi or (a < mid and not _before(src[b], src[a])):
                        dst[m] = src[a]
                        a += 1
                    else:
                        dst[m] = src[b]
                        b += 1
            src, dst = dst, src
            width *= 2
            flips += 1
        if flips % 2:  # the sorted row is in tmp
            for j in range(size):
                row[j] = tmp[j]
        for j in range(size):
            cos[i, j] = math.cos(row[j])
            sin[i, j] = math.sin(row[j])


def ellipse_nodes(
    th: np.ndarray, phi: np.ndarray, swept: bool, *, n_cert: int, uniform: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.reachable.fit._ellipse_nodes`: ``(nodes, cos, sin)``.

    Each ``(R, K + 48)``, the nodes ascending. Declines (``NotImplemented``) where numpy's
    cosines and sines are not the C library's.
    """
    if not common.sin_cos_agree():
        return NotImplemented
    shape = (th.shape[0], th.shape[1] + uniform.shape[0] + 1)
    out, cos, sin = np.empty(shape), np.empty(shape), np.empty(shape)
    _nodes_rows(frozen(th), frozen(phi), bool(swept), n_cert, frozen(uniform), out, cos, sin,
                np.empty(shape[1]))  # fmt: skip
    return out, cos, sin


@numba.njit(**_JIT)
def _arguments_rows(t_lo, powers, lat, lon, psin, pcos, y, x):  # noqa: ANN001, ANN202
    """Each row of ``_node_arguments`` into ``y``, ``x``.

    The parametric nodes, then the geometric ones towards 0, pi/2 (from below and above)
    and pi.
    """
    n_par, n_geo = psin.shape[0], powers.shape[1]
    half_pi = 0.5 * math.pi
    for i in range(t_lo.shape[0]):
        a, b = lon[i], lat[i]
        for j in range(n_par):
            y[i, j] = a * psin[j]
            x[i, j] = b * pcos[j]
        for g in range(n_geo):
            t = t_lo[i] * powers[i, g]
            for q in range(4):
                if q == 0:
                    angle = t
                elif q == 1:
                    angle = half_pi - t
                elif q == 2:
                    angle = half_pi + t
                else:
                    angle = math.pi - t
                j = n_par + q * n_geo + g
                y[i, j] = a * math.sin(angle)
                x[i, j] = b * math.cos(angle)


def node_arguments(
    t_lo: np.ndarray,
    powers: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    *,
    n_cert: int,
    parametric: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.reachable.fit._node_arguments`: ``(y, x)``, each ``(R, K)``.

    ``parametric``: the sines and cosines of the ``n_cert + 1`` nodes uniform in the
    ellipse's parameter. Declines (``NotImplemented``) where numpy's sines and cosines are
    not the C library's.
    """
    if not common.sin_cos_agree():
        return NotImplemented
    shape = (t_lo.shape[0], n_cert + 1 + 4 * powers.shape[1])
    y, x = np.empty(shape), np.empty(shape)
    _arguments_rows(frozen(t_lo), frozen(powers), frozen(lat), frozen(lon),
                    frozen(parametric[0]), frozen(parametric[1]), y, x)  # fmt: skip
    return y, x
