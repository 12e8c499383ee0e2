"""Named reward terms, combined by typed weights (:class:`uasep_env.config.RewardWeights`).

Every term is computed per agent from the true state after the step, reported by the
environments in ``infos[agent]["reward_terms"]``, and combined as
``own_i = sum_k weight_k * term_k``; ``reward_i = (1 - shared) * own_i + shared * mean_j own_j``.

=========================  ===========================================================
Term                       Value per agent (unweighted)
=========================  ===========================================================
``separation_inner``       ``-max(0, 1 - d_uav / d_sep)^2``: closest UAV over the step
                           (``d_sep`` = ``uav.separation_distance``); 0 when separated
``separation_obstacle``    ``-max(0, 1 - d_obstacle / d_osep)^2``: closest obstacle
                           centre over the step (``d_osep`` = ``uav.obstacle_separation``)
``separation_region``      ``-min(2, max(0, 1 - d_region / d_osep))``: signed distance
                           to the nearest predicted reachable ellipsoid; grows as the UAV
                           moves towards and into the region
``deviation``              ``-d / (d + s)``, ``d = |p - p_planned|``, ``s`` =
                           ``reward.deviation_scale`` (20 m): in ``(-1, 0]``,
                           steepest near the plan and still sloped 100 m off it
``control``                ``-|a_cmd / a_max|^2 / 3``: control effort
``smoothness``             ``-|(a_cmd - a_cmd_prev) / a_max|^2 / 3``: change of command
                           (down to -4, a full reversal on every axis)
``collision``              ``-T`` (``T`` = ``max_steps``, the episode's step budget) for
                           every UAV of an environment in which a UAV came within
                           ``uav.collision_distance`` of another UAV or an obstacle
                           during the step, else 0: the collision ends the episode for
                           the whole formation, and so costs each of its UAVs
``progress``               ``+1`` per step (alive bonus)
=========================  ===========================================================

Why these defaults (:class:`~uasep_env.config.RewardWeights`): the reward is learnable by
construction, and its optimum is what the paper wants (fly the plan, keep separation,
never collide).

* Every step alive pays ``progress`` (+1) minus penalties that sum to at most 1:
  obstacle separation 0.4, inner separation 0.25 and deviation 0.2 (terms in ``[-1, 0]``),
  region 0.05 (term in ``[-2, 0]``) and smoothness 0.0125 (``[-4, 0]``: a full reversal on
  every axis); control 0. So a step's reward is in ``[0, 1]``.
* Separation outweighs deviation. With the separation terms at a quarter of the weights
  (and deviation at 0.4), PPO learned to keep the formation (16-19 m max deviation) but
  to lose separation in 65-70 % of the episodes (the quadratic terms cost little just
  inside the thresholds), and a residual on the APF learned to cancel its avoidance
  (``train/README.md``).
  Ending an episode early therefore never pays: the earlier design (penalties only, up to
  -10 a step, a -10 collision) made the earliest collision the optimum, and PPO with
  return normalisation learned exactly that.
* A collision costs ``T``, the whole episode's worth of steps, to every UAV of the
  formation (it ends the episode for all of them, and a UAV-obstacle collision involves
  only one UAV). An episode that ends in a collision at any step ``k`` returns at most
  ``k - T <= 0``, for each agent and for the team; a collision-free one returns at least
  0, and more than 0 when its deviation stays bounded
  (``tests/test_rewards.py::test_collision_never_pays``).
* The deviation term saturates (``(-1, 0]``) so a policy far off the plan is not paid to
  end the episode, but keeps a slope at any distance, so a policy that has drifted still
  sees which way the plan is. Its scale, 20 m, is that of the APF's manoeuvres; at 100 m
  the slope is 1/36 of its value on the plan, so a policy that has drifted that far is paid
  little to come back. ``reward.deviation_scale`` (e.g. 200 m: 0.44 of it at 100 m) keeps
  more of the slope there, still in ``(-1, 0]``.

The task reward of constrained training, ``make_config(reward="task")``
(:meth:`RewardWeights.task() <uasep_env.config.RewardWeights.task>`), keeps only the task:
the default weights of ``deviation``, ``control``, ``smoothness`` and ``progress``, and no
separation, region or collision term; safety is the cost channel's
(:mod:`uasep_env.interface.costs`), bounded as a constraint (:mod:`uasep_env.training.lagrangian`).
From the term table (:func:`step_reward_bounds`) a step alive earns between 0.75 and 1 (the default
weights: between 0 and 1), so ending an episode early never pays there either.
"""

from __future__ import annotations

import functools
from collections import namedtuple
from typing import NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config import RewardWeights, UAVConfig
from uasep_env.sim.world import World

__all__ = [
    "DEVIATION_SCALE_M",
    "REGION_TERM_CAP",
    "REWARD_TERMS",
    "TERMS",
    "RewardTerm",
    "collisions",
    "compute_rewards",
    "step_reward_bounds",
    "team_mean",
    "term_bounds",
]

#: Deviation (m) at which the deviation term is -1/2 (it tends to -1 far off the plan): the
#: default of ``reward.deviation_scale``.
DEVIATION_SCALE_M = 20.0
#: Cap of the region term's intrusion depth (units of ``uav.obstacle_separation``).
REGION_TERM_CAP = 2.0


class RewardTerm(NamedTuple):
    """One row of the term table.

    Attributes:
        name: The term's name (a field of :class:`~uasep_env.config.RewardWeights` too).
        low: Least value of the unweighted term in one step.
        high: Greatest value of the unweighted term in one step.
        per_episode: Whether ``low`` and ``high`` are in units of ``max_steps`` (the
            collision term costs the whole episode's budget).
    """

    name: str
    low: float
    high: float
    per_episode: bool = False


#: The reward terms, in reporting order, with their per-step bounds: the one list the
#: numpy terms (:func:`_term_values`), the compiled kernel's term indices
#: (:data:`_TERM_INDEX`), the weights and the tests read.
TERMS: tuple[RewardTerm, ...] = (
    RewardTerm("separation_inner", -1.0, 0.0),
    RewardTerm("separation_obstacle", -1.0, 0.0),
    RewardTerm("separation_region", -REGION_TERM_CAP, 0.0),
    RewardTerm("deviation", -1.0, 0.0),
    RewardTerm("control", -1.0, 0.0),  # each axis of the command is within max_accel
    RewardTerm("smoothness", -4.0, 0.0),  # a full reversal on every axis
    RewardTerm("collision", -1.0, 0.0, per_episode=True),
    RewardTerm("progress", 1.0, 1.0),
)
#: Names of the reward terms, in reporting order.
REWARD_TERMS: tuple[str, ...] = tuple(t.name for t in TERMS)
#: Each term's row in the kernel's ``(T, E, N)`` terms array, by name (the kernel writes
#: ``terms[index.<name>, e, i]``, never a literal row).
_TERM_INDEX = namedtuple("TermIndex", REWARD_TERMS)(*range(len(REWARD_TERMS)))


def term_bounds(max_steps: int) -> dict[str, tuple[float, float]]:
    """Each term's ``(low, high)`` per step for an episode of ``max_steps`` steps."""
    return {
        t.name: (t.low * max_steps, t.high * max_steps) if t.per_episode else (t.low, t.high)
        for t in TERMS
    }


def step_reward_bounds(weights: RewardWeights) -> tuple[float, float]:
    """Least and greatest reward of a step without a collision, from the term table.

    Every per-step term (not the per-episode collision term) at the end of its bounds that
    minimises (maximises) its weighted value, summed: an agent's own reward, and so (a mean
    of such rewards) also its shared one.

    Args:
        weights: The term weights.

    Returns:
        ``(low, high)``: ``(0, 1)`` for the default weights, ``(0.75, 1)`` for
        :meth:`RewardWeights.task() <uasep_env.config.RewardWeights.task>`.
    """
    low = high = 0.0
    for t in TERMS:
        if t.per_episode:
            continue
        w = getattr(weights, t.name)
        low += min(w * t.low, w * t.high)
        high += max(w * t.low, w * t.high)
    return low, high


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
    return _collided(
        world.min_uav_dist, world.min_obstacle_dist, world.config.uav.collision_distance
    )


def _collided(d_uav: np.ndarray, d_obstacle: np.ndarray, d_col: float) -> np.ndarray:
    return (d_uav < d_col) | (d_obstacle < d_col)


class _Inputs(NamedTuple):
    """The world's arrays the reward terms are computed from (``E`` envs, ``N`` UAVs).

    Built in one place, :func:`_gather_inputs`, by keyword.
    """

    uav_pos: np.ndarray  # (E, N, 3) true positions (m)
    plan_pos: np.ndarray  # (E, N, 3) planned positions (m)
    cmd: np.ndarray  # (E, N, 3) commanded accelerations (m/s^2)
    prev_cmd: np.ndarray  # (E, N, 3) the previous command (m/s^2)
    min_uav_dist: np.ndarray  # (E, N) closest UAV over the step (m)
    min_obstacle_dist: np.ndarray  # (E, N) closest obstacle centre over the step (m)
    region: np.ndarray  # (E, N, M) signed distance to each reachable ellipsoid (m), inf if off


class _Constants(NamedTuple):
    """The scalars the terms use: the config's, :data:`DEVIATION_SCALE_M` and the cap."""

    max_accel: float  # m/s^2
    separation_distance: float  # m
    obstacle_separation: float  # m
    collision_distance: float  # m
    deviation_scale: float  # m, reward.deviation_scale (DEVIATION_SCALE_M by default)
    region_cap: float  # the region term's bound, REGION_TERM_CAP
    max_steps: float  # the collision term's magnitude


def compute_rewards(
    world: World, weights: RewardWeights, region: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Rewards and their named terms after a step.

    The terms and their weighted sum are :func:`_weighted_terms` (compiled when numba is
    in use, the same numbers bit for bit).

    Args:
        world: The batched world, just stepped.
        weights: Term weights and the shared fraction.
        region: Optional precomputed ``(E, N, M)`` true region distances (m).

    Returns:
        ``(rewards, terms)``: ``(E, N)`` rewards and a dict of ``(E, N)`` unweighted terms.
    """
    x = _gather_inputs(world, region)
    w, c = _vectors(weights, world.config.uav, world.config.max_steps)
    own, stacked = _weighted_terms(x, c, w)
    return share_rewards(own, weights), dict(zip(REWARD_TERMS, stacked, strict=True))


def share_rewards(own: np.ndarray, weights: RewardWeights) -> np.ndarray:
    """``(E, N)`` rewards: each agent's own, or with the team's mean mixed in (``shared``)."""
    if weights.shared > 0.0:
        return (1.0 - weights.shared) * own + weights.shared * team_mean(own)[:, None]
    return own


def _gather_inputs(world: World, region: np.ndarray | None = None) -> _Inputs:
    """The world's arrays the terms read (``region``: precomputed true region distances)."""
    f = world.frozen_inputs()
    return _Inputs(
        uav_pos=f["uav_pos"],
        plan_pos=world.plan_pos,
        cmd=f["accel_cmd"],
        prev_cmd=f["prev_accel_cmd"],
        min_uav_dist=f["min_uav_dist"],
        min_obstacle_dist=f["min_obstacle_dist"],
        region=world.region_distances() if region is None else region,
    )


@functools.lru_cache(maxsize=64)
def _vectors(weights: RewardWeights, u: UAVConfig, max_steps: int) -> tuple[np.ndarray, _Constants]:
    """The weights in term order (read-only) and the constants (configs are frozen)."""
    w = np.array([getattr(weights, name) for name in REWARD_TERMS])
    w.flags.writeable = False
    c = _Constants(
        max_accel=u.max_accel,
        separation_distance=u.separation_distance,
        obstacle_separation=u.obstacle_separation,
        collision_distance=u.collision_distance,
        deviation_scale=weights.deviation_scale,
        region_cap=-TERMS[REWARD_TERMS.index("separation_region")].low,
        max_steps=float(max_steps),
    )
    return w, c


@compiled_twin("reward_terms", index=_TERM_INDEX)
def _weighted_terms(x: _Inputs, c: _Constants, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unweighted terms and their weighted sum, before any team sharing.

    Args:
        x: The world's arrays.
        c: The constants.
        w: One weight per term, in :data:`REWARD_TERMS` order.

    Returns:
        ``(own, terms)``: ``(E, N)`` weighted sums and ``(T, E, N)`` unweighted terms in
        :data:`REWARD_TERMS` order.
    """
    terms = _term_values(x, c)
    stacked = np.stack([terms[name] for name in REWARD_TERMS])
    own = np.zeros_like(x.min_uav_dist)
    for k in range(len(REWARD_TERMS)):
        own += w[k] * stacked[k]
    return own, stacked


def _term_values(x: _Inputs, c: _Constants) -> dict[str, np.ndarray]:
    """Every term of :data:`TERMS`, by name, ``(E, N)`` each (the numpy reference)."""
    d_region = x.region.min(axis=-1, initial=np.inf)
    dev = np.linalg.norm(x.uav_pos - x.plan_pos, axis=-1)
    cmd = x.cmd / c.max_accel
    dcmd = (x.cmd - x.prev_cmd) / c.max_accel
    collided = _collided(x.min_uav_dist, x.min_obstacle_dist, c.collision_distance)
    d_obstacle = x.min_obstacle_dist
    return {
        "separation_inner": -(np.maximum(0.0, 1.0 - x.min_uav_dist / c.separation_distance) ** 2),
        "separation_obstacle": -(np.maximum(0.0, 1.0 - d_obstacle / c.obstacle_separation) ** 2),
        "separation_region": -np.minimum(
            c.region_cap, np.maximum(0.0, 1.0 - d_region / c.obstacle_separation)
        ),
        "deviation": -(dev / (dev + c.deviation_scale)),
        "control": -np.einsum("...i,...i->...", cmd, cmd) / 3.0,
        "smoothness": -np.einsum("...i,...i->...", dcmd, dcmd) / 3.0,
        "collision": -c.max_steps
        * np.broadcast_to(collided.any(axis=-1, keepdims=True), x.min_uav_dist.shape),
        "progress": np.ones_like(x.min_uav_dist),
    }
