"""UAV-UAV and UAV-obstacle centre distances over a recorded episode (NED, metres).

The world's own helpers (:mod:`uasep_env.sim.geometry`), so the metrics measure exactly the
distances the world's safety checks use (same summation order, same numbers).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uasep_env.sim.geometry import obstacle_distances, uav_distances

__all__ = ["obstacle_distances", "pairwise_uav_distances"]


def pairwise_uav_distances(uav_pos: ArrayLike) -> NDArray[np.float64]:
    """Return UAV-UAV centre distances.

    Args:
        uav_pos: (T, N, 3) positions (m).

    Returns:
        (T, N, N) distances (m), ``+inf`` on the diagonal.
    """
    return uav_distances(uav_pos, self_distance=np.inf)
