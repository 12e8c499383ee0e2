"""Signed distances from points to heading-aligned ellipsoids, nearest points and normals.

The solver (a safeguarded Newton iteration on the Lagrange multiplier, derived in
``docs/reachable_sets.md``) runs as a compiled kernel when numba is in use
(:func:`uasep_env._numba.compiled_twin`; the same numbers bit for bit).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env._numba import compiled_twin

__all__ = [
    "contains",
    "distance_to_ellipsoid",
    "nearest_point_on_ellipsoid",
    "pairwise_distances",
    "region_distances",
]

FloatArray = NDArray[np.float64]

#: Newton iterations of the point-to-ellipsoid distance.
_N_NEWTON = 8


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
    by Newton's method on the Lagrange multiplier (``docs/reachable_sets.md``); degenerate
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

    Examples:
        An ellipsoid heading north (semi-axes 20 m along, 10 m across, 5 m vertical): a
        point 30 m ahead is 10 m outside it, its centre 5 m inside (the smallest axis).

        >>> distance_to_ellipsoid([[30.0, 0, 0], [0, 0, 0]], [0, 0, 0], [20.0, 10, 5], 0.0)
        array([10., -5.])
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
