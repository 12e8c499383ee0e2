"""WGS-84 geodesy: geodetic coordinates to local north-east-down (NED) metres.

A local tangent plane about an origin: geodetic (latitude, longitude, height) -> Earth-centred
Earth-fixed (ECEF, WGS-84 ellipsoid) -> east-north-up about the origin -> NED. Exact (no
flat-Earth approximation); over the 100 km of a track the tangent plane's "down" departs from
the local vertical by under 1 degree, which is the usual meaning of a local NED frame.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FEET", "KNOT", "WGS84_A", "WGS84_F", "ecef", "ned_about", "ned_rotation"]

#: WGS-84 semi-major axis (m) and flattening.
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)
#: One foot (m) and one knot (m/s).
FEET = 0.3048
KNOT = 1852.0 / 3600.0


def ecef(lat_deg: ArrayLike, lon_deg: ArrayLike, height_m: ArrayLike) -> NDArray[np.float64]:
    """ECEF coordinates (m), ``(..., 3)``, of geodetic points on the WGS-84 ellipsoid.

    Args:
        lat_deg: Geodetic latitude (degrees).
        lon_deg: Longitude (degrees).
        height_m: Height above the ellipsoid (m).
    """
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    h = np.asarray(height_m, dtype=np.float64)
    s, c = np.sin(lat), np.cos(lat)
    n = WGS84_A / np.sqrt(1.0 - _E2 * s * s)  # prime vertical radius of curvature
    return np.stack(
        [(n + h) * c * np.cos(lon), (n + h) * c * np.sin(lon), (n * (1.0 - _E2) + h) * s], axis=-1
    )


def ned_rotation(lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray[np.float64]:
    """``(..., 3, 3)`` rotation taking ECEF vectors to NED at the given points (rows N, E, D)."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    north = np.stack([-sl * co, -sl * so, cl], axis=-1)
    east = np.stack([-so, co, np.zeros_like(so)], axis=-1)
    down = np.stack([-cl * co, -cl * so, -sl], axis=-1)
    return np.stack([north, east, down], axis=-2)


def ned_about(
    lat_deg: ArrayLike,
    lon_deg: ArrayLike,
    height_m: ArrayLike,
    origin: tuple[float, float, float],
) -> NDArray[np.float64]:
    """NED positions (m), ``(..., 3)``, of geodetic points about ``origin`` (lat, lon, height).

    Args:
        lat_deg: Geodetic latitudes (degrees).
        lon_deg: Longitudes (degrees).
        height_m: Heights (m).
        origin: The tangent point ``(lat_deg, lon_deg, height_m)``; it maps to ``(0, 0, 0)``.
    """
    lat0, lon0, h0 = origin
    d = ecef(lat_deg, lon_deg, height_m) - ecef(lat0, lon0, h0)
    return d @ ned_rotation(lat0, lon0).T
