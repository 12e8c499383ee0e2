"""Train a PPO residual on the APF under the safety constraint (PID Lagrangian).

The recipe of :mod:`~uasep_env.training.ppo_lagrangian` with the residual recipe's defaults
(:data:`~uasep_env.training.ppo_lagrangian.RESIDUAL_LAGRANGIAN_DEFAULTS`): a zero action
flies the APF, the task reward is maximised and the episode cost kept under the limit.

    uasep-train ppo_lagrangian_residual [--cost-limit apf] [--max-minutes M] ...

(``python train/ppo_lagrangian_residual.py`` in a checkout is the same command.)
"""

from __future__ import annotations

from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS, run_residual

__all__ = ["RESIDUAL_LAGRANGIAN_DEFAULTS", "run"]

run = run_residual
