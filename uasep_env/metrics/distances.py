"""UAV-UAV and UAV-obstacle centre distances over a recorded episode (NED, metres)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["obstacle_distances", "pairwise_uav_distances"]


def pairwise_uav_distances(uav_pos: ArrayLike) -> NDArray[np.float64]:
    """Return UAV-UAV centre distances.

    Args:
        uav_pos: (T, N, 3) positions (m).

    Returns:
        (T, N, N) distances (m), ``+inf`` on the diagonal.
    """
    pos = np.asarray(uav_pos, dtype=np.float64)
    diff = pos[:, :, None, :] - pos[:, None, :, :]
    dist = np.linalg.norm(diff, axis=-1)
    n = pos.shape[1]
    dist[:, np.arange(n), np.arange(n)] = np.inf
    return dist


def obstacle_distances(
    uav_pos: ArrayLike, obstacle_pos: ArrayLike, obstacle_active: ArrayLike
) -> NDArray[np.float64]:
    """Return UAV-obstacle centre distances, ``+inf`` where the obstacle is inactive.

    Args:
        uav_pos: (T, N, 3) UAV positions (m).
        obstacle_pos: (T, M, 3) obstacle positions (m).
        obstacle_active: (T, M) bool.

    Returns:
        (T, N, M) distances (m).
    """
    pos = np.asarray(uav_pos, dtype=np.float64)
    obs = np.asarray(obstacle_pos, dtype=np.float64)
    active = np.asarray(obstacle_active, dtype=bool)
    with np.errstate(invalid="ignore"):
        dist = np.linalg.norm(pos[:, :, None, :] - obs[:, None, :, :], axis=-1)
    return np.where(active[:, None, :], dist, np.inf)
