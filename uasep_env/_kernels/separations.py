"""Nearest UAV and obstacle distances: :func:`uasep_env.sim.geometry.nearest_separations`."""

from __future__ import annotations

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _gap, _parallel, frozen


@numba.njit(inline="always", **_JIT)
def _nearest(uav_pos, obstacle_pos, active, e, i):  # noqa: ANN001, ANN202
    """UAV ``i`` of world ``e``: distance to the nearest other UAV and active obstacle."""
    best_uav = np.inf
    for j in range(uav_pos.shape[1]):
        if j != i:
            best_uav = min(best_uav, _gap(uav_pos, e, i, uav_pos, j))
    best_obstacle = np.inf
    for j in range(obstacle_pos.shape[1]):
        if active[e, j]:
            best_obstacle = min(best_obstacle, _gap(uav_pos, e, i, obstacle_pos, j))
    return best_uav, best_obstacle


@numba.njit(inline="always", **_JIT)
def _separation_row(k, uav_pos, obstacle_pos, active, d_uav, d_obstacle):  # noqa: ANN001, ANN202
    n = uav_pos.shape[1]
    e = k // n
    i = k % n
    d_uav[e, i], d_obstacle[e, i] = _nearest(uav_pos, obstacle_pos, active, e, i)


@numba.njit(**_JIT)
def _separations_serial(uav_pos, obstacle_pos, active, d_uav, d_obstacle):  # noqa: ANN001, ANN202
    for k in range(d_uav.size):
        _separation_row(k, uav_pos, obstacle_pos, active, d_uav, d_obstacle)


@numba.njit(parallel=True, **_JIT)
def _separations_parallel(uav_pos, obstacle_pos, active, d_uav, d_obstacle):  # noqa: ANN001, ANN202
    for k in numba.prange(d_uav.size):
        _separation_row(k, uav_pos, obstacle_pos, active, d_uav, d_obstacle)


def separations(
    uav_pos: np.ndarray, obstacle_pos: np.ndarray, active: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled :meth:`uasep_env.sim.world.World.separations`: nearest UAV and obstacle distances.

    Args:
        uav_pos: ``(E, N, 3)`` positions (m).
        obstacle_pos: ``(E, M, 3)`` obstacle positions (m).
        active: ``(E, M)`` bool, which obstacles count.

    Returns:
        ``(E, N)`` distance to the nearest other UAV and to the nearest active obstacle (m),
        ``inf`` where there is none.
    """
    e, n, _ = uav_pos.shape
    d_uav = np.empty((e, n))
    d_obstacle = np.empty((e, n))
    fn = _separations_parallel if _parallel(d_uav.size) else _separations_serial
    fn(frozen(uav_pos), frozen(obstacle_pos), frozen(active), d_uav, d_obstacle)
    return d_uav, d_obstacle
