"""Reward terms and their weighted sum: :func:`uasep_env.interface.rewards._weighted_terms`."""

from __future__ import annotations

from collections import namedtuple

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _norm3, _parallel, _sq3, frozen


@numba.njit(inline="always", **_JIT)
def _reward_agent(k, x, c, ix, weights, own, terms):  # noqa: ANN001, ANN202
    """Agent ``k`` (flat over env and UAV) of :func:`uasep_env.interface.rewards._weighted_terms`.

    ``x`` is the :class:`uasep_env.interface.rewards._Inputs` named tuple, ``c`` the
    :class:`uasep_env.interface.rewards._Constants` one; ``ix`` gives each term's row of ``terms``
    by name (:data:`uasep_env.interface.rewards._TERM_INDEX`, from the term table).
    """
    n = x.uav_pos.shape[1]
    e = k // n
    i = k % n
    max_acc, d_sep, d_osep = c.max_accel, c.separation_distance, c.obstacle_separation
    d_col, dev_scale = c.collision_distance, c.deviation_scale
    region_cap, max_steps = c.region_cap, c.max_steps
    d_uav, d_obstacle = x.min_uav_dist[e, i], x.min_obstacle_dist[e, i]
    d_region = np.inf
    for j in range(x.region.shape[2]):
        d_region = min(d_region, x.region[e, i, j])
    t = max(0.0, 1.0 - d_uav / d_sep)
    terms[ix.separation_inner, e, i] = -(t * t)
    t = max(0.0, 1.0 - d_obstacle / d_osep)
    terms[ix.separation_obstacle, e, i] = -(t * t)
    terms[ix.separation_region, e, i] = -min(region_cap, max(0.0, 1.0 - d_region / d_osep))
    dev = _norm3(
        x.uav_pos[e, i, 0] - x.plan_pos[e, i, 0],
        x.uav_pos[e, i, 1] - x.plan_pos[e, i, 1],
        x.uav_pos[e, i, 2] - x.plan_pos[e, i, 2],
    )
    terms[ix.deviation, e, i] = -(dev / (dev + dev_scale))
    a0, a1, a2 = x.cmd[e, i, 0], x.cmd[e, i, 1], x.cmd[e, i, 2]
    u0, u1, u2 = a0 / max_acc, a1 / max_acc, a2 / max_acc
    terms[ix.control, e, i] = -_sq3(u0, u1, u2) / 3.0
    u0 = (a0 - x.prev_cmd[e, i, 0]) / max_acc
    u1 = (a1 - x.prev_cmd[e, i, 1]) / max_acc
    u2 = (a2 - x.prev_cmd[e, i, 2]) / max_acc
    terms[ix.smoothness, e, i] = -_sq3(u0, u1, u2) / 3.0
    hit = False  # any UAV of the environment (the collision ends everyone's episode)
    for j in range(n):
        hit = hit or x.min_uav_dist[e, j] < d_col or x.min_obstacle_dist[e, j] < d_col
    terms[ix.collision, e, i] = -max_steps if hit else -0.0
    terms[ix.progress, e, i] = 1.0
    total = 0.0
    for t_idx in range(terms.shape[0]):
        total += weights[t_idx] * terms[t_idx, e, i]
    own[e, i] = total
    return d_region  # the step's outcome reports it too


# The named tuples arrive as plain tuples and are named again here: numba reads a plain
# tuple's type in C and a named one's in Python, about half a microsecond a tuple on every
# call (observations.py says more). The fields are the reference's, in its order
# (tests/test_kernels.py checks them): uasep_env.interface.rewards._Inputs, _Constants and
# _TERM_INDEX (the term table's names), and uasep_env.interface.outcome.OutcomeConstants and
# _FLAG_INDEX (the safety flags, the cost table's names).
_Inputs = namedtuple(
    "_Inputs", "uav_pos plan_pos cmd prev_cmd min_uav_dist min_obstacle_dist region"
)
_Constants = namedtuple(
    "_Constants",
    "max_accel separation_distance obstacle_separation collision_distance deviation_scale "
    "region_cap max_steps",
)
_TermIndex = namedtuple(
    "_TermIndex",
    "separation_inner separation_obstacle separation_region deviation control smoothness "
    "collision progress",
)
_OutcomeConstants = namedtuple("_OutcomeConstants", "lost_sq cost_weights cost_flags")
_FlagIndex = namedtuple(
    "_FlagIndex", "loss_of_separation_uav loss_of_separation_obstacle in_reachable_region"
)


@numba.njit(**_JIT)
def _rewards_serial(xt, ct, it, weights, own, terms):  # noqa: ANN001, ANN202
    x = _Inputs(*xt)
    c = _Constants(*ct)
    ix = _TermIndex(*it)
    for k in range(own.size):
        _reward_agent(k, x, c, ix, weights, own, terms)


@numba.njit(parallel=True, **_JIT)
def _rewards_parallel(xt, ct, it, weights, own, terms):  # noqa: ANN001, ANN202
    x = _Inputs(*xt)  # one statement each: the parallel loop looks up the definitions
    c = _Constants(*ct)
    ix = _TermIndex(*it)
    for k in numba.prange(own.size):
        _reward_agent(k, x, c, ix, weights, own, terms)


def reward_terms(
    inputs: tuple, constants: tuple, weights: np.ndarray, *, index: tuple
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled reward terms and their weighted sum (before any team sharing).

    Args:
        inputs: The :class:`uasep_env.interface.rewards._Inputs` of one call.
        constants: The :class:`uasep_env.interface.rewards._Constants` of one call.
        weights: One weight per term, in :data:`uasep_env.interface.rewards.REWARD_TERMS` order.
        index: :data:`uasep_env.interface.rewards._TERM_INDEX`, each term's row by name.

    Returns:
        ``(own, terms)``: ``(E, N)`` weighted sums and ``(T, E, N)`` unweighted terms.
    """
    x = tuple(map(frozen, inputs))  # one compiled signature
    e, n = inputs.min_uav_dist.shape
    own = np.empty((e, n))
    terms = np.empty((len(index), e, n))
    fn = _rewards_parallel if _parallel(own.size) else _rewards_serial
    fn(x, tuple(constants), tuple(index), frozen(weights), own, terms)
    return own, terms


# ---------------------------------------------------------------- the step's outcome
# The outputs go in as separate arrays, not as the fields of one named tuple: read from a
# tuple inside the parallel loop (a parfor), the writes were lost (tests/test_kernels.py
# runs every kernel's parallel loops against its reference).
# fmt: off
@numba.njit(inline="always", **_JIT)
def _outcome_agent(k, x, c, ix, fx, weights, o, own, terms, d_reg, collided, lost, flags, cost,  # noqa: ANN001, ANN202
                   cost_terms):  # noqa: ANN001
# fmt: on
    """Agent ``k`` of :func:`~uasep_env.interface.outcome.step_outcome` (arrays: ``Outcome``)."""
    d_region = _reward_agent(k, x, c, ix, weights, own, terms)
    n = x.uav_pos.shape[1]
    e = k // n
    i = k % n
    d_uav, d_obstacle = x.min_uav_dist[e, i], x.min_obstacle_dist[e, i]
    d_reg[e, i] = d_region
    collided[e, i] = d_uav < c.collision_distance or d_obstacle < c.collision_distance
    off = _sq3(x.uav_pos[e, i, 0] - x.plan_pos[e, i, 0], x.uav_pos[e, i, 1] - x.plan_pos[e, i, 1],
               x.uav_pos[e, i, 2] - x.plan_pos[e, i, 2])  # fmt: skip
    lost[e, i] = off > o.lost_sq
    # The rows of uasep_env.interface.outcome.SAFETY_FLAGS, by name (_flag_values there).
    flags[fx.loss_of_separation_uav, e, i] = d_uav < c.separation_distance
    flags[fx.loss_of_separation_obstacle, e, i] = d_obstacle < c.obstacle_separation
    flags[fx.in_reachable_region, e, i] = d_region < 0.0
    total = 0.0
    for t in range(o.cost_weights.shape[0]):
        term = 1.0 if flags[o.cost_flags[t], e, i] else 0.0
        cost_terms[t, e, i] = term
        if o.cost_weights[t] != 0.0:  # a zero weight adds nothing (as costs.weighted_cost)
            total += o.cost_weights[t] * term
    cost[e, i] = total


# fmt: off
@numba.njit(**_JIT)
def _outcome_serial(xt, ct, it, ft, weights, ot, own, terms, d_reg, collided, lost, flags, cost,  # noqa: ANN001, ANN202
                    cost_terms):  # noqa: ANN001
# fmt: on
    x = _Inputs(*xt)
    c = _Constants(*ct)
    ix = _TermIndex(*it)
    fx = _FlagIndex(*ft)
    o = _OutcomeConstants(*ot)
    for k in range(own.size):
        _outcome_agent(k, x, c, ix, fx, weights, o, own, terms, d_reg, collided, lost, flags, cost,
                       cost_terms)  # fmt: skip


# fmt: off
@numba.njit(parallel=True, **_JIT)
def _outcome_parallel(xt, ct, it, ft, weights, ot, own, terms, d_reg, collided, lost, flags, cost,  # noqa: ANN001, ANN202
                      cost_terms):  # noqa: ANN001
# fmt: on
    x = _Inputs(*xt)  # one statement each: the parallel loop looks up the definitions
    c = _Constants(*ct)
    ix = _TermIndex(*it)
    fx = _FlagIndex(*ft)
    o = _OutcomeConstants(*ot)
    for k in numba.prange(own.size):
        _outcome_agent(k, x, c, ix, fx, weights, o, own, terms, d_reg, collided, lost, flags, cost,
                       cost_terms)  # fmt: skip


def step_outcome(
    inputs: tuple,
    constants: tuple,
    weights: np.ndarray,
    o: tuple,
    *,
    index: tuple,
    flag_index: tuple,
    result: type,
) -> tuple:
    """Compiled :func:`uasep_env.interface.outcome.step_outcome`: same arguments, same bits.

    Args:
        inputs: The :class:`uasep_env.interface.rewards._Inputs` of one call.
        constants: The :class:`uasep_env.interface.rewards._Constants` of one call.
        weights: One weight per reward term.
        o: The :class:`uasep_env.interface.outcome.OutcomeConstants`.
        index: :data:`uasep_env.interface.rewards._TERM_INDEX`.
        flag_index: :data:`uasep_env.interface.outcome._FLAG_INDEX`, each safety flag's row.
        result: :class:`uasep_env.interface.outcome.Outcome`, filled and returned.
    """
    x = tuple(map(frozen, inputs))  # one compiled signature
    e, n = inputs.min_uav_dist.shape
    n_costs = o.cost_weights.shape[0]
    out = result(
        np.empty((e, n)), np.empty((len(index), e, n)), np.empty((e, n)),
        np.empty((e, n), np.bool_), np.empty((e, n), np.bool_),
        np.empty((len(flag_index), e, n), np.bool_), np.empty((e, n)), np.empty((n_costs, e, n)),
    )  # fmt: skip
    o = (float(o.lost_sq), frozen(o.cost_weights), frozen(o.cost_flags))
    fn = _outcome_parallel if _parallel(e * n) else _outcome_serial
    fn(x, tuple(constants), tuple(index), tuple(flag_index), frozen(weights), o, *out)
    return out
