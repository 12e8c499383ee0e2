"""Named reward terms, combined by typed weights (:class:`uasep_env.config.RewardWeights`).

Every term is computed per agent from the true state after the step, reported by the
environments in ``infos[agent]["reward_terms"]``, and combined as
``own_i = sum_k weight_k * term_k``; ``reward_i = (1 - shared) * own_i + shared * mean_j own_j``.

=========================  ===========================================================
Term                       Value per agent (unweighted)
=========================  ===========================================================
``separation_inner``       ``-max(0, 1 - d_uav / d_sep)^2``: closest UAV over the step
                           (``d_sep`` = ``uav.separation_distance``); 0 when separated
``separation_obstacle``    ``-max(0, 1 - d_obs / d_obs_sep)^2``: closest obstacle centre
                           over the step (``d_obs_sep`` = ``uav.obstacle_separation``)
``separation_region``      ``-min(2, max(0, 1 - d_region / d_obs_sep))``: signed distance
                           to the nearest predicted reachable ellipsoid; grows as the UAV
                           moves towards and into the region
``deviation``              ``-min(10, |p - p_planned| / 10 m)``: distance from the planned
                           position
``control``                ``-|a_cmd / a_max|^2 / 3``: control effort
``smoothness``             ``-|(a_cmd - a_cmd_prev) / a_max|^2 / 3``: change of command
``collision``              ``-1`` when the UAV came within ``uav.collision_distance`` of
                           another UAV or an obstacle during the step, else 0
``progress``               ``+1`` per step (alive bonus; weight 0 by default)
=========================  ===========================================================
"""

from __future__ import annotations

import numpy as np

from uasep_env.config import RewardWeights
from uasep_env.world import World

__all__ = ["DEVIATION_SCALE_M", "REWARD_TERMS", "collisions", "compute_rewards"]

#: Names of the reward terms, in reporting order.
REWARD_TERMS = (
    "separation_inner",
    "separation_obstacle",
    "separation_region",
    "deviation",
    "control",
    "smoothness",
    "collision",
    "progress",
)
#: Deviation (m) that costs one unit of the deviation term.
DEVIATION_SCALE_M = 10.0


def collisions(world: World) -> np.ndarray:
    """``(E, N)`` whether each UAV collided during the last step (true state)."""
    d_col = world.config.uav.collision_distance
    return (world.min_uav_dist < d_col) | (world.min_obs_dist < d_col)


def compute_rewards(
    world: World, weights: RewardWeights, region: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Rewards and their named terms after a step.

    Args:
        world: The batched world, just stepped.
        weights: Term weights and the shared fraction.
        region: Optional precomputed ``(E, N, M)`` true region distances (m).

    Returns:
        ``(rewards, terms)``: ``(E, N)`` rewards and a dict of ``(E, N)`` unweighted terms.
    """
    cfg = world.config
    u = cfg.uav
    plan_pos, _ = world.planned()
    if region is None:
        region = world.region_distances()
    d_region = region.min(axis=-1, initial=np.inf)
    dev = np.linalg.norm(world.uav_pos - plan_pos, axis=-1)
    cmd = world.accel_cmd / u.max_accel
    dcmd = (world.accel_cmd - world.prev_accel_cmd) / u.max_accel
    terms = {
        "separation_inner": -(
            np.maximum(0.0, 1.0 - world.min_uav_dist / u.separation_distance) ** 2
        ),
        "separation_obstacle": -(
            np.maximum(0.0, 1.0 - world.min_obs_dist / u.obstacle_separation) ** 2
        ),
        "separation_region": -np.minimum(
            2.0, np.maximum(0.0, 1.0 - d_region / u.obstacle_separation)
        ),
        "deviation": -np.minimum(10.0, dev / DEVIATION_SCALE_M),
        "control": -np.einsum("...i,...i->...", cmd, cmd) / 3.0,
        "smoothness": -np.einsum("...i,...i->...", dcmd, dcmd) / 3.0,
        "collision": -collisions(world).astype(float),
        "progress": np.ones((world.n_envs, world.n_uavs)),
    }
    own = np.zeros((world.n_envs, world.n_uavs))
    for name in REWARD_TERMS:
        own += getattr(weights, name) * terms[name]
    if weights.shared > 0.0:
        own = (1.0 - weights.shared) * own + weights.shared * own.mean(axis=1, keepdims=True)
    return own, terms
