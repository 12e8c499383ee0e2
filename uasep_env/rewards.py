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

import functools
from typing import NamedTuple

import numpy as np

from uasep_env import _numba
from uasep_env.config import RewardWeights, UAVConfig
from uasep_env.world import World

__all__ = ["DEVIATION_SCALE_M", "REWARD_TERMS", "collisions", "compute_rewards", "team_mean"]

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


def team_mean(x: np.ndarray) -> np.ndarray:
    """``x.mean(axis=-1)``: the mean over the UAVs of ``(..., N)`` values.

    The same numbers (numpy adds fewer than 8 values in order), but a few whole-array adds
    rather than one short reduction per row, which is slow for large batches.
    """
    n = x.shape[-1]
    if n >= 8:
        return x.mean(axis=-1)
    total = x[..., 0].copy()
    for j in range(1, n):
        total += x[..., j]
    total /= n
    return total


def collisions(world: World) -> np.ndarray:
    """``(E, N)`` whether each UAV collided during the last step (true state)."""
    return _collided(world.min_uav_dist, world.min_obs_dist, world.config.uav.collision_distance)


def _collided(d_uav: np.ndarray, d_obs: np.ndarray, d_col: float) -> np.ndarray:
    return (d_uav < d_col) | (d_obs < d_col)


class _Inputs(NamedTuple):
    """The world's arrays the reward terms are computed from (``E`` envs, ``N`` UAVs)."""

    uav_pos: np.ndarray  # (E, N, 3) true positions (m)
    plan_pos: np.ndarray  # (E, N, 3) planned positions (m)
    cmd: np.ndarray  # (E, N, 3) commanded accelerations (m/s^2)
    prev_cmd: np.ndarray  # (E, N, 3) the previous command (m/s^2)
    min_uav_dist: np.ndarray  # (E, N) closest UAV over the step (m)
    min_obs_dist: np.ndarray  # (E, N) closest obstacle centre over the step (m)
    region: np.ndarray  # (E, N, M) signed distance to each reachable ellipsoid (m), inf if off


def compute_rewards(
    world: World, weights: RewardWeights, region: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Rewards and their named terms after a step.

    The terms and their weighted sum are :func:`_terms`, or its compiled form in
    :mod:`uasep_env._kernels` when numba is in use (the same numbers bit for bit).

    Args:
        world: The batched world, just stepped.
        weights: Term weights and the shared fraction.
        region: Optional precomputed ``(E, N, M)`` true region distances (m).

    Returns:
        ``(rewards, terms)``: ``(E, N)`` rewards and a dict of ``(E, N)`` unweighted terms.
    """
    x = _Inputs(
        world.uav_pos,
        world.plan_pos,
        world.accel_cmd,
        world.prev_accel_cmd,
        world.min_uav_dist,
        world.min_obs_dist,
        world.region_distances() if region is None else region,
    )
    u = world.config.uav
    w, c = _vectors(weights, u)
    if (_kernels := _numba.kernels()) is not None:
        own, stacked = _kernels.reward_terms(x, c, w)
        terms = dict(zip(REWARD_TERMS, stacked, strict=True))
    else:
        terms = _terms(x, u)
        own = np.zeros_like(x.min_uav_dist)
        for k, name in enumerate(REWARD_TERMS):
            own += w[k] * terms[name]
    if weights.shared > 0.0:
        own = (1.0 - weights.shared) * own + weights.shared * team_mean(own)[:, None]
    return own, terms


@functools.lru_cache(maxsize=64)
def _vectors(weights: RewardWeights, u: UAVConfig) -> tuple[np.ndarray, np.ndarray]:
    """The weights in term order and the kernel's constants (read-only; configs are frozen)."""
    w = np.array([getattr(weights, name) for name in REWARD_TERMS])
    c = np.array(
        [
            u.max_accel,
            u.separation_distance,
            u.obstacle_separation,
            u.collision_distance,
            DEVIATION_SCALE_M,
        ]
    )
    w.flags.writeable = c.flags.writeable = False
    return w, c


def _terms(x: _Inputs, u: UAVConfig) -> dict[str, np.ndarray]:
    """The unweighted terms in numpy (the reference of the compiled form)."""
    d_region = x.region.min(axis=-1, initial=np.inf)
    dev = np.linalg.norm(x.uav_pos - x.plan_pos, axis=-1)
    cmd = x.cmd / u.max_accel
    dcmd = (x.cmd - x.prev_cmd) / u.max_accel
    return {
        "separation_inner": -(np.maximum(0.0, 1.0 - x.min_uav_dist / u.separation_distance) ** 2),
        "separation_obstacle": -(
            np.maximum(0.0, 1.0 - x.min_obs_dist / u.obstacle_separation) ** 2
        ),
        "separation_region": -np.minimum(
            2.0, np.maximum(0.0, 1.0 - d_region / u.obstacle_separation)
        ),
        "deviation": -np.minimum(10.0, dev / DEVIATION_SCALE_M),
        "control": -np.einsum("...i,...i->...", cmd, cmd) / 3.0,
        "smoothness": -np.einsum("...i,...i->...", dcmd, dcmd) / 3.0,
        "collision": -_collided(x.min_uav_dist, x.min_obs_dist, u.collision_distance).astype(float),
        "progress": np.ones_like(x.min_uav_dist),
    }
