"""Train a PPO residual on the APF under the safety constraint (PID Lagrangian).

The recipe of :mod:`~uasep_env.training.ppo_lagrangian` with the residual recipe's defaults
(:data:`~uasep_env.training.ppo_lagrangian.RESIDUAL_LAGRANGIAN_DEFAULTS`): the policy
learns corrections to the APF's command (``--action-mode residual_apf``), so a zero action
flies the APF and training starts from the reference controller; the task reward is
maximised and the expected episode cost per agent (steps in loss of separation) kept under
``--cost-limit``. Every flag of ``uasep-train ppo_lagrangian`` applies (its ``--help`` says
what the constraint's options mean); the defaults that differ are the residual recipe's
(``uasep-train ppo_residual_apf``): ``--residual-scale``, ``--log-std-init``,
``--learning-rate``, ``--target-kl``, ``--critic-warmup`` and ``--out-dir``.

    uasep-train ppo_lagrangian_residual [--cost-limit apf] [--max-minutes M] ...

(``python train/ppo_lagrangian_residual.py`` in a checkout is the same command.)
"""

from __future__ import annotations

from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS, run_residual

__all__ = ["RESIDUAL_LAGRANGIAN_DEFAULTS", "run"]

run = run_residual
