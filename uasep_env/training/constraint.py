"""The Lagrangian recipes' constraint: its options, its cost limit, its multiplier, its costs.

Shared by MAPPO-Lagrangian (:mod:`~uasep_env.training.mappo_lagrangian`) and PPO-Lagrangian.
The constraint keeps the expected episode cost per agent (:mod:`uasep_env.interface.costs`: steps in
loss of separation) at most a limit, with a PID Lagrange multiplier
(:class:`uasep_env.training.lagrangian.PIDLagrangian`) moved once per rollout:

* :class:`LagrangianArgs`: the options, a dataclass mixin placed before the recipe's
  ``Args`` (``class Args(LagrangianArgs, mappo.Args)``); each flag carries its validator,
  so :func:`uasep_env.training.args.parse_args` refuses a bad value in one line naming it;
* :func:`check`: what the parser refuses beyond each flag's range (``check=`` of
  :func:`~uasep_env.training.args.parse_args`);
* :func:`cost_limit`, :func:`make_lagrangian`, :func:`measure_budget` (``budget.json``);
* :class:`CostTracker`: the agents' running episode costs, the multiplier's update at the
  end of each rollout, the ``cost_progress.csv`` rows
  (:data:`COST_FIELDS`) and the state a checkpoint keeps.

``--cost-limit``: a number >= 0 (steps in loss of separation per agent and episode),
``apf`` (the APF's mean episode cost on ``--budget-episodes`` validation encounters) or
``apf-rate`` (the APF's loss-of-separation rate over the formation size; see
:class:`uasep_env.training.lagrangian.CostBudget`).

This module imports neither torch nor stable-baselines3.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.interface.costs import COST_TERMS
from uasep_env.training.args import (
    non_negative_float,
    positive_int,
    shield_problem,
    sizes_problem,
)
from uasep_env.training.lagrangian import PIDLagrangian, check_cost_limit
from uasep_env.training.shield_loop import SHIELD_COST

__all__ = [
    "COST_FIELDS",
    "COST_FILES",
    "CostTracker",
    "LagrangianArgs",
    "LeanCost",
    "check",
    "cost_limit",
    "cost_limit_option",
    "cost_name",
    "make_lagrangian",
    "measure_budget",
]

#: Columns of ``cost_progress.csv``, one row per rollout: agent-steps, agent-episodes ended so
#: far (one per UAV; ``progress.csv``'s ``episodes`` count environment episodes), the mean
#: episode cost per agent of the rollout's episodes (what the multiplier was updated with;
#: empty: none ended) and of the last 200, the limit, and the multiplier after the update.
COST_FIELDS = (
    "agent_steps",
    "agent_episodes",
    "episode_cost_mean",
    "episode_cost_window",
    "cost_limit",
    "multiplier",
)

#: What a Lagrangian run writes beside its recipe's run files (``--overwrite`` deletes them).
COST_FILES = ("cost_progress.csv", "cost_curves.png", "budget.json")


def cost_name(text: str) -> str:
    """An argparse type: a cost the environments report, or the shield's interventions.

    ``cost`` or a term's name; ``shield``: the interventions while training under the
    shield (``--shield cbf``).
    """
    if text != "cost" and text not in COST_TERMS and text != SHIELD_COST:
        raise argparse.ArgumentTypeError(
            f"cost {text!r} is not reported by the environment; choose 'cost' or one of its "
            f"terms {COST_TERMS}, or {SHIELD_COST!r} (the shield's interventions, with "
            "--shield cbf)"
        )
    return text


def cost_limit_option(text: str) -> str:
    """An argparse type: ``--cost-limit``, a number >= 0, ``apf`` or ``apf-rate``."""
    if text in ("apf", "apf-rate"):
        return text
    try:
        check_cost_limit(float(text), "--cost-limit")
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a number >= 0, 'apf' or 'apf-rate', got {text!r}"
        ) from None
    return text


def _smoothing(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1), got {text!r}")
    return value


def _opt(default: Any, kind: Any, text: str) -> Any:
    return field(default=default, metadata={"type": kind, "help": text})


@dataclass
class LagrangianArgs:
    """The constraint's options (a mixin: ``class Args(LagrangianArgs, RecipeArgs)``)."""

    # The task reward by default: the separation is the constraint's, not the reward's.
    config: str = "reward=task"
    cost: str = _opt("cost", cost_name, "the constrained cost: 'cost' or one of its terms")
    cost_limit: str = _opt(
        "apf", cost_limit_option, "episode cost per agent allowed: a number >= 0, apf, apf-rate"
    )
    budget_episodes: int = _opt(
        1000, positive_int, "validation encounters the APF's budget is measured on"
    )
    # Gains and start for the scales here (docs/training.md): a step in loss of separation
    # costs 1 against at most 0.2 of deviation reward, and lambda moves about once per four
    # rollouts; an integral gain of 0.01 moved it by < 0.01 an update, too slow for an hour.
    pid_kp: float = _opt(1.0, non_negative_float, "multiplier: proportional gain")
    pid_ki: float = _opt(0.2, non_negative_float, "multiplier: integral gain (learning rate)")
    pid_kd: float = _opt(0.0, non_negative_float, "multiplier: derivative gain")
    pid_ema: float = _opt(0.9, _smoothing, "multiplier: smoothing of the P and D terms")
    multiplier_init: float = _opt(1.0, non_negative_float, "multiplier at the start")
    multiplier_max: float = _opt(100.0, non_negative_float, "multiplier's bound (0: none)")


def check(args: Any, trainers: tuple[str, ...] = ("default",)) -> str | None:
    """What the Lagrangian recipes refuse beyond each flag's range (a message), or None.

    ``trainers``: the loops the recipe's constraint runs in (PPO-Lagrangian: SB3's and the
    lean loop; MAPPO-Lagrangian: skrl's only).
    """
    from uasep_env.scenarios import VALIDATION_SEEDS

    if args.trainer not in trainers:
        return (
            f"argument --trainer: {args.trainer!r} is not for this Lagrangian recipe (its "
            f"constraint runs in the loops {', '.join(trainers)})"
        )
    if args.norm_reward:
        return (
            "argument --norm-reward: rescales the reward but not the cost; a Lagrangian "
            "recipe trains without it"
        )
    # The multiplier's running costs are tracked per agent row: one formation size a run.
    problem = shield_problem(args) or sizes_problem(args, "the Lagrangian recipes")
    if problem:
        return problem
    if args.cost == SHIELD_COST and args.shield == "none":
        return (
            f"argument --cost: {SHIELD_COST!r} counts the shield's interventions; add --shield cbf"
        )
    if args.cost == SHIELD_COST and isinstance(cost_limit(args), str):
        return (
            f"argument --cost-limit: {args.cost_limit!r} is the APF's budget of the "
            f"environment's cost; with --cost {SHIELD_COST} give a number (interventions per "
            "agent and episode)"
        )
    if isinstance(cost_limit(args), str) and args.budget_episodes > len(VALIDATION_SEEDS):
        return (
            f"argument --budget-episodes: {args.budget_episodes} > the "
            f"{len(VALIDATION_SEEDS)} validation encounters"
        )
    return None


def cost_limit(args: Any) -> float | str:
    """``--cost-limit`` as a number, or ``"apf"`` / ``"apf-rate"`` (measured later).

    Raises:
        ValueError: Anything else, or a negative or non-finite number, named.
    """
    if args.cost_limit in ("apf", "apf-rate"):
        return str(args.cost_limit)
    try:
        value = float(args.cost_limit)
    except ValueError:
        raise ValueError(
            f"--cost-limit {args.cost_limit!r}: a number >= 0, 'apf' or 'apf-rate'"
        ) from None
    return check_cost_limit(value, "--cost-limit")


def make_lagrangian(args: Any, limit: float) -> PIDLagrangian:
    """The multiplier's controller for ``args`` and the limit ``limit``."""
    from uasep_env.config.options import pick

    return PIDLagrangian(
        limit,
        max_multiplier=args.multiplier_max if args.multiplier_max > 0 else math.inf,
        **pick(args, **_PID_OPTIONS),
    )


#: The controller's keywords and the flags that give them.
_PID_OPTIONS = {"kp": "pid_kp", "ki": "pid_ki", "kd": "pid_kd", "ema_p": "pid_ema",
                "ema_d": "pid_ema", "init": "multiplier_init"}  # fmt: skip


def measure_budget(args: Any, config: Any, out: Path) -> float:
    """The cost limit of ``args`` (the APF's budget measured if asked); ``budget.json``."""
    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.scenarios import VALIDATION_SEEDS
    from uasep_env.training.lagrangian import apf_cost_budget

    limit = cost_limit(args)
    record: dict[str, Any] = {"cost_limit_option": args.cost_limit}
    if isinstance(limit, str):
        seeds = list(VALIDATION_SEEDS)[: args.budget_episodes]
        budget = apf_cost_budget(config, seeds)
        record.update(dataclasses.asdict(budget), parity_limit=budget.parity_limit,
                      rate_limit=budget.rate_limit)  # fmt: skip
        limit = budget.parity_limit if limit == "apf" else budget.rate_limit
    record["cost_limit"] = limit
    atomic_write(out / "budget.json", json.dumps(record, indent=2) + "\n", replace_links=True)
    print(f"cost limit {limit:.4g} per agent and episode ({args.cost_limit})")
    return float(limit)


class CostTracker:
    """The agents' episode costs over a run, and the multiplier they move.

    Args:
        lagrangian: The multiplier's controller (its ``cost_limit`` is the constraint's).
        cost: The constrained cost's name (recorded in :meth:`info`).
        n: Sub-environments (one per agent and environment), each a running episode.
        window: Episodes in the running mean ``episode_cost_window``.

    Attributes:
        episodes: Agent-episodes ended so far.
        window: The last ``window`` episode costs.
    """

    def __init__(self, lagrangian: PIDLagrangian, cost: str, n: int, window: int = 200) -> None:
        self.lagrangian, self.cost = lagrangian, cost
        self.window: collections.deque[float] = collections.deque(maxlen=int(window))
        self.episodes = 0
        self._batch: list[float] = []
        self._running = np.zeros(int(n))
        self._resumed: np.ndarray | None = None  # running costs to continue (load_state_dict)

    def start(self, n: int) -> None:
        """Begin ``n`` running episodes: at zero cost, or where a resumed state left them.

        The running costs :meth:`load_state_dict` restored (``running=True``) continue when
        there are ``n`` of them; otherwise (a run's start, a resumption whose environments
        restart their episodes) every episode starts at zero.
        """
        resumed, self._resumed = self._resumed, None
        self._running = resumed if resumed is not None and len(resumed) == n else np.zeros(int(n))
        self._batch = []

    def step(self, costs: np.ndarray, dones: np.ndarray) -> None:
        """Add one step's costs ``(n,)``; the episodes of ``dones`` ``(n,)`` end with it."""
        self._running += costs
        for k in np.flatnonzero(dones):
            self._batch.append(float(self._running[k]))
            self.window.append(float(self._running[k]))
            self._running[k] = 0.0
            self.episodes += 1

    def end_rollout(self, agent_steps: int) -> dict[str, Any]:
        """Move the multiplier with the mean cost of the rollout's episodes (if any ended).

        Returns:
            The ``cost_progress.csv`` row (:data:`COST_FIELDS`).
        """
        batch = float(np.mean(self._batch)) if self._batch else math.nan
        if self._batch:
            self.lagrangian.update(batch)
        self._batch = []
        return {
            "agent_steps": int(agent_steps),
            "agent_episodes": self.episodes,
            "episode_cost_mean": batch,
            "episode_cost_window": self.window_mean(),
            "cost_limit": self.lagrangian.cost_limit,
            "multiplier": self.lagrangian.multiplier,
        }

    def window_mean(self) -> float:
        """The mean of the last episode costs (NaN before the first ends)."""
        return float(np.mean(self.window)) if self.window else math.nan

    def info(self) -> dict[str, Any]:
        """The constraint's summary: cost, limit, the multiplier's state, episodes."""
        return {
            "cost": self.cost,
            "cost_limit": self.lagrangian.cost_limit,
            **self.lagrangian.state_dict(),
            "episodes": self.episodes,
            "episode_cost_window": self.window_mean(),
        }

    def state_dict(self) -> dict[str, Any]:
        """What a checkpoint keeps (JSON-friendly): :meth:`info`, the window, running costs.

        The episode window and the running episodes' costs so far; saved between rollouts,
        so there is no rollout's batch to keep.
        """
        return {**self.info(), "window": list(self.window), "running": self._running.tolist()}

    def load_state_dict(self, state: dict[str, Any], running: bool = False) -> None:
        """Restore :meth:`state_dict`.

        Args:
            state: A :meth:`state_dict` (from a file: checked).
            running: The environments continue their episodes (an SB3 checkpoint with its
                environments' state): their running costs continue too, from the next
                :meth:`start`. Otherwise they start anew, as the environments do.

        Raises:
            ValueError: A value out of range, named. KeyError: a missing field.
        """
        from uasep_env.config.checks import check, check_int_in, check_positive

        resumed = None
        if running:
            costs = state["running"]
            check(isinstance(costs, list), "running", costs, "must be a list of episode costs")
            for c in costs:
                check_positive("running[]", c, allow_zero=True, hi=1e300)
            resumed = np.array(costs, dtype=np.float64)

        self.lagrangian.load_state_dict(state)  # checked there (the multiplier's range)
        check_int_in("episodes", state["episodes"], 0, 2**62)
        window = state["window"]
        check(isinstance(window, list), "window", window, "must be a list of episode costs")
        for c in window:
            check_positive("window[]", c, allow_zero=True, hi=1e300)
        self.episodes = int(state["episodes"])
        self.window.clear()
        self.window.extend(float(c) for c in window)
        self._batch = []
        self._running[:] = 0.0
        self._resumed = resumed


class LeanCost:
    """The multiplier applied in the lean loop (:mod:`~uasep_env.training.ppo_lean`).

    What :class:`~uasep_env.training.sb3_lagrangian.LagrangianCallback` does in SB3's loop,
    on the batched core's step results: each agent's reward becomes
    ``(r - lambda c) / (1 + lambda)`` (before a time limit's bootstrap, as in SB3), its
    cost is added to its running episode's, and at the end of each rollout ``lambda`` moves
    with the mean cost of the episodes that ended during it (one ``cost_progress.csv`` row).

    Args:
        lagrangian: The multiplier's controller.
        cost: ``"cost"`` or a cost term's name.
        csv_path: Where the rows go (appended; a new file gets a header), or None.
        window: Episodes in the running mean ``episode_cost_window``.
    """

    def __init__(
        self, lagrangian: PIDLagrangian, cost: str = "cost", csv_path: Path | None = None,
        window: int = 200,
    ) -> None:  # fmt: skip
        try:
            cost_name(cost)
        except argparse.ArgumentTypeError as err:
            raise ValueError(f"cost={cost!r}: {err}") from None
        self.lagrangian, self.cost, self.csv_path = lagrangian, cost, csv_path
        self.tracker = CostTracker(lagrangian, cost, 1, window)
        self._fh: Any = None

    def start(self, n: int) -> None:
        """Begin ``n`` running agent-episodes (environments x UAVs) and the CSV."""
        self.tracker.start(n)
        if self.csv_path is not None and self._fh is None:
            from uasep_env.training.curves import ProgressLog

            self._fh = ProgressLog(self.csv_path, COST_FIELDS)

    def shape(
        self, res: Any, reward: np.ndarray, dones: np.ndarray, shield: np.ndarray | None = None
    ) -> np.ndarray:
        """The rewards PPO learns from for one step of the core; the step's costs counted.

        Args:
            res: The core's :class:`~uasep_env.envs.core.StepResult` (costs ``(E, N)``).
            reward: ``(E * N,)`` the agents' rewards, environment-major.
            dones: ``(E * N,)`` whether each agent's episode ended with the step.
            shield: ``(E * N,)`` the shield's interventions in the step
                (:class:`~uasep_env.training.shield_loop.ShieldInLoop`), the cost under
                ``cost="shield"``.

        Raises:
            ValueError: ``cost="shield"`` with no interventions given (no shield).
        """
        if self.cost == SHIELD_COST:
            if shield is None:
                raise ValueError("cost='shield': the run trains without a shield (--shield cbf)")
            cost = shield
        else:
            cost = res.cost if self.cost == "cost" else res.cost_terms[self.cost]
        costs = np.asarray(cost, dtype=np.float64).reshape(-1)
        reward = self.lagrangian.penalise(reward, costs)
        self.tracker.step(costs, dones)
        return reward

    def rollout_end(self, agent_steps: int) -> None:
        """Move the multiplier; write the rollout's ``cost_progress.csv`` row."""
        row = self.tracker.end_rollout(agent_steps)
        if self._fh is not None:
            self._fh.write(row)

    def state_dict(self) -> dict[str, Any]:
        """:meth:`CostTracker.state_dict` (what a checkpoint keeps)."""
        return self.tracker.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`; the episodes start anew (as the lean loop's do)."""
        self.tracker.load_state_dict(state, running=False)

    def close(self) -> None:
        """Close the CSV."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
