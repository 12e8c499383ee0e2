"""Plot coordinates and the reachable ellipsoid's shapes, for frames and figures alike.

Plots use east as the horizontal axis, north as the vertical one and altitude ``-z`` (the
simulator's frame is NED): :func:`enu`. A reachable ellipsoid is drawn by mapping points of
the unit sphere in its body frame (longitudinal along the heading, lateral to the right,
vertical) onto it: :func:`ellipsoid_points`, which the surface grid, the meshes and the
horizontal outline all go through.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "SPHERE_LINES",
    "SPHERE_QUADS",
    "ellipse_outline",
    "ellipsoid_points",
    "ellipsoid_surface",
    "enu",
    "unit_ring",
]


def enu(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(east, north, altitude)`` of NED points ``(..., 3)``."""
    return p[..., 1], p[..., 0], -p[..., 2]


def ellipsoid_points(
    unit: np.ndarray, center: np.ndarray, axes: np.ndarray, heading: float
) -> np.ndarray:
    """Map body-frame unit points onto a reachable ellipsoid, in plot coordinates.

    Args:
        unit: ``(..., 3)`` points ``u`` in the ellipsoid's body frame (longitudinal along the
            heading, lateral to the right, vertical), on the unit sphere.
        center: ``(3,)`` the ellipsoid's centre (m, NED).
        axes: ``(3,)`` its semi-axes (longitudinal, lateral, vertical) (m).
        heading: Its heading (rad from north towards east).

    Returns:
        ``(..., 3)`` points as ``(east, north, altitude)`` (m).
    """
    lon, lat, vert = unit[..., 0] * axes[0], unit[..., 1] * axes[1], unit[..., 2] * axes[2]
    ch, sh = math.cos(heading), math.sin(heading)
    north = center[0] + lon * ch - lat * sh
    east = center[1] + lon * sh + lat * ch
    alt = -(center[2] + vert)
    return np.stack([east, north, alt], axis=-1)


def unit_ring(n: int) -> np.ndarray:
    """``n`` points of the unit circle in the horizontal body plane (closed), ``(n, 3)``."""
    u = np.linspace(0.0, 2.0 * math.pi, n)
    return np.stack([np.cos(u), np.sin(u), np.zeros(n)], axis=1)


def _unit_sphere_wireframe(n_meridians: int = 6, n_parallels: int = 5) -> np.ndarray:
    """Points of a unit-sphere wireframe, curves separated by NaN rows, ``(K, 3)``."""
    t = np.linspace(0.0, 2.0 * math.pi, 37)
    curves = []
    for k in range(n_meridians):  # great circles through the poles
        lon = math.pi * k / n_meridians
        curves.append(
            np.stack([np.cos(t) * math.cos(lon), np.cos(t) * math.sin(lon), np.sin(t)], 1)
        )
    for lat in np.linspace(-math.pi / 2, math.pi / 2, n_parallels + 2)[1:-1]:
        curves.append(
            np.stack(
                [
                    np.cos(t) * math.cos(lat),
                    np.sin(t) * math.cos(lat),
                    np.full_like(t, math.sin(lat)),
                ],
                1,
            )
        )
    nan = np.full((1, 3), np.nan)
    return np.concatenate([np.concatenate([c, nan]) for c in curves])[:-1]


def _unit_sphere_quads(n_lon: int = 16, n_lat: int = 8) -> np.ndarray:
    """Quadrilaterals tiling the unit sphere, ``(n_lon * n_lat, 4, 3)``."""
    lon = np.linspace(0.0, 2.0 * math.pi, n_lon + 1)
    lat = np.linspace(-math.pi / 2, math.pi / 2, n_lat + 1)
    lo, la = np.meshgrid(lon, lat, indexing="ij")
    pts = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)
    quads = np.stack([pts[:-1, :-1], pts[1:, :-1], pts[1:, 1:], pts[:-1, 1:]], axis=2)
    return quads.reshape(-1, 4, 3)


#: Wireframe of the unit sphere (curves separated by NaN rows), for the live frames.
SPHERE_LINES = _unit_sphere_wireframe()
#: Quadrilaterals tiling the unit sphere, for the live frames' translucent surface.
SPHERE_QUADS = _unit_sphere_quads()


def ellipsoid_surface(
    center: np.ndarray, axes: np.ndarray, heading: float, n_lon: int = 33, n_lat: int = 17
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid of points on a heading-aligned ellipsoid, in plot coordinates.

    Args:
        center: ``(3,)`` centre (m, NED).
        axes: ``(3,)`` semi-axes (longitudinal along the heading, lateral to the right,
            vertical) (m).
        heading: Heading (rad from north towards east).
        n_lon: Grid points around the vertical axis.
        n_lat: Grid points from pole to pole.

    Returns:
        ``(east, north, altitude)`` arrays of shape ``(n_lat, n_lon)`` (m).
    """
    u = np.linspace(0.0, 2.0 * math.pi, n_lon)
    v = np.linspace(0.0, math.pi, n_lat)
    unit = np.stack(
        [
            np.outer(np.sin(v), np.cos(u)),
            np.outer(np.sin(v), np.sin(u)),
            np.outer(np.cos(v), np.ones_like(u)),
        ],
        axis=-1,
    )
    pts = ellipsoid_points(unit, center, axes, heading)
    return pts[..., 0], pts[..., 1], pts[..., 2]


def ellipse_outline(
    center: np.ndarray, axes: np.ndarray, heading: float, n: int = 97
) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal section through the centre, as ``(east, north)``."""
    pts = ellipsoid_points(unit_ring(n), center, axes, heading)
    return pts[:, 0], pts[:, 1]
