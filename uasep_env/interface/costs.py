"""The cost channel of constrained RL: named safety costs, beside the reward, never in it.

Every view reports, per agent and per step, a cost ``>= 0`` and its named terms, combined by
typed weights (:class:`uasep_env.config.CostWeights`): ``cost_i = sum_k weight_k * term_k``.
Each term is an indicator of a safety condition in the step, read from the step's safety
figures (the same distances and strict "closer than" thresholds as the metrics,
:mod:`uasep_env.metrics`), so with the default weights **the cost is > 0 exactly when the
UAV has lost separation** (tested in every view), and an agent's episode cost is the number
of steps it spent in loss of separation (two when it is too close to a UAV and an obstacle
at once).

=========================  ===========================================================
Term                       Value per agent (1 when the condition holds in the step)
=========================  ===========================================================
``separation_uav``         another UAV closer than ``uav.separation_distance`` (m) during
                           the step (``infos["loss_of_separation_uav"]``); weight 1
``separation_obstacle``    an active obstacle's centre closer than
                           ``uav.obstacle_separation`` (m) during the step
                           (``infos["loss_of_separation_obstacle"]``); weight 1
``region``                 inside a predicted reachable region at the end of the step
                           (``infos["in_reachable_region"]``); weight 0 by default: the
                           region is a prediction, not a loss of separation
=========================  ===========================================================

Units: a term is 1 per environment step (dimensionless), a weight a cost per step, an
episode's cost a (weighted) number of steps: times ``step_duration`` it is the time in loss
of separation (s) that :func:`uasep_env.metrics.episode_metrics` reports per UAV
(``uav_los_time + obstacle_los_time``; with ``decision_interval > 1`` the cost also counts
a step whose loss lies between two recorded samples).

Where each view reports it (the reward, the episode and its random stream are unchanged:
the cost is computed from figures the core already has, whether or not anyone reads it):

* PettingZoo: ``infos[agent]["cost"]`` (float) and ``infos[agent]["cost_terms"]`` (dict);
* Gymnasium (centralised): ``info["cost"]``, the mean of the agents' costs (as the reward is
  the mean of theirs), ``info["costs"]`` per UAV and ``info["cost_<term>"]``, the mean of
  each term (flat keys, as the reward terms);
* vector: the same keys as arrays over the environments (``infos["cost"]`` is
  ``(num_envs,)``);
* SB3 (:class:`~uasep_env.envs.sb3.UAVSharedVecEnv`, one sub-environment per agent):
  ``infos[k]["cost"]`` and ``infos[k]["cost_terms"]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from uasep_env.config import CostWeights

__all__ = ["COST_TERMS", "SAFETY_FLAGS", "TERMS", "CostTerm", "compute_costs", "weighted_cost"]


class CostTerm(NamedTuple):
    """One row of the cost table.

    Attributes:
        name: The term's name (a field of :class:`~uasep_env.config.CostWeights` too).
        safety: The step's safety flag it is 1 on (a key of the step's safety figures and
            of every agent's infos; :data:`SAFETY_FLAGS` is made of these names, and the
            flag's value is computed under this name by
            :func:`uasep_env.interface.outcome.step_outcome` and its compiled twin).
        low: Least value of the unweighted term in one step.
        high: Greatest value of the unweighted term in one step.
    """

    name: str
    safety: str
    low: float = 0.0
    high: float = 1.0


#: The cost terms, in reporting order: the one list the costs, the weights, the safety flags
#: (:data:`SAFETY_FLAGS`, the kernel's flag rows) and the tests read (``docs/extending.md``,
#: "Adding a cost term").
TERMS: tuple[CostTerm, ...] = (
    CostTerm("separation_uav", "loss_of_separation_uav"),
    CostTerm("separation_obstacle", "loss_of_separation_obstacle"),
    CostTerm("region", "in_reachable_region"),
)
#: Names of the cost terms, in reporting order.
COST_TERMS: tuple[str, ...] = tuple(t.name for t in TERMS)
#: The step's safety flags, in the order of the outcome's ``flags`` rows and of the infos'
#: keys: the terms' ``safety`` names, each once, in table order.
SAFETY_FLAGS: tuple[str, ...] = tuple(dict.fromkeys(t.safety for t in TERMS))


def compute_costs(
    safety: dict[str, np.ndarray], weights: CostWeights
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The step's costs and their named terms, from its safety flags.

    Args:
        safety: The step's safety figures (``EnvCore.step``), name -> ``(E, N)``; the
            flags of :data:`TERMS` are read.
        weights: One weight per term (>= 0, validated by the config).

    Returns:
        ``(cost, terms)``: ``(E, N)`` float64 costs and a dict of ``(E, N)`` float64 terms
        (0 or 1).
    """
    terms = {t.name: safety[t.safety].astype(np.float64) for t in TERMS}
    cost = weighted_cost(list(terms.values()), [getattr(weights, t.name) for t in TERMS])
    return cost, terms


def weighted_cost(terms: Sequence[np.ndarray], weights: Sequence[float]) -> np.ndarray:
    """The cost: the terms (0 or 1, float64, in :data:`TERMS` order) by their weights.

    Args:
        terms: One ``(E, N)`` array per term.
        weights: One weight per term.

    Returns:
        ``(E, N)`` float64.
    """
    cost = np.zeros(terms[0].shape)
    for w, term in zip(weights, terms, strict=True):
        if w:  # a zero weight adds nothing (and keeps -0.0 and NaN out)
            cost += w * term
    return cost
