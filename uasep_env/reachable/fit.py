"""The heading-aligned ellipse and ellipsoid around a reachable set (eqs. 17-18).

``fit="enclosing"`` (the default) is certified to enclose the set and is steered towards the
minimum area by a shipped shape table (:mod:`uasep_env.reachable.shape_table`,
``data/ellipse_table.npz``, rebuilt by ``tools/build_reachable_table.py`` from
:mod:`uasep_env.reachable.optimal`); ``fit="paper"`` is eq. 17 as published. The certificate
(:mod:`uasep_env.reachable.certificate`) and the measured area factors are derived in
``docs/reachable_sets.md``. The fit's search, axes and certificate (arithmetic and square roots
only) have a compiled twin (``fit_ellipse``), so that the few rows of a partial reset cost
little.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env._numba import compiled_twin
from uasep_env.reachable.certificate import _axes_for, _certified, _margins, _Nodes
from uasep_env.reachable.sets import (
    FloatArray,
    Mode,
    _check_mode,
    _h_unit_of,
    _inv,
    _nonneg_all,
    _out,
    _unit_factors,
)
from uasep_env.reachable.shape_table import (  # noqa: F401 (_TAB: read from here too)
    _CORNERS,
    _TAB,
    _TAB_LOGR,
    _TAB_U,
    _interp_table,
)
from uasep_env.sim.obstacles import _EPS

__all__ = ["Fit", "ellipse", "ellipsoid"]

Fit = Literal["enclosing", "paper"]
_FITS = ("enclosing", "paper")

#: Intervals of the enclosure certificate on ``[0, pi]`` (even, so that pi/2 is a node).
_N_CERT = 96
#: Geometrically spaced parameter nodes at each end of the ellipse's axes.
_N_GEO = 14
#: Nodes uniform in the normal angle, merged with those uniform in the ellipse's parameter.
_UNIFORM_NODES = np.linspace(0.0, np.pi, 49)[1:-1]
_PARAMETRIC_NODES = np.linspace(0.0, np.pi, _N_CERT + 1)
_PARAMETRIC_SIN, _PARAMETRIC_COS = np.sin(_PARAMETRIC_NODES), np.cos(_PARAMETRIC_NODES)
_GEO_EXPONENTS = np.linspace(0.0, 1.0, _N_GEO)
#: Relative absolute margin (of ``v t + r``) that absorbs floating-point rounding.
_EPS_ABS = 1e-12
#: Half-width (fraction of the set's length) and iterations of the centre's polishing search.
_C_SEARCH = 0.02
_C_ITERS = 8


def _check_fit(fit: str) -> bool:
    """True for ``"paper"``, False for ``"enclosing"``; raises on anything else."""
    if fit not in _FITS:
        raise ValueError(f"fit must be 'enclosing' or 'paper', got {fit!r}")
    return fit == "paper"


# ---------------------------------------------------------------------------- search
def _golden_max(
    f: Callable[[FloatArray], FloatArray], lo: FloatArray, hi: FloatArray, iters: int
) -> FloatArray:
    """Vectorised golden-section search for the maximiser of a unimodal ``f`` on ``[lo, hi]``."""
    g = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    c1 = b - g * (b - a)
    c2 = a + g * (b - a)
    f1, f2 = f(c1), f(c2)
    for _ in range(iters):
        right = f1 < f2
        a = np.where(right, c1, a)
        b = np.where(right, b, c2)
        new = np.where(right, a + g * (b - a), b - g * (b - a))
        fn = f(new)
        c1, c2, f1, f2 = (
            np.where(right, c2, new),
            np.where(right, new, c1),
            np.where(right, f2, fn),
            np.where(right, fn, f1),
        )
    return 0.5 * (a + b)


# ---------------------------------------------------------------------------- ellipse fit
# The directions of the extents: ahead, behind, to the side.
_EXTENT_DIRECTIONS = np.array([0.0, np.pi, 0.5 * np.pi])


_EXTENT_SIN, _EXTENT_COS = np.sin(_EXTENT_DIRECTIONS), np.cos(_EXTENT_DIRECTIONS)


def _extents(
    vt: FloatArray, phi: FloatArray, r: FloatArray, swept: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The set's supports ahead (``0``), behind (``pi``) and to the side (``pi / 2``) (m)."""
    return _extents_of(vt, phi, r, *_unit_factors(phi), swept)


def _extents_of(
    vt: FloatArray,
    phi: FloatArray,
    r: FloatArray,
    ip: FloatArray,
    omc: FloatArray,
    sc: FloatArray,
    swept: bool,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`_extents` from :func:`_unit_factors` of ``phi`` (no trigonometry)."""
    unit = _h_unit_of(
        _EXTENT_DIRECTIONS,
        _EXTENT_SIN,
        _EXTENT_COS,
        phi[..., None],
        ip[..., None],
        omc[..., None],
        sc[..., None],
        swept,
    )
    h = r[..., None] + vt[..., None] * unit
    return h[..., 0], h[..., 1], h[..., 2]


def _fit_trigonometry(
    vt: FloatArray, phi: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The fit's start's transcendental functions that stay numpy's (not the C library's).

    numpy's ``arctan2`` and ``log10`` differ from the C library's in the last bit on some
    CPUs, so the compiled start takes them from here, as its reference does.

    Returns:
        ``arctan2(2 eps, phi)`` and ``log10(hypot(phi, 2 eps))``, whence the shape table's
        coordinates (``eps = r / (v t)``, 0 where it is not finite: the start takes the
        logarithm as ``inf`` there). The callers silence numpy's divide warnings.
    """
    eps = r / vt  # inf or NaN where v t = 0
    e2 = 2.0 * np.where(np.isfinite(eps), eps, 0.0)
    return np.arctan2(e2, phi), np.log10(np.hypot(phi, e2))


@compiled_twin(
    "ellipse_start",
    tab_u=(float(_TAB_U[0]), float(_TAB_U[1] - _TAB_U[0])),
    tab_logr=(float(_TAB_LOGR[0]), float(_TAB_LOGR[1] - _TAB_LOGR[0])),
    corners=(_CORNERS[True], _CORNERS[False]),
    directions=(_EXTENT_DIRECTIONS, _EXTENT_SIN, _EXTENT_COS),
    constants=(_EPS, _EPS_ABS, np.pi / _N_CERT, _C_SEARCH),
)
def _ellipse_start(
    vt: FloatArray,
    phi: FloatArray,
    r: FloatArray,
    atan: FloatArray,
    logr: FloatArray,
    swept: bool,
) -> tuple[FloatArray, ...]:
    """The fit's start from the table, and its nodes' spacing.

    Compiled as ``ellipse_start``; ``atan`` and ``logr`` come in (:func:`_fit_trigonometry`);
    its sines are the C library's, which numpy's are (the kernel declines where not).

    Returns:
        ``(c, B, A, half, eps_abs, A_g, B_g, t_lo, base, ip, omc, sc)``, each ``(R,)``: the
        table's centre and axes (m), the half-width of the centre's search (m), the
        rounding margin (m), the axes the nodes are spaced on (m), the smallest node
        spacing and the ratio of the largest to it, and :func:`_unit_factors` of ``phi``.
    """
    scale = vt + r
    pos = vt > 0.0
    finite = np.isfinite(np.where(pos, r / np.where(pos, vt, 1.0), np.inf))
    u = np.sqrt(np.where(finite, atan * (2.0 / np.pi), 1.0))
    ip = _inv(phi)
    omc = 2.0 * np.sin(0.5 * phi) ** 2 * ip
    y = np.pi * (phi / np.pi)
    y = np.where(y, y, _EPS)
    sc = np.sin(y) / y
    frac = _interp_table(swept, u, np.where(finite, logr, np.inf))
    h0, hpi, hx = _extents_of(vt, phi, r, ip, omc, sc, swept)
    ext = h0 + hpi
    c = frac[..., 0] * ext - hpi
    lon = frac[..., 1] * ext
    lat = frac[..., 2] * hx
    # Nodes: uniform in the parametric angle of the table's ellipse, merged with nodes uniform
    # in the normal angle, pi/2 and the kink of the swept set's support.
    # Near the ends of a thin ellipse the normal turns fast, so the parameter is also refined
    # geometrically towards 0, pi/2 and pi, down to a fifth of the aspect ratio.
    lat_g = np.maximum(lat, 1e-9 * scale)
    lon_g = np.maximum(lon, 1e-9 * scale)
    step = np.pi / _N_CERT
    t_lo = np.minimum(0.2 * np.minimum(lat_g, lon_g) / np.maximum(lat_g, lon_g), step)
    return (c, lon, lat, _C_SEARCH * ext, _EPS_ABS * scale, lat_g, lon_g, t_lo, step / t_lo,
            ip, omc, sc)  # fmt: skip


@compiled_twin("node_arguments", n_cert=_N_CERT, parametric=(_PARAMETRIC_SIN, _PARAMETRIC_COS))
def _node_arguments(
    t_lo: FloatArray, powers: FloatArray, lat: FloatArray, lon: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``arctan2``'s arguments for the normal angles of the table ellipse's nodes.

    The nodes are uniform in the ellipse's parameter ``t``, and geometric towards 0, pi/2
    and pi from ``t_lo``. Compiled as ``node_arguments`` (its sines and cosines are the C
    library's, which numpy's are; the kernel declines where not).

    Args:
        t_lo: ``(R,)`` the smallest geometric spacing.
        powers: ``(R, G)`` the spacings' ratios, ``base ** (0 .. 1)`` (numpy's power).
        lat: ``(R,)`` the lateral axis the nodes are spaced on (m).
        lon: ``(R,)`` the longitudinal one (m).

    Returns:
        ``(lon sin t, lat cos t)``, each ``(R, K)``.
    """
    geo = t_lo[..., None] * powers
    geo = np.concatenate([geo, 0.5 * np.pi - geo, 0.5 * np.pi + geo, np.pi - geo], axis=-1)
    # The parametric nodes' sines and cosines are the same every call: made once.
    shape = (*t_lo.shape, _N_CERT + 1)
    sin_t = np.concatenate([np.broadcast_to(_PARAMETRIC_SIN, shape), np.sin(geo)], axis=-1)
    cos_t = np.concatenate([np.broadcast_to(_PARAMETRIC_COS, shape), np.cos(geo)], axis=-1)
    return lon[..., None] * sin_t, lat[..., None] * cos_t


@compiled_twin("ellipse_nodes", n_cert=_N_CERT, uniform=_UNIFORM_NODES)
def _ellipse_nodes(
    th: FloatArray, phi: FloatArray, swept: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The certificate's nodes, ascending, with their cosines and sines.

    ``th``'s, those uniform in the normal angle, the kink of the swept set's support, and 0,
    pi/2 and pi exactly. Compiled as ``ellipse_nodes`` (its cosines and sines are the C
    library's, which numpy's are; the kernel declines where not).

    Args:
        th: ``(R, K)`` the normal angles of the table ellipse's parametric nodes.
        phi: ``(R,)`` the largest turn (rad).
        swept: The swept set (else the terminal one).

    Returns:
        ``(nodes, cos, sin)``, each ``(R, K + 48)``.
    """
    kink = np.where(swept & (phi < np.pi), 0.5 * (np.pi + phi), 0.5 * np.pi)
    uni = np.broadcast_to(_UNIFORM_NODES, (*th.shape[:-1], _UNIFORM_NODES.size))
    out = np.concatenate([th, uni, kink[..., None]], axis=-1)
    out[..., 0] = 0.0
    out[..., _N_CERT // 2] = 0.5 * np.pi
    out[..., _N_CERT] = np.pi
    nodes = np.sort(out, axis=-1)
    return nodes, np.cos(nodes), np.sin(nodes)


@compiled_twin("fit_ellipse", golden_iters=_C_ITERS)
def _fit_certified(
    th: FloatArray,
    cos: FloatArray,
    sin: FloatArray,
    vt: FloatArray,
    phi: FloatArray,
    ip: FloatArray,
    omc: FloatArray,
    sc: FloatArray,
    r: FloatArray,
    c: FloatArray,
    half: FloatArray,
    lat: FloatArray,
    lon: FloatArray,
    eps_abs: FloatArray,
    swept: bool,
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """The nodes' support, the centre polished, the axes fitted, and the certificate.

    Arithmetic and square roots only (the sines and cosines come in), compiled as
    ``fit_ellipse``: here, a handful of rows (a partial reset's) costs a few hundred small
    numpy calls.

    Args:
        th: ``(R, K)`` the certificate nodes, ascending in ``[0, pi]``.
        cos: ``(R, K)`` their cosines.
        sin: ``(R, K)`` their sines.
        vt: ``(R,)`` the distance flown ``v t`` (m).
        phi: ``(R,)`` the largest turn ``w t`` (rad).
        ip: ``(R,)`` ``1 / phi`` (0 for a straight line), as :func:`_unit_factors`.
        omc: ``(R,)`` ``(1 - cos phi) / phi``.
        sc: ``(R,)`` ``sin(phi) / phi``.
        r: ``(R,)`` the radius (m).
        c: ``(R,)`` the table's centre (m).
        half: ``(R,)`` the half-width of the centre's search (m).
        lat: ``(R,)`` the table's lateral axis, at least a tiny fraction of the scale (m).
        lon: ``(R,)`` the table's longitudinal axis (m).
        eps_abs: ``(R,)`` the rounding margin (m).
        swept: The swept set (else the terminal one).

    Returns:
        ``(c, A, B, certified)``, each ``(R,)``.
    """
    nd = _Nodes(th, vt, phi, r, swept, cos, sin, (ip, omc, sc))
    lat_g = lat
    # The margins depend on (A, B): fit twice, taking the margins at the previous axes with a
    # 25% allowance, then certify; rows that still fail grow until they pass (the caller).
    delta = 1.25 * _margins(nd, lat_g, lon, r, eps_abs)

    # Polish the centre by a short golden-section search on the area (margins held fixed).
    def neg_area(cc: FloatArray) -> FloatArray:
        a_, b_ = _axes_for(nd, delta, cc, lon)
        return -(a_ * b_)

    c = _golden_max(neg_area, c - half, c + half, _C_ITERS)
    for _ in range(2):  # the margins at the previous axes, plus 25%; B only grows
        margins = 1.25 * _margins(nd, np.maximum(lat, 1e-3 * lat_g), lon, r, eps_abs)
        lat, lon = _axes_for(nd, margins, c, lon)
    return c, lat, lon, _certified(nd, c, lat, lon, r, eps_abs)


def _ellipse_core(
    vt: FloatArray, phi: FloatArray, r: FloatArray, swept: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Certified near-minimal ellipse ``(c, A, B)`` for flat arrays of parameters."""
    # The callers (ellipse, ellipsoid) silence numpy's divide and invalid warnings.
    scale = vt + r
    live = scale > 0.0
    atan, logr = _fit_trigonometry(vt, phi, r)
    c, lon, lat, half, eps_abs, lat_g, lon_g, t_lo, base, ip, omc, sc = _ellipse_start(
        vt, phi, r, atan, logr, swept
    )
    # numpy's power and arctangent between the compiled stages (not the C library's).
    y, x = _node_arguments(t_lo, base[..., None] ** _GEO_EXPONENTS, lat_g, lon_g)
    th, cos, sin = _ellipse_nodes(np.arctan2(y, x), phi, swept)
    c, lat, lon, ok = _fit_certified(
        th, cos, sin, vt, phi, ip, omc, sc, r, c, half, lat_g, lon, eps_abs, swept
    )
    ok |= ~live
    grow = 1e-6
    nd = None
    for _ in range(30):
        if ok.all():
            break
        if nd is None:  # rare: the nodes in numpy, for the rows that grow
            nd = _Nodes(th, vt, phi, r, swept, cos, sin, (ip, omc, sc))
        bad = np.flatnonzero(~ok)
        lat[bad] *= 1.0 + grow
        lon[bad] *= 1.0 + grow
        ok[bad] = _certified(nd.take(bad), c[bad], lat[bad], lon[bad], r[bad], eps_abs[bad])
        grow *= 8.0
    # The circle of radius v t + r about the obstacle holds everything within reach; use it
    # if the certificate never passed, or if it is smaller (sets that are nearly discs).
    fallback = ~ok | (lat * lon > scale * scale)
    # Exact special cases: a disc (v t = 0, includes a point) and a segment (phi = 0, r = 0).
    disc = vt <= 0.0
    seg = (phi <= 0.0) & (r <= 0.0) & ~disc
    if not (fallback | disc | seg).any():  # the usual case, in a dozen calls fewer
        return c, lat, lon
    c = np.where(fallback, 0.0, c)
    lat = np.where(fallback, scale, lat)
    lon = np.where(fallback, scale, lon)
    c = np.where(disc, 0.0, np.where(seg, 0.5 * vt, c))
    lat = np.where(disc, r, np.where(seg, 0.0, lat))
    lon = np.where(disc, r, np.where(seg, 0.5 * vt, lon))
    return c, lat, lon


def _paper_core(
    vt: FloatArray, phi: FloatArray, r: FloatArray, swept: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The paper's ellipse (eq. 17) ``(c, A, B)``: the set's extents, not an enclosure.

    Major axis ``a`` = the lateral extent between S3 and S4 (twice the support at
    ``theta = pi/2``), minor axis ``b`` = the extent along the heading from S5 to the tip of
    S1,2 (the supports at ``0`` and ``pi``). Eq. 17 writes ``x = a cos alpha``,
    ``y = b sin alpha``, but the text defines ``a`` and ``b`` as the *lengths* of the axes;
    taken as semi-axes the ellipse would be twice the size of the set in both directions, so
    the semi-axes are ``a / 2`` and ``b / 2``, centred on the middle of the extents (the
    ellipse inscribed in the set's bounding box, Figure 3). The extents are those of the
    corrected set (S3/S4 centred on ``F(+-phi)``, the erratum of eqs. 13-14), read off its
    support function.
    """
    h0, hpi, hx = _extents(vt, phi, r, swept)
    return 0.5 * (h0 - hpi), hx, 0.5 * (h0 + hpi)


def ellipse(
    speed: ArrayLike,
    max_turn_rate: ArrayLike,
    horizon: ArrayLike,
    radius: ArrayLike,
    mode: Mode = "swept",
    fit: Fit = "enclosing",
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Heading-aligned ellipse around the reachable set plus the radius.

    ``fit="enclosing"`` (default) provably encloses the set and replaces the paper's eq. 17.
    See ``docs/reachable_sets.md`` for the enclosure certificate and the measured area factors
    (median 1.0004, at most 1.007 / 1.03 times the minimum enclosing ellipse for the swept /
    terminal set). ``fit="paper"`` is eq. 17 as published (axes = the set's extents, see
    :func:`_paper_core`): it does **not** enclose the set; it misses the set's "shoulders"
    between the axes. At the paper's example (terminal set, ``w_max = 0.013``, ``v = 4``,
    ``t = 10``, ``r = 3``) boundary points lie up to 0.51 m outside it and it misses 10 % of
    the set's area; with ``w_max = 0.1``, ``v = 8``, up to 5.5 m and 13 %
    (``tests/test_reachable.py::test_paper_fit_misses_the_shoulders``).

    Args:
        speed: Horizontal speed ``v`` (m/s).
        max_turn_rate: ``w_max`` (rad/s); 0 (straight flight) is allowed.
        horizon: Prediction horizon ``t`` (s).
        radius: Safety radius ``r`` (m).
        mode: ``"swept"`` (reachable at any time in ``[0, t]``, default) or ``"terminal"``
            (the S1..S5 region, reachable at exactly ``t``).
        fit: ``"enclosing"`` (default) or ``"paper"`` (eq. 17 as published, not enclosing).

    Returns:
        ``(center_offset, lateral_semi_axis, longitudinal_semi_axis)`` (m), broadcast shape:
        the centre lies ``center_offset`` ahead of the obstacle along its heading.

    Raises:
        ValueError: On a negative/non-finite parameter, an unknown mode or an unknown fit.
    """
    swept = _check_mode(mode)
    core = _paper_core if _check_fit(fit) else _ellipse_core
    v, w, t, r = _nonneg_all(
        speed=speed, max_turn_rate=max_turn_rate, horizon=horizon, radius=radius
    )
    v, w, t, r = np.broadcast_arrays(v, w, t, r)
    shape = v.shape
    vt = (v * t).ravel()
    phi = (w * t).ravel()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c, lat, lon = core(vt, phi, r.ravel().astype(np.float64), swept)
    return _out(c.reshape(shape)), _out(lat.reshape(shape)), _out(lon.reshape(shape))


def _spread(a: FloatArray, shape: tuple[int, ...]) -> FloatArray:
    """``a`` broadcast to ``shape``, flat (a view where it has that shape already)."""
    return (a if a.shape == shape else np.broadcast_to(a, shape)).ravel()


def ellipsoid(
    speed: ArrayLike,
    max_turn_rate: ArrayLike,
    max_climb_rate: ArrayLike,
    horizon: ArrayLike,
    radius: ArrayLike,
    mode: Mode = "swept",
    fit: Fit = "enclosing",
) -> tuple[FloatArray, FloatArray]:
    """Heading-aligned ellipsoid around the 3D reachable set (eq. 18).

    Horizontal Dubins motion as in :func:`ellipse`, vertical speed ``|v_z| <= vz_max``,
    everything inflated by a ball of radius ``r``.

    ``fit="enclosing"`` (default, eq. 18 fixed, provably enclosing): semi-axes are
    ``sqrt(3/2)`` times the enclosing 2D ellipse's and ``sqrt(3) (vz_max t + r)`` vertically
    (the least-volume ellipsoid of that family containing the cylinder "2D ellipse x
    vertical extent"); the flat 2D ellipse when ``vz_max t + r = 0``.

    ``fit="paper"`` (as published, not enclosing): the paper's 2D ellipse (axis lengths
    ``a`` lateral, ``b`` along the heading, see :func:`ellipse`) and, as the text says, a
    circular section of diameter ``a`` across the heading: the vertical semi-axis is
    ``a / 2``, whatever ``vz_max``. The printed eq. 18 (vertical semi-axis ``b``)
    contradicts that sentence (notes); the text is followed.

    Args:
        speed: Horizontal speed ``v`` (m/s).
        max_turn_rate: ``w_max`` (rad/s).
        max_climb_rate: ``vz_max`` (m/s).
        horizon: Prediction horizon ``t`` (s).
        radius: Safety radius ``r`` (m).
        mode: ``"swept"`` (default) or ``"terminal"``.
        fit: ``"enclosing"`` (default) or ``"paper"`` (as published, not enclosing).

    Returns:
        ``(center_offset, semi_axes)``: the offset ahead of the obstacle along its heading
        (m, broadcast shape) and the semi-axes ``(..., 3)`` ordered (longitudinal, lateral,
        vertical) (m).

    Raises:
        ValueError: On a negative/non-finite parameter, an unknown mode or an unknown fit.
    """
    swept = _check_mode(mode)
    paper = _check_fit(fit)
    v, w, vz, t, r = _nonneg_all(
        speed=speed,
        max_turn_rate=max_turn_rate,
        max_climb_rate=max_climb_rate,
        horizon=horizon,
        radius=radius,
    )
    # The products broadcast, and are spread to the common shape only where they lack it
    # (np.broadcast_arrays of five arrays cost a tenth of a partial reset's fit).
    vt, phi, z = v * t, w * t, vz * t + r
    shape = np.broadcast(vt, phi, z).shape
    vt, phi, z, r = (_spread(a, shape) for a in (vt, phi, z, r))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c, lat, lon = (_paper_core if paper else _ellipse_core)(vt, phi, r, swept)
    axes = np.empty((c.size, 3))
    if paper:
        axes[:, 0], axes[:, 1], axes[:, 2] = lon, lat, lat
        return _out(c.reshape(shape)), axes.reshape((*shape, 3))
    lam = np.where(z <= 0.0, 1.0, np.sqrt(1.5))
    axes[:, 0] = lam * lon
    axes[:, 1] = lam * lat
    axes[:, 2] = np.sqrt(3.0) * z
    return _out(c.reshape(shape)), axes.reshape((*shape, 3))
