"""A step's outcome, read off the world just stepped: rewards, episode ends, safety, costs.

:func:`step_outcome` is what :meth:`uasep_env.envs.core.EnvCore.step` needs after the world
moved, in one call: the reward terms and their weighted sum (:mod:`uasep_env.interface.rewards`),
each UAV's collision and lost tests (the episode ends), the safety flags of the step and the
costs weighted from them (:mod:`uasep_env.interface.costs`). Its numpy reference composes those
modules' functions; its compiled twin (``_kernels.rewards.step_outcome``) computes it all in
one pass over the agents, so that a small batch's step does not pay a dozen numpy calls
for it.
"""

from __future__ import annotations

import functools
from collections import namedtuple
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config import CostWeights
from uasep_env.interface.costs import SAFETY_FLAGS, weighted_cost
from uasep_env.interface.costs import TERMS as COST_TABLE
from uasep_env.interface.rewards import (
    _TERM_INDEX,
    _collided,
    _Constants,
    _gather_inputs,
    _Inputs,
    _vectors,
    _weighted_terms,
)

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig
    from uasep_env.sim.world import World

__all__ = [
    "SAFETY_FLAGS",
    "Outcome",
    "OutcomeConstants",
    "compute_outcome",
    "outcome_constants",
    "step_outcome",
]

# SAFETY_FLAGS (re-exported here): the step's safety flags :func:`step_outcome` computes, in
# the order of its ``flags`` rows, derived from the cost table (uasep_env.interface.costs).
#: Each flag's row in the ``(F, E, N)`` flags array, by name (the kernel writes
#: ``flags[fx.<name>, e, i]``, never a literal row, into an array of ``len(_FLAG_INDEX)`` rows).
_FLAG_INDEX = namedtuple("FlagIndex", SAFETY_FLAGS)(*range(len(SAFETY_FLAGS)))


class Outcome(NamedTuple):
    """What :func:`step_outcome` returns (``E`` environments, ``N`` UAVs).

    Attributes:
        own: ``(E, N)`` each agent's weighted reward, before any team sharing.
        terms: ``(T, E, N)`` the unweighted reward terms, in ``REWARD_TERMS`` order.
        d_region: ``(E, N)`` distance to the nearest reachable region (m), ``inf`` if none.
        collided: ``(E, N)`` bool, a collision during the step.
        lost: ``(E, N)`` bool, farther than ``uav.lost_distance`` from the plan.
        flags: ``(F, E, N)`` bool, the :data:`SAFETY_FLAGS`.
        cost: ``(E, N)`` the weighted cost.
        cost_terms: ``(C, E, N)`` float64 cost terms (0 or 1), in ``COST_TERMS`` order.
    """

    own: np.ndarray
    terms: np.ndarray
    d_region: np.ndarray
    collided: np.ndarray
    lost: np.ndarray
    flags: np.ndarray
    cost: np.ndarray
    cost_terms: np.ndarray


class OutcomeConstants(NamedTuple):
    """The constants of :func:`step_outcome` besides the reward terms' own.

    Attributes:
        lost_sq: ``uav.lost_distance ** 2`` (m^2).
        cost_weights: ``(C,)`` each cost term's weight.
        cost_flags: ``(C,)`` int64, each cost term's row of :data:`SAFETY_FLAGS`.
    """

    lost_sq: float
    cost_weights: np.ndarray
    cost_flags: np.ndarray


@functools.lru_cache(maxsize=64)
def outcome_constants(lost_distance: float, weights: CostWeights) -> OutcomeConstants:
    """The :class:`OutcomeConstants` of a config (read-only arrays; configs are frozen)."""
    cost_weights = np.array([getattr(weights, t.name) for t in COST_TABLE], dtype=np.float64)
    cost_flags = np.array([SAFETY_FLAGS.index(t.safety) for t in COST_TABLE], dtype=np.int64)
    for a in (cost_weights, cost_flags):
        a.flags.writeable = False
    return OutcomeConstants(float(lost_distance) ** 2, cost_weights, cost_flags)


def _flag_values(x: _Inputs, c: _Constants, d_region: np.ndarray) -> dict[str, np.ndarray]:
    """Each safety flag of :data:`SAFETY_FLAGS` by name, ``(E, N)`` bool (numpy reference)."""
    return {
        "loss_of_separation_uav": x.min_uav_dist < c.separation_distance,
        "loss_of_separation_obstacle": x.min_obstacle_dist < c.obstacle_separation,
        "in_reachable_region": d_region < 0.0,
    }


@compiled_twin("step_outcome", index=_TERM_INDEX, flag_index=_FLAG_INDEX, result=Outcome)
def step_outcome(x: _Inputs, c: _Constants, w: np.ndarray, o: OutcomeConstants) -> Outcome:
    """The reward terms, episode-end tests, safety flags and costs of a step.

    Args:
        x: The world's arrays the reward terms read
            (:func:`uasep_env.interface.rewards._gather_inputs`).
        c: The reward terms' constants.
        w: One reward weight per term.
        o: The other constants.

    Returns:
        The :class:`Outcome`.
    """
    own, terms = _weighted_terms.reference(x, c, w)
    d_region = x.region.min(axis=-1, initial=np.inf)
    collided = _collided(x.min_uav_dist, x.min_obstacle_dist, c.collision_distance)
    off = x.uav_pos - x.plan_pos
    lost = np.einsum("eni,eni->en", off, off) > o.lost_sq
    values = _flag_values(x, c, d_region)
    flags = np.stack([values[name] for name in SAFETY_FLAGS])
    cost_terms = flags[o.cost_flags].astype(np.float64)
    cost = weighted_cost(list(cost_terms), list(o.cost_weights))
    return Outcome(own, terms, d_region, collided, lost, flags, cost, cost_terms)


def compute_outcome(world: World, config: EnvConfig, region: np.ndarray) -> Outcome:
    """:func:`step_outcome` of the world just stepped.

    Args:
        world: The batched world.
        config: Its configuration (the reward and cost weights, the UAVs' distances).
        region: ``(E, N, M)`` the true positions' region distances (m).
    """
    cached = _LAST[0]
    if cached is None or cached[0] is not config:  # configs are frozen: one look-up each
        w, c = _vectors(config.reward, config.uav, config.max_steps)
        cached = (config, c, w, outcome_constants(config.uav.lost_distance, config.cost))
        _LAST[0] = cached  # one tuple, replaced whole: a reader never sees a mix of two
    return step_outcome(_gather_inputs(world, region), *cached[1:])


#: The last config's constants (a config's step after step; the lru caches behind it hash
#: each config's fields again on every call).
_LAST: list[tuple | None] = [None]
