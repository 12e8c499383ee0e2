"""Distances between UAVs and from UAVs to obstacle centres: the one set of helpers.

The world's safety check (:meth:`uasep_env.sim.world.World.separations`), the metrics of a
recorded episode and the figures all measure with these functions, so a distance is the same
number wherever it is reported. The norm is numpy's ``sqrt(einsum("...i,...i"))``, whose
summation order the compiled kernels reproduce (:mod:`uasep_env._kernels`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env._numba import compiled_twin

__all__ = ["nearest_separations", "obstacle_distances", "uav_distances"]

FloatArray = NDArray[np.float64]


def _norm(diff: FloatArray) -> FloatArray:
    return np.sqrt(np.einsum("...i,...i->...", diff, diff))


def uav_distances(uav_pos: ArrayLike, *, self_distance: float = 0.0) -> FloatArray:
    """Distances between the UAVs of each row.

    Args:
        uav_pos: ``(..., N, 3)`` positions (m).
        self_distance: Value on the diagonal (a UAV's distance to itself): 0, or ``inf``
            to exclude it from a minimum.

    Returns:
        ``(..., N, N)`` distances (m).

    Examples:
        >>> uav_distances([[0, 0, 0], [3, 4, 0], [0, 0, 12]])
        array([[ 0.,  5., 12.],
               [ 5.,  0., 13.],
               [12., 13.,  0.]])
    """
    p = np.asarray(uav_pos, dtype=np.float64)
    d = _norm(p[..., :, None, :] - p[..., None, :, :])
    if self_distance != 0.0:
        n = p.shape[-2]
        d[..., np.arange(n), np.arange(n)] = self_distance
    return d


def obstacle_distances(
    uav_pos: ArrayLike, obstacle_pos: ArrayLike, active: ArrayLike
) -> FloatArray:
    """Distances from each UAV to each obstacle centre, ``inf`` for inactive obstacles.

    Args:
        uav_pos: ``(..., N, 3)`` UAV positions (m).
        obstacle_pos: ``(..., M, 3)`` obstacle positions (m).
        active: ``(..., M)`` bool, which obstacles count.

    Returns:
        ``(..., N, M)`` distances (m).
    """
    p = np.asarray(uav_pos, dtype=np.float64)
    o = np.asarray(obstacle_pos, dtype=np.float64)
    on = np.asarray(active, dtype=bool)
    with np.errstate(invalid="ignore"):  # an inactive obstacle may have no position (NaN)
        d = _norm(p[..., :, None, :] - o[..., None, :, :])
    return np.where(on[..., None, :], d, np.inf)


@compiled_twin("separations")
def nearest_separations(
    uav_pos: np.ndarray, obstacle_pos: np.ndarray, active: np.ndarray
) -> tuple[FloatArray, FloatArray]:
    """Each UAV's distance to the nearest other UAV and to the nearest active obstacle.

    Args:
        uav_pos: ``(E, N, 3)`` positions (m).
        obstacle_pos: ``(E, M, 3)`` obstacle positions (m).
        active: ``(E, M)`` bool, which obstacles count.

    Returns:
        ``(uav, obstacle)``, each ``(E, N)`` (m), ``inf`` where there is none.
    """
    d_uav = uav_distances(uav_pos, self_distance=np.inf).min(axis=-1)
    d_obstacle = obstacle_distances(uav_pos, obstacle_pos, active).min(axis=-1, initial=np.inf)
    return d_uav, d_obstacle
