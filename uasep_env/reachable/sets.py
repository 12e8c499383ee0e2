"""The 2D reachable sets of paper section 3.1: the front curve, support functions, boundaries.

The terminal set S1..S5 (eqs. 9-16, with the erratum of ``notes.md``) and the swept set (the
project's default), in the paper frame: obstacle at the origin heading ``+y``, ``x`` lateral
(to the right), directions ``theta`` from the heading axis. The derivation is in
``docs/reachable_sets.md``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env.sim.obstacles import sinc

__all__ = ["FloatArray", "Mode", "boundary", "front_curve", "support"]

Mode = Literal["swept", "terminal"]
_MODES = ("swept", "terminal")
FloatArray = NDArray[np.float64]


# ---------------------------------------------------------------------------- validation
def _nonneg(name: str, value: ArrayLike) -> FloatArray:
    """``value`` as a float64 array; raises if any entry is negative, NaN or infinite."""
    arr = np.asarray(value, dtype=np.float64)
    bad = ~(np.isfinite(arr) & (arr >= 0.0))
    if np.any(bad):
        first = arr[bad].flat[0] if arr.ndim else arr.item()
        raise ValueError(f"{name} must be finite and >= 0, got {first!r}")
    return arr


def _nonneg_all(**values: ArrayLike) -> list[FloatArray]:
    """:func:`_nonneg` of each value, in order, checked in one pass (a reset fits a few rows)."""
    arrs = [np.asarray(v, dtype=np.float64) for v in values.values()]
    flat = np.concatenate([a.ravel() for a in arrs])
    if not (np.isfinite(flat) & (flat >= 0.0)).all():
        for name, value in values.items():
            _nonneg(name, value)  # raises, naming the first bad one
    return arrs


def _check_mode(mode: str) -> bool:
    """True for ``"swept"``, False for ``"terminal"``; raises on anything else."""
    if mode not in _MODES:
        raise ValueError(f"mode must be 'swept' or 'terminal', got {mode!r}")
    return mode == "swept"


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


def _h_unit(a: FloatArray, phi: FloatArray, swept: bool) -> FloatArray:
    """Support of the ``r = 0`` set in units of ``v t``, direction ``a = |theta|`` in [0, pi].

    ``1 - (a - sin a) / phi`` where the heading ``a`` can be reached (``a <= phi``), else the
    support of the corner ``F(phi)``: ``sin a (1 - cos phi) / phi + cos a sin(phi) / phi``;
    clipped at 0 (the origin) for the swept set (:func:`_h_unit_of`, where the sines and
    cosines are known already).
    """
    ip, omc, sc = _unit_factors(phi)
    return _h_unit_of(a, np.sin(a), np.cos(a), phi, ip, omc, sc, swept)


def _unit_factors(phi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``1 / phi``, ``(1 - cos phi) / phi`` and ``sin(phi) / phi``: :func:`_h_unit`'s factors."""
    ip = _inv(phi)
    return ip, 2.0 * np.sin(0.5 * phi) ** 2 * ip, sinc(phi / np.pi)


def _h_unit_of(
    a: FloatArray,
    sa: FloatArray,
    ca: FloatArray,
    phi: FloatArray,
    ip: FloatArray,
    omc: FloatArray,
    sc: FloatArray,
    swept: bool,
) -> FloatArray:
    """:func:`_h_unit` from the sines, cosines and factors (the fit's kernel repeats it)."""
    reach = 1.0 - (a - sa) * ip
    corner = sa * omc + ca * sc
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
