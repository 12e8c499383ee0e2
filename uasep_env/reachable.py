"""Reachable sets of non-cooperative obstacles and the ellipses/ellipsoids that enclose them.

Paper section 3.1 (eqs. 8-18) with the errata of ``notes.md`` ("Obstacle reachable set").
Units: metres, seconds, radians, m/s throughout.

Model (eq. 8)
    The obstacle is a Dubins car: constant horizontal speed ``v``, turn rate in
    ``[-w_max, w_max]``; in 3D also a climb rate ``|v_z| <= vz_max`` independent of the
    horizontal motion. A safety radius ``r`` is added around every reachable position.

Paper frame (2D functions of this module)
    Obstacle at the origin heading ``+y``, ``x`` lateral (to the right). Directions are given
    by ``theta`` measured from the heading axis: ``u(theta) = (sin theta, cos theta)``.
    ``rho = v / w_max`` (minimum turning radius), ``phi = w_max t``.

Front curve (r = 0), a full-rate turn through ``theta`` followed by a straight leg::

    F(theta) = ( sgn(theta) rho (1 - cos theta) + (v t - rho |theta|) sin theta,
                 rho sin|theta| + (v t - rho |theta|) cos theta ),   |theta| <= min(phi, pi).

``F(theta)`` is the point of the reachable set at time ``t`` that is extreme in direction
``u(theta)`` (a turn as fast as possible to heading ``theta``, then straight, maximises
``v int cos(psi(s) - theta) ds`` because ``|psi(s)| <= w_max s``).  It is evaluated as
``v t`` times functions of ``theta`` and ``theta / phi`` only, so ``w_max -> 0`` (``rho``
infinite) is exact and stable.

Terminal set S1..S5 (eqs. 9-16), positions reachable at exactly ``t``, inflated by ``r``
    * S1 (eq. 9, ``-min(phi, pi) <= theta <= 0``, eq. 11) and S2 (eq. 10,
      ``0 <= theta <= min(phi, pi)``, eq. 12): ``F(theta) + r u(theta)``.
    * S3 (eq. 13, ``-pi <= theta <= -phi``, eq. 15) and S4 (eq. 14, ``phi <= theta <= pi``,
      eq. 16): arcs of radius ``r`` centred on ``F(-phi)`` and ``F(phi)``.
      **Erratum:** the paper centres them on ``S1(-phi)`` / ``S2(phi)``, which already contain
      ``r``; as printed the region misses reachable points by about ``r`` (3 m at the paper's
      example). For ``phi >= pi`` S3 and S4 vanish.
    * S5: the chord closing the region at ``y = F_y(+-min(phi, pi)) - r`` (``= rho sin(phi) - r``
      for ``phi <= pi``).

    The region is exactly ``conv(reachable set at t) (+) disc(r)``; its support function is
    ``h_T(theta) = r + v t - rho (|theta| - sin|theta|)`` for ``|theta| <= phi`` and
    ``h_T(theta) = r + rho (sin|theta| + sin(phi - |theta|))`` (support of the corner
    ``F(+-phi)``) for ``phi < |theta| <= pi`` (``|theta|`` wrapped to ``[0, pi]``).

Swept set (the project's default)
    Every position reachable at *any* time in ``[0, t]``, inflated by ``r``. Its convex hull is
    ``conv({0}, front curve) (+) disc(r)`` with support ``h_S(theta) = r + max(0, h_T(theta) - r)``:
    for ``|theta| <= phi`` the terminal support grows with the time, and beyond ``phi`` the
    terminal support ``rho (sin a + sin(w tau - a))`` is convex in ``tau`` on ``[0, t]`` so its
    maximum is at ``tau = 0`` (the origin) or ``tau = t``. For ``phi < pi`` the hull has a
    straight edge from the origin to ``F(+-phi)`` (normal at ``|theta| = (pi + phi) / 2``).

Enclosing ellipse (replaces the paper's eq. 17, which does not enclose)
    Heading-aligned, centred on the heading axis ``center_offset`` metres ahead of the obstacle,
    with lateral semi-axis ``A`` and longitudinal semi-axis ``B``; its support is
    ``h_E(theta) = c cos theta + sqrt(A^2 sin^2 theta + B^2 cos^2 theta)``.  The minimum-area
    enclosing ellipse of a set symmetric about the heading axis belongs to this family, so the
    family loses nothing. ``(c, B)`` come from a table of optimal shapes (a function of the two
    dimensionless numbers ``phi`` and ``r / (v t)``, computed by :func:`_optimal_shape`);
    ``A`` is then the smallest value that passes the enclosure certificate below, so the
    result encloses whatever the table says.

    *Certificate.*  ``E`` contains the set iff ``g = h_E - h_set >= 0`` for all ``theta``
    (both are convex, support functions characterise them). By symmetry ``[0, pi]`` suffices.
    Take nodes ``0 = theta_0 < ... < theta_N = pi`` that include ``pi/2`` and every kink of
    ``h_set`` (the edge normals ``(pi + phi) / 2`` and ``pi``). Between nodes both support
    functions are ``C^1`` and piecewise ``C^2`` with ``h'' + h = `` radius of curvature, so
    ``g'' = rho_E - rho_set - g <= (max rho_E - r) - g`` (the set's curvature radius is at least
    ``r``). ``rho_E(theta) = A^2 B^2 / (A^2 sin^2 + B^2 cos^2)^{3/2}`` is monotone on each
    quadrant, so its maximum on an interval is at an end. If ``M = max rho_E - r`` and the node
    values satisfy ``g >= max(M, 0) Delta^2 / 8`` (``Delta`` the interval length, ``< sqrt 8``),
    then ``g >= 0`` on the whole interval: at an interior minimum ``m < 0`` the bound
    ``g'' <= M - m`` gives ``m >= min(g_ends) - (M - m) Delta^2 / 8`` hence ``m (1 - Delta^2 / 8)
    >= 0``, a contradiction. Nodes are spaced uniformly in the ellipse's parametric angle, which
    keeps ``rho_E Delta^2`` small even for elongated ellipses. A further ``1e-12 (v t + r)``
    absorbs rounding. If the certificate ever fails, the axes grow until it passes, and as a
    last resort the circle of radius ``v t + r`` about the obstacle (which trivially contains
    everything within reach) is returned.

    Nodes: uniform in ``theta`` (48 intervals), uniform in the parametric angle of the
    table's ellipse (96 intervals), geometrically refined towards the ends of its axes (where a
    thin ellipse's normal turns fast), plus ``pi/2`` and the kink. Before the final fit the
    centre is polished by a short golden-section search on the area.

    Measured area factors (3000 random parameter sets with speeds 0.5-60 m/s, ``w_max`` 0-1
    rad/s, horizons 1-60 s, radii 0-20 m, compared with :func:`_optimal_shape`): ellipse area
    over the minimum-area enclosing ellipse (the best any ellipse can do) median 1.0004,
    99th percentile 1.002, max 1.007 (swept) / 1.03 (terminal). Ellipse area over the set's
    own area: median 1.11, max 2.42 (swept) / median 1.03, max 1.81 (terminal); no ellipse
    does better than ``4 pi / (3 sqrt 3) = 2.418`` on a triangle, which is what a swept set
    with small ``phi`` and ``r`` looks like. At the paper's example (``w_max = 0.013``,
    ``v = 4``, ``t = 10``, ``r = 3``): 1.54 (swept: ``c = 24.76``, ``A = 6.64``, ``B = 28.55``)
    and 1.12 (terminal), both within 0.06 % of the minimum enclosing ellipse.
    Cost: about 0.3 s for 10,000 parameter sets on one core.

Enclosing ellipsoid (eq. 18, corrected)
    The 3D swept set lies in ``(swept 2D set (+) disc(r)) x [-(vz_max t + r), vz_max t + r]``
    (the ball of radius ``r`` lies in a disc times an interval). With the 2D ellipse
    ``(A, B)`` and ``Z = vz_max t + r``, the ellipsoid with semi-axes ``sqrt(3/2) (B, A)`` and
    ``sqrt(3) Z`` contains that cylinder: a point of it has
    ``x^2 / (1.5 A^2) + y^2 / (1.5 B^2) + z^2 / (3 Z^2) <= 2/3 + 1/3``. Among ellipsoids
    ``(lambda B, lambda A, mu Z)`` that contain the cylinder (``1/lambda^2 + 1/mu^2 <= 1``) it
    has the least volume. When ``Z = 0`` the flat ellipse itself (``lambda = 1``) is returned.

Distances
    :func:`distance_to_ellipsoid` computes the true Euclidean distance from points to the
    ellipsoid surface (negative inside). With ``q`` the point in the body frame (by symmetry in
    the positive octant) the nearest point is ``x_i = a_i^2 q_i / (a_i^2 + t)`` where the
    Lagrange multiplier ``t >= -a_min^2`` is the largest root of ``F(t) = 1``,
    ``F = ||(a_i q_i / (t + a_i^2))_i||``; ``1/F`` is concave and increasing in ``t`` (a power
    mean of affine functions), so Newton's method on ``1/F - 1`` never passes the root from the
    left and, started right of it, lands left of it in one step. It starts at the radial
    projection's multiplier (exact on the surface and for spheres), clamped to lower bounds of
    the root, and also takes the Newton step of the equation without the smallest axis while
    that one is left of its own root (this avoids crawling up the pole of a nearly flat axis).
    Eight iterations give about 1e-12 of the size in the tests. When the root would lie below
    ``-a_min^2`` (a point inside, on the plane of the smallest axis) the nearest point leaves
    that plane: ``t = -a_min^2``. The smallest axis's coordinate is always taken from the
    surface equation, so the point lies on the surface and the distance error is second order
    in the multiplier's error. About 0.15 s for 100,000 points on one core.

Frames for ellipsoids: world NED (x north, y east, z down); heading ``psi`` from north towards
east; the body frame has axis 0 along the heading, axis 1 to the right (``psi + pi/2``) and
axis 2 down. ``semi_axes[..., :]`` is ordered (longitudinal, lateral, vertical).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env._numba import compiled_twin

__all__ = [
    "boundary",
    "contains",
    "distance_to_ellipsoid",
    "ellipse",
    "ellipsoid",
    "front_curve",
    "nearest_point_on_ellipsoid",
    "pairwise_distances",
    "region_distances",
    "support",
]

Mode = Literal["swept", "terminal"]
Fit = Literal["enclosing", "paper"]
_MODES = ("swept", "terminal")
_FITS = ("enclosing", "paper")
FloatArray = NDArray[np.float64]

#: Intervals of the enclosure certificate on ``[0, pi]`` (even, so that pi/2 is a node).
_N_CERT = 96
#: Geometrically spaced parameter nodes at each end of the ellipse's axes.
_N_GEO = 14
#: Nodes uniform in the normal angle, merged with those uniform in the ellipse's parameter.
_UNIFORM_NODES = np.linspace(0.0, np.pi, 49)[1:-1]
#: Relative absolute margin (of ``v t + r``) that absorbs floating-point rounding.
_EPS_ABS = 1e-12
#: Half-width (fraction of the set's length) and iterations of the centre's polishing search.
_C_SEARCH = 0.02
_C_ITERS = 8
#: Newton iterations of the point-to-ellipsoid distance.
_N_NEWTON = 8


# ---------------------------------------------------------------------------- validation
def _nonneg(name: str, value: ArrayLike) -> FloatArray:
    """``value`` as a float64 array; raises if any entry is negative, NaN or infinite."""
    arr = np.asarray(value, dtype=np.float64)
    bad = ~(np.isfinite(arr) & (arr >= 0.0))
    if np.any(bad):
        first = arr[bad].flat[0] if arr.ndim else arr.item()
        raise ValueError(f"{name} must be finite and >= 0, got {first!r}")
    return arr


def _check_mode(mode: str) -> bool:
    """True for ``"swept"``, False for ``"terminal"``; raises on anything else."""
    if mode not in _MODES:
        raise ValueError(f"mode must be 'swept' or 'terminal', got {mode!r}")
    return mode == "swept"


def _check_fit(fit: str) -> bool:
    """True for ``"paper"``, False for ``"enclosing"``; raises on anything else."""
    if fit not in _FITS:
        raise ValueError(f"fit must be 'enclosing' or 'paper', got {fit!r}")
    return fit == "paper"


def _out(x: FloatArray) -> FloatArray:
    """0-d arrays come back as 0-d float64 arrays, others unchanged."""
    return np.asarray(x, dtype=np.float64)


# ---------------------------------------------------------------------------- core maths
def _inv(phi: FloatArray) -> FloatArray:
    """``1 / phi`` with ``1 / 0 := 0`` (every use multiplies a quantity that is 0 there).

    ``phi`` below 1e-200 counts as 0 (a straight line): ``1 / phi`` would overflow to inf
    for subnormal ``phi`` and turn ``0 * inf`` into NaN.
    """
    tiny = phi > 1e-200
    safe = np.where(tiny, phi, 1.0)
    return np.where(tiny, 1.0 / safe, 0.0)


def _wrap_abs(theta: FloatArray) -> FloatArray:
    """``|theta|`` wrapped to ``[0, pi]``."""
    return np.abs(np.remainder(theta + np.pi, 2.0 * np.pi) - np.pi)


def _h_unit(
    a: FloatArray,
    phi: FloatArray,
    swept: bool,
    sin_a: FloatArray | None = None,
    cos_a: FloatArray | None = None,
) -> FloatArray:
    """Support of the ``r = 0`` set in units of ``v t``, direction ``a = |theta|`` in [0, pi].

    ``1 - (a - sin a) / phi`` where the heading ``a`` can be reached (``a <= phi``), else the
    support of the corner ``F(phi)``: ``sin a (1 - cos phi) / phi + cos a sin(phi) / phi``;
    clipped at 0 (the origin) for the swept set. ``sin_a``/``cos_a`` may be passed if known.
    """
    sa = np.sin(a) if sin_a is None else sin_a
    ca = np.cos(a) if cos_a is None else cos_a
    ip = _inv(phi)
    reach = 1.0 - (a - sa) * ip
    omc = 2.0 * np.sin(0.5 * phi) ** 2 * ip  # (1 - cos phi) / phi
    corner = sa * omc + ca * np.sinc(phi / np.pi)
    if swept:
        corner = np.maximum(corner, 0.0)
    return np.where(a <= phi, reach, corner)


def _front_unit(a: FloatArray, phi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``F(a) / (v t)`` for ``0 <= a <= min(phi, pi)`` (x >= 0 branch)."""
    ip = _inv(phi)
    x = np.sin(a) + (2.0 * np.sin(0.5 * a) ** 2 - a * np.sin(a)) * ip
    y = np.cos(a) + (np.sin(a) - a * np.cos(a)) * ip
    return x, y


# ---------------------------------------------------------------------------- 2D public API
def front_curve(
    theta: ArrayLike, speed: ArrayLike, max_turn_rate: ArrayLike, horizon: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Front curve ``F(theta)`` of the reachable set (``r = 0``), paper frame.

    ``F(theta)`` is the position at time ``t`` after turning at the full rate ``w_max`` to the
    heading ``theta`` and flying straight since; S1 (eq. 9) and S2 (eq. 10) are
    ``F(theta) + r (sin theta, cos theta)``.

    Args:
        theta: Final heading / outward normal angle from the heading axis (rad). Clipped to
            the curve's domain ``|theta| <= min(w_max t, pi)`` (eqs. 11-12).
        speed: Horizontal speed ``v`` (m/s).
        max_turn_rate: ``w_max`` (rad/s); 0 gives the straight-line tip ``(0, v t)``.
        horizon: Time ``t`` (s).

    Returns:
        ``(x, y)`` in the paper frame (x lateral, y along the heading) (m), broadcast shape.

    Raises:
        ValueError: If a speed, turn rate or horizon is negative or not finite.
    """
    th = np.asarray(theta, dtype=np.float64)
    v = _nonneg("speed", speed)
    w = _nonneg("max_turn_rate", max_turn_rate)
    t = _nonneg("horizon", horizon)
    th, v, w, t = np.broadcast_arrays(th, v, w, t)
    phi = w * t
    lim = np.minimum(phi, np.pi)
    a = np.minimum(np.abs(th), lim)
    xu, yu = _front_unit(a, phi)
    vt = v * t
    return _out(np.sign(th) * vt * xu), _out(vt * yu)


def support(
    theta: ArrayLike,
    speed: ArrayLike,
    max_turn_rate: ArrayLike,
    horizon: ArrayLike,
    radius: ArrayLike,
    mode: Mode = "swept",
) -> FloatArray:
    """Support function of the reachable set (plus the safety radius), paper frame.

    ``h(theta) = max over the set of p . (sin theta, cos theta)``. Exact for both modes:
    ``"swept"`` is the convex hull of everything reachable in ``[0, t]``; ``"terminal"`` is
    the S1..S5 region (eqs. 9-16 with the erratum), the convex hull of the positions at exactly
    ``t``. For ``|theta| <= w_max t``: ``r + v t - rho (|theta| - sin|theta|)``.

    Args:
        theta: Direction from the heading axis (rad), any real (wrapped).
        speed: Horizontal speed ``v`` (m/s).
        max_turn_rate: ``w_max`` (rad/s).
        horizon: Prediction horizon ``t`` (s).
        radius: Safety radius ``r`` (m).
        mode: ``"swept"`` or ``"terminal"``.

    Returns:
        The support value (m), broadcast shape.

    Raises:
        ValueError: On a negative/non-finite parameter or an unknown mode.
    """
    swept = _check_mode(mode)
    th = np.asarray(theta, dtype=np.float64)
    v = _nonneg("speed", speed)
    w = _nonneg("max_turn_rate", max_turn_rate)
    t = _nonneg("horizon", horizon)
    r = _nonneg("radius", radius)
    th, v, w, t, r = np.broadcast_arrays(th, v, w, t, r)
    return _out(r + v * t * _h_unit(_wrap_abs(th), w * t, swept))


def boundary(
    speed: float,
    max_turn_rate: float,
    horizon: float,
    radius: float,
    n: int = 721,
    mode: Mode = "terminal",
) -> FloatArray:
    """Closed polygon through the boundary of the reachable region, paper frame.

    For ``mode="terminal"`` the pieces are, in order: S3 (eq. 13, arc of radius ``r`` about
    ``F(-phi)``, normals ``-pi..-phi``), S1 (eq. 9), S2 (eq. 10), S4 (eq. 14, arc about
    ``F(phi)``), and the closing edge from the last point back to the first is the chord S5.
    For ``phi >= pi`` S3/S4 are empty. ``mode="swept"`` gives the swept set's hull boundary
    (arcs about the origin replace part of S3/S4 for ``phi < pi``). Every vertex lies on the
    boundary (the polygon is inscribed); the corner normals ``+-phi`` are vertices.

    Args:
        speed: Horizontal speed ``v`` (m/s).
        max_turn_rate: ``w_max`` (rad/s).
        horizon: Time ``t`` (s).
        radius: Safety radius ``r`` (m).
        n: Number of rows; the last row repeats the first (at least 8).
        mode: ``"terminal"`` (S1..S5, default) or ``"swept"``.

    Returns:
        ``(n, 2)`` array of ``(x, y)`` vertices (m), x lateral, y along the heading.

    Raises:
        ValueError: On a negative/non-finite or non-scalar parameter, ``n < 8`` or an unknown
            mode.
    """
    swept = _check_mode(mode)
    vals = []
    for name, val in (
        ("speed", speed),
        ("max_turn_rate", max_turn_rate),
        ("horizon", horizon),
        ("radius", radius),
    ):
        arr = _nonneg(name, val)
        if arr.ndim:
            raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
        vals.append(float(arr))
    v, w, t, r = vals
    if int(n) != n or n < 8:
        raise ValueError(f"n must be an integer >= 8, got {n!r}")
    n = int(n)
    phi = w * t
    lim = min(phi, np.pi)
    th = np.linspace(-np.pi, np.pi, n - 1)
    if lim < np.pi:
        specials = [lim]
        if swept:
            specials.append(0.5 * (np.pi + phi))
        for s in specials:
            for sgn in (-1.0, 1.0):
                th[np.argmin(np.abs(th - sgn * s))] = sgn * s
        th = np.sort(th)
    a = np.abs(th)
    xu, yu = _front_unit(np.minimum(a, lim), np.asarray(phi))
    if swept and lim < np.pi:
        behind = a > 0.5 * (np.pi + phi)
        xu = np.where(behind, 0.0, xu)
        yu = np.where(behind, 0.0, yu)
    vt = v * t
    x = np.sign(th) * vt * xu + r * np.sin(th)
    y = vt * yu + r * np.cos(th)
    pts = np.stack([x, y], axis=-1)
    return np.concatenate([pts, pts[:1]], axis=0)


# ---------------------------------------------------------------------------- shape table
# Shape table (``data/ellipse_table.npz``): the minimum-area enclosing ellipse's centre c and
# longitudinal semi-axis B as fractions of the set's extent along the heading (c from the back
# end), and its lateral semi-axis A as a fraction of the set's half-width, for the swept ("s")
# and the terminal ("t") set, on a grid of u = sqrt((2/pi) atan2(2 r / (v t), phi)) ("al";
# 0: r = 0, 1: phi = 0; 33 nodes) and log10(hypot(phi, 2 r / (v t))) ("lr"; -3..3, 49 nodes).
# Made by ``_build_table(swept, u, logr)`` (about a minute). It only steers the fit towards the
# minimum area: whatever it holds, the returned ellipse passes the enclosure certificate.
def _load_table() -> tuple[FloatArray, FloatArray, dict[bool, FloatArray]]:
    """The shipped shape table: ``(u nodes, log10 radius nodes, {swept: (33, 49, 3)})``."""
    path = Path(__file__).with_name("data") / "ellipse_table.npz"
    with np.load(path) as data:
        return (
            np.asarray(data["al"], dtype=np.float64),
            np.asarray(data["lr"], dtype=np.float64),
            {True: np.asarray(data["s"], np.float64), False: np.asarray(data["t"], np.float64)},
        )


_TAB_U, _TAB_LOGR, _TAB = _load_table()


def _table_coords(phi: FloatArray, eps: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Table coordinates for ``phi = w t`` and ``eps = r / (v t)`` (may be inf)."""
    finite = np.isfinite(eps)
    e = np.where(finite, eps, 0.0)
    u = np.sqrt(np.where(finite, np.arctan2(2.0 * e, phi) * (2.0 / np.pi), 1.0))
    rad = np.where(finite, np.hypot(phi, 2.0 * e), np.inf)
    with np.errstate(divide="ignore"):
        logr = np.log10(rad)
    return u, logr


def _interp_table(swept: bool, u: FloatArray, logr: FloatArray) -> FloatArray:
    """Bilinear interpolation of the shape table, ``(..., 3)`` = (c, B, A) fractions."""
    tab = _TAB[swept]
    na, nl = tab.shape[:2]
    fa = np.clip((u - _TAB_U[0]) / (_TAB_U[1] - _TAB_U[0]), 0.0, na - 1.0)
    fl = np.clip((logr - _TAB_LOGR[0]) / (_TAB_LOGR[1] - _TAB_LOGR[0]), 0.0, nl - 1.0)
    fl = np.where(np.isnan(fl), 0.0, fl)
    i0 = np.minimum(fa.astype(np.intp), na - 2)
    j0 = np.minimum(fl.astype(np.intp), nl - 2)
    ta = (fa - i0)[..., None]
    tl = (fl - j0)[..., None]
    return (
        tab[i0, j0] * (1 - ta) * (1 - tl)
        + tab[i0 + 1, j0] * ta * (1 - tl)
        + tab[i0, j0 + 1] * (1 - ta) * tl
        + tab[i0 + 1, j0 + 1] * ta * tl
    )


# ---------------------------------------------------------------------------- reference optimiser
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


def _optimal_shape(
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


def _build_table(swept: bool, u: FloatArray, logr: FloatArray, **kwargs: int) -> FloatArray:
    """Shape table ``(len(u), len(logr), 3)``: (c, B) over the y-extent, A over max |x|."""
    al, lr = np.meshgrid(np.asarray(u) ** 2, logr, indexing="ij")
    rad = 10.0**lr
    phi = np.where(al >= 1.0, 0.0, rad * np.cos(0.5 * np.pi * al))
    eps = 0.5 * rad * np.sin(0.5 * np.pi * al)
    kappa = eps / (1.0 + eps)
    c, lat, lon = _optimal_shape(phi, kappa, swept, **kwargs)
    h0 = kappa + (1.0 - kappa) * _h_unit(np.zeros_like(phi), phi, swept)
    hpi = kappa + (1.0 - kappa) * _h_unit(np.full_like(phi, np.pi), phi, swept)
    hx = kappa + (1.0 - kappa) * _h_unit(np.full_like(phi, 0.5 * np.pi), phi, swept)
    ext = h0 + hpi
    return np.stack([(c + hpi) / ext, lon / ext, lat / np.maximum(hx, 1e-300)], axis=-1)


# ---------------------------------------------------------------------------- ellipse fit
class _Nodes:
    """Certificate nodes on ``[0, pi]`` with their trigonometry and the set's support there."""

    def __init__(
        self, th: FloatArray, vt: FloatArray, phi: FloatArray, r: FloatArray, swept: bool
    ) -> None:
        self.th = th
        self.cos = np.cos(th)
        self.c2 = self.cos**2
        sin = np.sin(th)
        self.s2 = sin**2
        self.d2 = np.diff(th, axis=-1) ** 2 / 8.0
        self.cos_in = self.cos[..., 1:-1]
        self.c2_in = self.c2[..., 1:-1]
        self.inv_s2_in = 1.0 / self.s2[..., 1:-1]
        self.h = r[..., None] + vt[..., None] * _h_unit(th, phi[..., None], swept, sin, self.cos)

    def take(self, idx: NDArray[np.intp]) -> _Nodes:
        """The nodes of the rows ``idx``."""
        sub = object.__new__(_Nodes)
        for name in ("th", "cos", "c2", "s2", "d2", "h", "cos_in", "c2_in", "inv_s2_in"):
            setattr(sub, name, getattr(self, name)[idx])
        return sub


def _margins(
    nd: _Nodes, lat: FloatArray, lon: FloatArray, r: FloatArray, eps_abs: FloatArray
) -> FloatArray:
    """Certificate margins ``max(max rho_E - r, 0) Delta^2 / 8`` at the nodes, ``(..., K)``."""
    a2 = (lat * lat)[..., None]
    b2 = (lon * lon)[..., None]
    den = a2 * nd.s2
    den += b2 * nd.c2
    np.maximum(den, 1e-300, out=den)
    rho = np.sqrt(den)
    rho *= den
    np.divide(a2 * b2, rho, out=rho)  # radius of curvature of the ellipse at the nodes
    m_int = np.maximum(rho[..., 1:], rho[..., :-1])
    m_int -= r[..., None]
    np.maximum(m_int, 0.0, out=m_int)
    m_int *= nd.d2
    out = rho
    out[..., 0] = m_int[..., 0]
    out[..., -1] = m_int[..., -1]
    np.maximum(m_int[..., 1:], m_int[..., :-1], out=out[..., 1:-1])
    out += eps_abs[..., None]
    return out


def _axes_for(
    nd: _Nodes, delta: FloatArray, c: FloatArray, lon: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Least axes ``(A, B >= lon)`` with ``h_E(theta_k) >= h_k + delta_k`` at every node."""
    h = nd.h
    lon = np.maximum(lon, h[..., 0] + delta[..., 0] - c)
    lon = np.maximum(lon, h[..., -1] + delta[..., -1] + c)
    need = c[..., None] * nd.cos_in
    np.subtract(h[..., 1:-1], need, out=need)
    need += delta[..., 1:-1]
    np.maximum(need, 0.0, out=need)
    need *= need
    need -= (lon * lon)[..., None] * nd.c2_in
    need *= nd.inv_s2_in
    return np.sqrt(np.maximum(np.max(need, axis=-1), 0.0)), lon


def _fit_axes(
    nd: _Nodes,
    c: FloatArray,
    lat: FloatArray,
    lon: FloatArray,
    r: FloatArray,
    eps_abs: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Least axes for the centre ``c`` with the margins of ``(lat, lon)`` plus 25%.

    ``B`` only grows (to meet the tip constraints at 0 and pi); ``A`` is the least value with
    ``c cos theta_k + sqrt(A^2 sin^2 + B^2 cos^2) >= h_k + delta_k`` at the inner nodes.
    """
    return _axes_for(nd, 1.25 * _margins(nd, lat, lon, r, eps_abs), c, lon)


def _certified(
    nd: _Nodes,
    c: FloatArray,
    lat: FloatArray,
    lon: FloatArray,
    r: FloatArray,
    eps_abs: FloatArray,
) -> NDArray[np.bool_]:
    """Whether ``(c, A, B)`` passes the enclosure certificate (see the module docstring)."""
    delta = _margins(nd, lat, lon, r, eps_abs)
    he = c[..., None] * nd.cos + np.sqrt(
        (lat * lat)[..., None] * nd.s2 + (lon * lon)[..., None] * nd.c2
    )
    return np.all(he - nd.h >= delta, axis=-1)


def _ellipse_core(
    vt: FloatArray, phi: FloatArray, r: FloatArray, swept: bool
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Certified near-minimal ellipse ``(c, A, B)`` for flat arrays of parameters."""
    scale = vt + r
    live = scale > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = np.where(vt > 0.0, r / np.where(vt > 0.0, vt, 1.0), np.inf)
    u, logr = _table_coords(phi, eps)
    frac = _interp_table(swept, u, logr)
    zero = np.zeros_like(vt)
    h0 = r + vt * _h_unit(zero, phi, swept)
    hpi = r + vt * _h_unit(zero + np.pi, phi, swept)
    hx = r + vt * _h_unit(zero + 0.5 * np.pi, phi, swept)
    ext = h0 + hpi
    c = frac[..., 0] * ext - hpi
    lon = frac[..., 1] * ext
    lat = frac[..., 2] * hx
    eps_abs = _EPS_ABS * scale
    # Nodes: uniform in the parametric angle of the table's ellipse, merged with nodes uniform
    # in the normal angle, pi/2 and the kink of the swept set's support.
    # Near the ends of a thin ellipse the normal turns fast, so the parameter is also refined
    # geometrically towards 0, pi/2 and pi, down to a fifth of the aspect ratio.
    lat_g = np.maximum(lat, 1e-9 * scale)
    lon_g = np.maximum(lon, 1e-9 * scale)
    step = np.pi / _N_CERT
    t_lo = np.minimum(0.2 * np.minimum(lat_g, lon_g) / np.maximum(lat_g, lon_g), step)
    geo = t_lo[..., None] * (step / t_lo)[..., None] ** np.linspace(0.0, 1.0, _N_GEO)
    tpar = np.concatenate(
        [
            np.broadcast_to(np.linspace(0.0, np.pi, _N_CERT + 1), (*vt.shape, _N_CERT + 1)),
            geo,
            0.5 * np.pi - geo,
            0.5 * np.pi + geo,
            np.pi - geo,
        ],
        axis=-1,
    )
    th = np.arctan2(lon_g[..., None] * np.sin(tpar), lat_g[..., None] * np.cos(tpar))
    th[..., 0] = 0.0
    th[..., _N_CERT // 2] = 0.5 * np.pi
    th[..., _N_CERT] = np.pi
    kink = np.where(swept & (phi < np.pi), 0.5 * (np.pi + phi), 0.5 * np.pi)
    uni = np.broadcast_to(_UNIFORM_NODES, (*th.shape[:-1], _UNIFORM_NODES.size))
    th = np.sort(np.concatenate([th, uni, kink[..., None]], axis=-1), axis=-1)
    nd = _Nodes(th, vt, phi, r, swept)
    # The margins depend on (A, B): fit twice, taking the margins at the previous axes with a
    # 25% allowance, then certify; rows that still fail grow until they pass.
    delta = 1.25 * _margins(nd, lat_g, lon, r, eps_abs)
    # Polish the centre by a short golden-section search on the area (margins held fixed).
    half = _C_SEARCH * ext

    def neg_area(cc: FloatArray) -> FloatArray:
        a_, b_ = _axes_for(nd, delta, cc, lon)
        return -(a_ * b_)

    c = _golden_max(neg_area, c - half, c + half, _C_ITERS)
    lat = lat_g
    for _ in range(2):
        lat, lon = _fit_axes(nd, c, np.maximum(lat, 1e-3 * lat_g), lon, r, eps_abs)
    ok = _certified(nd, c, lat, lon, r, eps_abs) | ~live
    grow = 1e-6
    for _ in range(30):
        if np.all(ok):
            break
        bad = np.flatnonzero(~ok)
        lat[bad] *= 1.0 + grow
        lon[bad] *= 1.0 + grow
        ok[bad] = _certified(nd.take(bad), c[bad], lat[bad], lon[bad], r[bad], eps_abs[bad])
        grow *= 8.0
    # The circle of radius v t + r about the obstacle holds everything within reach; use it
    # if the certificate never passed, or if it is smaller (sets that are nearly discs).
    fallback = ~ok | (lat * lon > scale * scale)
    c = np.where(fallback, 0.0, c)
    lat = np.where(fallback, scale, lat)
    lon = np.where(fallback, scale, lon)
    # Exact special cases: a disc (v t = 0, includes a point) and a segment (phi = 0, r = 0).
    disc = vt <= 0.0
    seg = (phi <= 0.0) & (r <= 0.0) & ~disc
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
    ellipse inscribed in the set's bounding box, Figure 3).
    """
    zero = np.zeros_like(vt)
    h0 = r + vt * _h_unit(zero, phi, swept)
    hpi = r + vt * _h_unit(zero + np.pi, phi, swept)
    hx = r + vt * _h_unit(zero + 0.5 * np.pi, phi, swept)
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
    See the module docstring for the enclosure certificate and the measured area factors
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
    v = _nonneg("speed", speed)
    w = _nonneg("max_turn_rate", max_turn_rate)
    t = _nonneg("horizon", horizon)
    r = _nonneg("radius", radius)
    v, w, t, r = np.broadcast_arrays(v, w, t, r)
    shape = v.shape
    vt = (v * t).ravel()
    phi = (w * t).ravel()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c, lat, lon = core(vt, phi, r.ravel().astype(np.float64), swept)
    return _out(c.reshape(shape)), _out(lat.reshape(shape)), _out(lon.reshape(shape))


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
    v = _nonneg("speed", speed)
    w = _nonneg("max_turn_rate", max_turn_rate)
    vz = _nonneg("max_climb_rate", max_climb_rate)
    t = _nonneg("horizon", horizon)
    r = _nonneg("radius", radius)
    v, w, vz, t, r = np.broadcast_arrays(v, w, vz, t, r)
    shape = v.shape
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        c, lat, lon = (_paper_core if paper else _ellipse_core)(
            (v * t).ravel(), (w * t).ravel(), r.ravel().astype(float), swept
        )
    if paper:
        axes = np.stack([lon, lat, lat], axis=-1)
        return _out(c.reshape(shape)), axes.reshape((*shape, 3))
    z = (vz * t + r).ravel()
    flat = z <= 0.0
    lam = np.where(flat, 1.0, np.sqrt(1.5))
    axes = np.stack([lam * lon, lam * lat, np.sqrt(3.0) * z], axis=-1)
    return _out(c.reshape(shape)), axes.reshape((*shape, 3))


# ---------------------------------------------------------------------------- distances
def _to_body(
    points: ArrayLike, centers: ArrayLike, headings: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body-frame coordinates of ``points`` and the heading's cos/sin (broadcast)."""
    p = np.asarray(points, dtype=np.float64)
    ctr = np.asarray(centers, dtype=np.float64)
    psi = np.asarray(headings, dtype=np.float64)
    d = p - ctr
    cp = np.cos(psi)
    sp = np.sin(psi)
    q0 = d[..., 0] * cp + d[..., 1] * sp
    q1 = -d[..., 0] * sp + d[..., 1] * cp
    q2 = np.broadcast_to(d[..., 2], q0.shape)
    return np.stack([q0, q1, q2], axis=-1), cp, sp


def _check_axes(semi_axes: ArrayLike) -> FloatArray:
    ax = np.asarray(semi_axes, dtype=np.float64)
    if ax.shape[-1:] != (3,):
        raise ValueError(f"semi_axes must have a last dimension of 3, got shape {ax.shape}")
    # Two reductions in the usual case (NaN fails the first): this runs every step.
    if ax.size and not (ax.min() >= 0.0 and ax.max() < np.inf):
        bad = ~(np.isfinite(ax) & (ax >= 0.0))
        raise ValueError(f"semi_axes must be finite and >= 0, got {ax[bad].flat[0]!r}")
    return ax


def _nearest_body(q: FloatArray, ax: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Nearest surface point, signed distance and outward unit normal, body frame.

    Args:
        q: ``(..., 3)`` points relative to the centre, body frame.
        ax: ``(..., 3)`` semi-axes (broadcastable with ``q``).

    Returns:
        ``(x, dist, normal)``: nearest point ``(..., 3)``, signed distance ``(...)`` and the
        unit outward normal at ``x`` ``(..., 3)``.
    """
    q, ax = np.broadcast_arrays(q, ax)
    sgn = np.where(q < 0.0, -1.0, 1.0)
    qa = np.abs(q)
    scale = np.maximum(np.max(ax, axis=-1), np.max(qa, axis=-1))
    scale = np.where(scale > 0.0, scale, 1.0)[..., None]
    qs = qa / scale
    a = ax / scale
    m = np.argmin(a, axis=-1)[..., None]
    am = np.take_along_axis(a, m, axis=-1)
    is_m = np.arange(3) == m
    off = a * a - am * am  # >= 0, exactly 0 on the smallest axis
    cq = a * qs
    # Lower bounds of sigma = t + a_m^2 at the root (t: the Lagrange multiplier).
    sig = np.max(cq - a * a + am * am, axis=-1)
    sig = np.maximum(
        sig, np.sqrt(np.sum(cq * cq, axis=-1)) - np.max(a, axis=-1) ** 2 + am[..., 0] ** 2
    )
    sig_lo = np.maximum(sig, 0.0)
    # Start from the radial projection's multiplier (exact on the surface and for spheres),
    # never below the lower bound: a first step from the right of the root lands left of it
    # (the tangent of a concave function lies above it), after which Newton climbs
    # monotonically to the root.
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(a > 0.0, qs / np.where(a > 0.0, a, 1.0), np.where(qs > 0.0, np.inf, 0.0))
    level = np.sqrt(np.sum(ratio * ratio, axis=-1))
    am0 = am[..., 0]
    guess = np.where(am0 > 0.0, am0 * am0 * np.where(np.isfinite(level), level, 0.0), 0.0)
    sig = np.maximum(sig_lo, guess)
    # Each iteration also takes the Newton step of the equation without the smallest axis when
    # that one is still left of its own root: it bounds the full root from below too, and it
    # does not crawl up the steep pole of a nearly flat axis.
    for _ in range(_N_NEWTON):
        s = sig[..., None] + off
        pos = s > 0.0
        w = np.where(pos, cq / np.where(pos, s, 1.0), 0.0)
        w2 = w * w
        w2s = np.where(pos, w2 / np.where(pos, s, 1.0), 0.0)
        f2 = np.sum(w2, axis=-1)
        g = np.sum(w2s, axis=-1)
        wm2 = np.take_along_axis(w2, m, axis=-1)[..., 0]
        f2r = f2 - wm2
        gr = g - np.take_along_axis(w2s, m, axis=-1)[..., 0]
        f = np.sqrt(f2)
        fr = np.sqrt(np.maximum(f2r, 0.0))
        step = np.where(g > 0.0, f2 * (f - 1.0) / np.where(g > 0.0, g, 1.0), 0.0)
        live = (gr > 0.0) & (fr > 1.0)
        step_r = np.where(live, f2r * (fr - 1.0) / np.where(live, gr, 1.0), -np.inf)
        sig = np.maximum(sig_lo, sig + np.maximum(step, step_r))
    s = sig[..., None] + off
    w = np.where(s > 0.0, cq / np.where(s > 0.0, s, 1.0), 0.0)
    w = np.where(is_m, 0.0, w)
    rest = np.sum(w * w, axis=-1)
    shrink = np.where(rest > 1.0, 1.0 / np.sqrt(np.maximum(rest, 1.0)), 1.0)
    w = w * shrink[..., None]
    wm = np.sqrt(np.maximum(1.0 - rest, 0.0))
    w = np.where(is_m, wm[..., None], w)
    x = a * w  # positive orthant, scaled units
    # Outward normal ~ x_i / a_i^2 = w_i / a_i, multiplied through by a_m to stay bounded.
    with np.errstate(divide="ignore", invalid="ignore"):
        ng = np.where(a > 0.0, w * am / np.where(a > 0.0, a, 1.0), 0.0)
    ng = np.where(is_m & (am <= 0.0), np.where(rest < 1.0, 1.0, 0.0)[..., None], ng)
    diff = qs - x
    dist = np.sqrt(np.sum(diff * diff, axis=-1))
    inside = level < 1.0
    ngn = np.sqrt(np.sum(ng * ng, axis=-1))
    dirn = np.where(
        (inside | (dist <= 1e-12))[..., None] & (ngn > 0.0)[..., None],
        ng / np.where(ngn > 0.0, ngn, 1.0)[..., None],
        diff / np.where(dist > 0.0, dist, 1.0)[..., None],
    )
    dn = np.sqrt(np.sum(dirn * dirn, axis=-1))
    dirn = np.where((dn > 0.0)[..., None], dirn, is_m.astype(np.float64))
    signed = np.where(inside, -dist, dist) * scale[..., 0]
    return x * scale * sgn, signed, dirn * sgn


def _to_world(n: FloatArray, cp: FloatArray, sp: FloatArray) -> FloatArray:
    """Rotate body-frame vectors back to NED."""
    return np.stack(
        [n[..., 0] * cp - n[..., 1] * sp, n[..., 0] * sp + n[..., 1] * cp, n[..., 2]], axis=-1
    )


@compiled_twin("nearest_on_ellipsoids", n_newton=_N_NEWTON)
def _nearest(
    points: ArrayLike, centers: ArrayLike, ax: FloatArray, headings: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Nearest point minus the centre, signed distance and outward normal (all NED).

    The solve behind :func:`distance_to_ellipsoid` and :func:`nearest_point_on_ellipsoid`;
    ``ax`` is validated (:func:`_check_axes`), the four broadcast together.
    """
    q, cp, sp = _to_body(points, centers, headings)
    x, dist, n = _nearest_body(q, ax)
    cp, sp = np.broadcast_arrays(cp, sp, dist)[:2]
    offset = _to_world(np.broadcast_to(x, (*dist.shape, 3)), cp, sp)
    return offset, dist, _to_world(np.broadcast_to(n, (*dist.shape, 3)), cp, sp)


def distance_to_ellipsoid(
    points: ArrayLike,
    centers: ArrayLike,
    semi_axes: ArrayLike,
    headings: ArrayLike,
    return_normal: bool = False,
) -> FloatArray | tuple[FloatArray, FloatArray]:
    """Signed Euclidean distance from points to heading-aligned ellipsoids (negative inside).

    The true distance to the surface (not the support-function bound of the paper's eq. 25),
    by Newton's method on the Lagrange multiplier (see the module docstring); degenerate
    cases (a point at the centre or on an axis, zero semi-axes, huge distances) are handled.

    Args:
        points: ``(..., 3)`` positions, NED (m).
        centers: ``(..., 3)`` ellipsoid centres, NED (m).
        semi_axes: ``(..., 3)`` semi-axes (longitudinal, lateral, vertical) (m).
        headings: ``(...)`` heading ``psi`` of each ellipsoid (rad from north towards east).
        return_normal: Also return the repulsion direction.

    Returns:
        The signed distance ``(...)`` (m); with ``return_normal`` also ``(..., 3)`` unit
        vectors, NED: the outward surface normal at the nearest surface point, i.e. from that
        point towards an outside point, and the direction that pushes an inside point out.
        Never NaN; for a point exactly at the centre the smallest axis (the first of equal
        ones, positive direction) is chosen.

    Raises:
        ValueError: If a semi-axis is negative or not finite.
    """
    _, dist, normal = _nearest(points, centers, _check_axes(semi_axes), headings)
    return (dist, normal) if return_normal else dist


def pairwise_distances(
    points: ArrayLike, centers: ArrayLike, semi_axes: ArrayLike, headings: ArrayLike
) -> FloatArray:
    """Signed distance of every point to every ellipsoid of the same batch row.

    :func:`distance_to_ellipsoid` on ``points[:, :, None]`` against ``centers[:, None]``,
    the shape every env step asks for (UAVs against obstacles' regions).

    Args:
        points: ``(E, N, 3)`` positions, NED (m).
        centers: ``(E, M, 3)`` ellipsoid centres, NED (m).
        semi_axes: ``(E, M, 3)`` semi-axes (m).
        headings: ``(E, M)`` headings (rad).

    Returns:
        ``(E, N, M)`` signed distances (m, negative inside).

    Raises:
        ValueError: If a semi-axis is negative or not finite.
    """
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64)
    psi = np.asarray(headings, dtype=np.float64)
    return _pairwise(p, c, _check_axes(semi_axes), psi)


@compiled_twin("pairwise_distances", n_newton=_N_NEWTON)
def _pairwise(
    points: FloatArray, centers: FloatArray, ax: FloatArray, headings: FloatArray
) -> FloatArray:
    """:func:`pairwise_distances` of float64 arrays with validated semi-axes."""
    a = (points[:, :, None], centers[:, None], ax[:, None], headings[:, None])
    return _nearest.reference(*a)[1]


@compiled_twin("region_distances", n_newton=_N_NEWTON)
def region_distances(
    points: FloatArray,
    centers: FloatArray,
    semi_axes: FloatArray,
    headings: FloatArray,
    cos_h: FloatArray,
    sin_h: FloatArray,
    active: NDArray[np.bool_],
) -> FloatArray:
    """:func:`pairwise_distances` against the regions of a world, ``inf`` where inactive.

    The compiled form reads the headings' kept cosines and sines (numpy's, the same numbers
    the numpy form computes from ``headings``), so a step does not compute them again.

    Args:
        points: ``(E, N, 3)`` positions, NED (m).
        centers: ``(E, M, 3)`` ellipsoid centres, NED (m).
        semi_axes: ``(E, M, 3)`` semi-axes (m), finite and >= 0.
        headings: ``(E, M)`` headings (rad).
        cos_h: ``(E, M)`` ``np.cos(headings)``.
        sin_h: ``(E, M)`` ``np.sin(headings)``.
        active: ``(E, M)`` bool; inactive ellipsoids give ``inf``.

    Returns:
        ``(E, N, M)`` signed distances (m, negative inside).
    """
    p = np.asarray(points, dtype=np.float64)
    c = np.asarray(centers, dtype=np.float64)
    psi = np.asarray(headings, dtype=np.float64)
    d = _pairwise.reference(p, c, _check_axes(semi_axes), psi)
    return np.where(active[:, None, :], d, np.inf)


def nearest_point_on_ellipsoid(
    points: ArrayLike, centers: ArrayLike, semi_axes: ArrayLike, headings: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Nearest surface point, signed distance and outward unit normal (all NED).

    Args:
        points: ``(..., 3)`` positions, NED (m).
        centers: ``(..., 3)`` ellipsoid centres, NED (m).
        semi_axes: ``(..., 3)`` semi-axes (longitudinal, lateral, vertical) (m).
        headings: ``(...)`` headings (rad).

    Returns:
        ``(nearest, distance, normal)``: ``(..., 3)`` surface points (m), ``(...)`` signed
        distances (m, negative inside) and ``(..., 3)`` unit outward normals at the nearest
        points, as in :func:`distance_to_ellipsoid`.

    Raises:
        ValueError: If a semi-axis is negative or not finite.
    """
    ctr = np.asarray(centers, dtype=np.float64)
    offset, dist, normal = _nearest(points, ctr, _check_axes(semi_axes), headings)
    return offset + ctr, dist, normal


def contains(
    points: ArrayLike, centers: ArrayLike, semi_axes: ArrayLike, headings: ArrayLike
) -> NDArray[np.bool_]:
    """Whether each point lies inside or on its ellipsoid.

    Args:
        points: ``(..., 3)`` positions, NED (m).
        centers: ``(..., 3)`` ellipsoid centres, NED (m).
        semi_axes: ``(..., 3)`` semi-axes (longitudinal, lateral, vertical) (m).
        headings: ``(...)`` headings (rad).

    Returns:
        Boolean array of the broadcast shape.

    Raises:
        ValueError: If a semi-axis is negative or not finite.
    """
    ax = _check_axes(semi_axes)
    q, _, _ = _to_body(points, centers, headings)
    q, ax = np.broadcast_arrays(q, ax)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(ax > 0.0, q / np.where(ax > 0.0, ax, 1.0), np.where(q != 0.0, np.inf, 0.0))
    return np.sum(ratio * ratio, axis=-1) <= 1.0
