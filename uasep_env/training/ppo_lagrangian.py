"""Train the shared PPO policy under a safety constraint (PID Lagrangian).

The recipe of :mod:`~uasep_env.training.ppo_shared` (every flag applies), with the task
reward (``--config reward=task``: deviation, control, smoothness and the alive bonus, no
separation or collision term) and the separation kept as a constraint on the cost channel
instead: the expected episode cost per agent (:mod:`uasep_env.interface.costs`: steps in loss of
separation) must stay at most ``--cost-limit``. The multiplier is the PID Lagrangian of
Stooke et al. (2020) (:mod:`uasep_env.training.lagrangian`; ``--pid-kp 0 --pid-kd 0`` is plain
gradient ascent), applied to PPO's rollouts by
:class:`uasep_env.training.sb3_lagrangian.LagrangianCallback`.

    uasep-train ppo_lagrangian                               # pure policy, limit: the APF's
    uasep-train ppo_lagrangian_residual                      # residual on the APF
    uasep-train ppo_lagrangian --cost-limit 0.5              # a limit of your own
    uasep-train ppo_lagrangian --cost-limit apf-rate         # the loss-rate bound
    uasep-train ppo_lagrangian --resume runs/ppo_lagrangian/checkpoints/latest

(``python train/ppo_lagrangian.py`` in a checkout is the same command.)

``--cost-limit``: a number >= 0 (steps in loss of separation per agent and episode),
``apf`` (the APF's mean episode cost on ``--budget-episodes`` validation encounters: as
many steps in loss of separation as the APF on average) or ``apf-rate`` (the APF's
loss-of-separation rate ``r`` over the formation size ``N``: meeting it bounds the policy's
loss rate by ``r``; see :class:`uasep_env.training.lagrangian.CostBudget`). The budget is measured
at the start with the project's evaluation code and written to ``budget.json`` (a resumed
run keeps its checkpoint's limit).

Beside ``ppo_shared``'s outputs a run writes ``cost_progress.csv`` (one row per PPO
iteration: the agent-episodes ended so far, the mean episode cost of the rollout and of the
last 200 agent-episodes, the limit and the multiplier), ``cost_curves.png`` drawn from it,
and the multiplier's state in every checkpoint's ``state.json`` and in ``validation.json``
(``training.lagrangian``), so that ``--resume`` continues the multiplier, its cost window,
the running episodes' costs and ``cost_progress.csv``. With the environments' and SB3's state
the checkpoint keeps (``env_state.npz``, :mod:`uasep_env.training.sb3_state`), a run killed
at any point and resumed from its last checkpoint ends with the same weights, multiplier,
``progress.csv`` (but its wall times) and ``cost_progress.csv`` as an uninterrupted run of the
same length and seed, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uasep_env.training import ppo_shared
from uasep_env.training.args import parse_args as _parse_args
from uasep_env.training.constraint import (
    COST_FILES,
    LagrangianArgs,
    LeanCost,
    check,
    cost_limit,
    make_lagrangian,
    measure_budget,
)
from uasep_env.training.lagrangian import check_cost_limit
from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS

__all__ = ["COST_FILES", "Args", "Constraint", "cost_limit", "main", "parse_args", "run",
           "run_residual"]  # fmt: skip


@dataclass
class Args(LagrangianArgs, ppo_shared.Args):
    """``ppo_shared.Args`` with the constraint's options (:mod:`~uasep_env.training.constraint`)."""

    out_dir: str = "runs/ppo_lagrangian"


#: The residual variant's defaults: the residual recipe's, with the constraint's options.
_RESIDUAL_FIELDS = ("action_mode", "residual_scale", "log_std_init", "learning_rate",
                    "target_kl", "critic_warmup")  # fmt: skip
RESIDUAL_LAGRANGIAN_DEFAULTS = Args(
    **{k: getattr(RESIDUAL_DEFAULTS, k) for k in _RESIDUAL_FIELDS},
    out_dir="runs/ppo_lagrangian_residual",
)


def parse_args(argv: list[str] | None = None, defaults: Args | None = None) -> Args:
    """:class:`Args` from the command line, or exit (status 2) with one line naming the value."""
    return _parse_args(
        argv,
        defaults or Args(),
        prog=ppo_shared._prog(),
        # The residual recipe's own text under ``uasep-train ppo_lagrangian_residual``.
        description=ppo_shared._PROG.get("doc") or __doc__,
        check=lambda a: check(a, trainers=("default", "lean")),
    )


class Constraint:
    """The Lagrangian's part of :func:`uasep_env.training.ppo_shared.train` (its plugin)."""

    title = "PPO-Lagrangian"

    def __init__(self, args: Args) -> None:
        self.args = args
        self.callback: Any = None

    def _begin(self, out: Path, config: Any, resumed: dict) -> tuple[Any, dict, Path]:
        """The multiplier (the limit measured, or a resumed run's own), its saved state, folder."""
        from uasep_env.training.rundir import restore_json

        task = config.reward == config.reward.task()
        print(f"reward: {'the task reward' if task else config.reward} "
              f"(--config {self.args.config!r})")  # fmt: skip
        if not resumed:
            for name in COST_FILES:  # --overwrite: ppo_shared's files are gone, ours too
                (out / name).unlink(missing_ok=True)
        kept = resumed.get("lagrangian", {})
        folder = Path(self.args.resume) if resumed else out
        if resumed and kept.get("cost_limit_option") == self.args.cost_limit:
            limit = kept.get("cost_limit")  # the run's own, not measured again
            restore_json(folder, "lagrangian.cost_limit", check_cost_limit, limit)
        else:
            limit = measure_budget(self.args, config, out)
        return make_lagrangian(self.args, float(limit)), kept, folder

    def start(self, out: Path, config: Any, resumed: dict) -> list:
        """The multiplier's callback, its state restored from ``resumed`` if any."""
        from uasep_env.training.rundir import restore_json, rewind_csv
        from uasep_env.training.sb3_lagrangian import COST_FIELDS, LagrangianCallback
        from uasep_env.training.sb3_state import continues_episodes

        lagrangian, kept, folder = self._begin(out, config, resumed)
        path = out / "cost_progress.csv"
        self.callback = LagrangianCallback(lagrangian, self.args.cost, path)
        if resumed:
            state = kept.get("state")
            # The environments continue their episodes where the checkpoint has their state
            # (loaded already): so do the episodes' running costs.
            running = continues_episodes(self.args, resumed, folder)

            def load(saved: Any) -> None:
                self.callback.load_state_dict(saved, running=running)

            restore_json(folder, "lagrangian.state", load, state)
            # Rows of the abandoned continuation go, as progress.csv's.
            rewind_csv(path, COST_FIELDS, int(resumed["agent_steps"]))
        return [self.callback]

    def start_lean(self, out: Path, config: Any, resumed: dict) -> LeanCost:
        """The multiplier for the lean loop (:class:`~uasep_env.training.constraint.LeanCost`).

        A resumed run continues its multiplier, window and ``cost_progress.csv``; its
        episodes start anew, as the lean loop's environments do.
        """
        from uasep_env.training.constraint import COST_FIELDS
        from uasep_env.training.rundir import restore_json, rewind_csv

        lagrangian, kept, folder = self._begin(out, config, resumed)
        path = out / "cost_progress.csv"
        self.callback = LeanCost(lagrangian, self.args.cost, path)
        if resumed:
            restore_json(folder, "lagrangian.state", self.callback.load_state_dict,
                         kept.get("state"))  # fmt: skip
            rewind_csv(path, COST_FIELDS, int(resumed["agent_steps"]))
        return self.callback

    def facts(self) -> dict:
        """The constraint's state, saved in every checkpoint and in ``validation.json``."""
        lag = self.callback.lagrangian
        return {"lagrangian": {"cost": self.args.cost, "cost_limit": lag.cost_limit,
                               "cost_limit_option": self.args.cost_limit,
                               "multiplier": lag.multiplier,
                               "state": self.callback.state_dict()}}  # fmt: skip

    def finish(self, out: Path) -> None:
        """Draw ``cost_curves.png`` from ``cost_progress.csv``."""
        from uasep_env.training.sb3_lagrangian import plot_cost_curves

        if (out / "cost_progress.csv").exists():
            plot_cost_curves(out / "cost_progress.csv", out / "cost_curves.png", self.title)


def main(argv: list[str] | None = None, defaults: Args | None = None) -> dict:
    """Train (or resume) under the constraint, export the policy, validate; the summary."""
    args = parse_args(argv, defaults)
    return ppo_shared.train(args, Constraint(args))


def run(argv: list[str] | None = None) -> None:
    """``uasep-train ppo_lagrangian``: the pure policy under the constraint."""
    ppo_shared.cli(None, argv, main)


def run_residual(argv: list[str] | None = None) -> None:
    """``uasep-train ppo_lagrangian_residual``: the residual policy under the constraint."""
    ppo_shared.cli(RESIDUAL_LAGRANGIAN_DEFAULTS, argv, main)
