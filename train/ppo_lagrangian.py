"""Train the shared PPO policy under a safety constraint (PID Lagrangian, issue 29).

The recipe of :mod:`ppo_shared` (every flag applies), with the task reward
(``--config reward=task``: deviation, control, smoothness and the alive bonus, no
separation or collision term) and the separation kept as a constraint on the cost channel
instead: the expected episode cost per agent (:mod:`uasep_env.costs`: steps in loss of
separation) must stay at most ``--cost-limit``. The multiplier is the PID Lagrangian of
Stooke et al. (2020) (:mod:`uasep_env.lagrangian`; ``--pid-kp 0 --pid-kd 0`` is plain
gradient ascent), applied to PPO's rollouts by
:class:`uasep_env.sb3_lagrangian.LagrangianCallback`.

    python train/ppo_lagrangian.py                          # limit: the APF's mean cost
    python train/ppo_lagrangian.py --cost-limit 0.5         # a limit of your own
    python train/ppo_lagrangian.py --cost-limit apf-rate    # the loss-rate bound

``--cost-limit``: a number >= 0 (steps in loss of separation per agent and episode),
``apf`` (the APF's mean episode cost on ``--budget-episodes`` validation encounters: as
many steps in loss of separation as the APF on average) or ``apf-rate`` (the APF's
loss-of-separation rate ``r`` over the formation size ``N``: meeting it bounds the policy's
loss rate by ``r``; see :class:`uasep_env.lagrangian.CostBudget`). The budget is measured
at the start with the project's evaluation code and written to ``budget.json``.

Beside ``ppo_shared``'s outputs a run writes ``cost_progress.csv`` (one row per PPO
iteration: the mean episode cost of the rollout and of the last 200 episodes, the limit
and the multiplier), ``cost_curves.png`` drawn from it, and the final multiplier in
``validation.json`` (``training.lagrangian``). ``--resume`` is not supported yet (the
checkpoints do not hold the multiplier's state).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import ppo_shared

#: What this recipe writes beside ``ppo_shared``'s run files (``--overwrite`` deletes them).
COST_FILES = ("cost_progress.csv", "cost_curves.png", "budget.json")


@dataclass
class Args(ppo_shared.Args):
    """``ppo_shared.Args`` with the constraint's options."""

    # env overrides; keep reward=task in them for the task reward (this default)
    config: str = "reward=task"
    cost: str = "cost"  # the constrained cost: "cost" or one of uasep_env.costs.COST_TERMS
    cost_limit: str = "apf"  # a number >= 0, "apf" or "apf-rate" (module docstring)
    budget_episodes: int = 1000  # validation encounters the APF's budget is measured on
    pid_kp: float = 0.0  # proportional gain (0 with --pid-kd 0: gradient ascent)
    pid_ki: float = 0.01  # integral gain: the multiplier's learning rate
    pid_kd: float = 0.0  # derivative gain
    pid_ema: float = 0.9  # smoothing of the proportional and derivative terms
    multiplier_init: float = 0.0
    multiplier_max: float = 100.0
    out_dir: str = "runs/ppo_lagrangian"


def parse_args(argv: list[str] | None = None, defaults: Args | None = None) -> Args:
    """``ppo_shared.parse_args`` for :class:`Args`, and the constraint's options checked.

    Raises:
        SystemExit: A bad option, named with its value (a negative limit or gain, a cost
            the environment does not report, reward normalisation, ``--resume``).
    """
    from uasep_env.sb3_lagrangian import cost_reader

    args = ppo_shared.parse_args(argv, defaults or Args())
    try:
        cost_reader(args.cost)
        cost_limit(args)
        make_lagrangian(args, 0.0)
    except ValueError as err:
        raise SystemExit(f"ppo_lagrangian.py: error: {err}") from err
    if args.budget_episodes < 1:
        raise SystemExit(f"ppo_lagrangian.py: error: --budget-episodes {args.budget_episodes}")
    if args.norm_reward:
        raise SystemExit("ppo_lagrangian.py: error: --norm-reward rescales the reward only")
    if args.resume:
        raise SystemExit("ppo_lagrangian.py: error: --resume is not supported by this recipe yet")
    return args


def cost_limit(args: Args) -> float | str:
    """``--cost-limit`` as a number, or ``"apf"`` / ``"apf-rate"`` (measured later).

    Raises:
        ValueError: Anything else, or a negative or non-finite number, named.
    """
    from uasep_env.lagrangian import check_cost_limit

    if args.cost_limit in ("apf", "apf-rate"):
        return args.cost_limit
    try:
        value = float(args.cost_limit)
    except ValueError:
        raise ValueError(
            f"--cost-limit {args.cost_limit!r}: a number >= 0, 'apf' or 'apf-rate'"
        ) from None
    return check_cost_limit(value, "--cost-limit")


def make_lagrangian(args: Args, limit: float) -> Any:
    """The multiplier's controller for ``args`` and the limit ``limit``."""
    from uasep_env.lagrangian import PIDLagrangian

    return PIDLagrangian(
        limit,
        kp=args.pid_kp,
        ki=args.pid_ki,
        kd=args.pid_kd,
        ema_p=args.pid_ema,
        ema_d=args.pid_ema,
        init=args.multiplier_init,
        max_multiplier=args.multiplier_max if args.multiplier_max > 0 else math.inf,
    )


def measure_budget(args: Args, config: Any, out: Path) -> float:
    """The cost limit of ``args`` (the APF's budget measured if asked); ``budget.json``."""
    import dataclasses

    from uasep_env.atomic import atomic_write
    from uasep_env.lagrangian import apf_cost_budget
    from uasep_env.scenarios import VALIDATION_SEEDS

    limit = cost_limit(args)
    record: dict[str, Any] = {"cost_limit_option": args.cost_limit}
    if isinstance(limit, str):
        seeds = list(VALIDATION_SEEDS)[: args.budget_episodes]
        budget = apf_cost_budget(config, seeds)
        record.update(dataclasses.asdict(budget), parity_limit=budget.parity_limit,
                      rate_limit=budget.rate_limit)  # fmt: skip
        limit = budget.parity_limit if limit == "apf" else budget.rate_limit
    record["cost_limit"] = limit
    atomic_write(out / "budget.json", json.dumps(record, indent=2) + "\n")
    print(f"cost limit {limit:.4g} per agent and episode ({args.cost_limit})")
    return float(limit)


def main(argv: list[str] | None = None, defaults: Args | None = None) -> dict:
    """Train under the constraint, export the policy, validate; returns the summary."""
    args = parse_args(argv, defaults)
    import torch
    from rundir import plot_curves, prepare_out_dir
    from stable_baselines3.common.callbacks import CallbackList

    from uasep_env.sb3_lagrangian import LagrangianCallback, plot_cost_curves

    torch.set_num_threads(args.torch_threads)
    config = ppo_shared.make_env_config(args)
    task = config.reward == config.reward.task()
    print(f"reward: {'the task reward' if task else config.reward} (--config {args.config!r})")
    out = Path(args.out_dir)
    prepare_out_dir(out, "", args.overwrite)
    for name in COST_FILES:  # --overwrite: ppo_shared's files are gone, ours too
        (out / name).unlink(missing_ok=True)
    lagrangian = make_lagrangian(args, measure_budget(args, config, out))
    venv, model = ppo_shared.build(args, config)
    progress = ppo_shared.make_callback(args, config, venv, 0.0, args.total_timesteps)
    constraint = LagrangianCallback(lagrangian, args.cost, out / "cost_progress.csv")
    model.learn(
        total_timesteps=args.total_timesteps,
        callback=CallbackList([constraint, progress]),
        tb_log_name="lagrangian",
    )
    info = {**progress.info(), "lagrangian": {"cost": args.cost, "cost_limit":
            lagrangian.cost_limit, **lagrangian.state_dict()}}  # fmt: skip
    policy_path = ppo_shared.export_policy(model, venv, config, args, out / "policy.zip", info)
    plot_curves(out / "progress.csv", out / "curves.png", ppo_shared.CSV_FIELDS, "PPO-Lagrangian")
    plot_cost_curves(out / "cost_progress.csv", out / "cost_curves.png", "PPO-Lagrangian")
    return ppo_shared.write_validation(out, config, policy_path, info, args.eval_episodes)


if __name__ == "__main__":
    try:
        main()
    except OSError as err:
        sys.exit(f"{Path(sys.argv[0]).name}: error: {err}")
