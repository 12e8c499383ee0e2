"""Train the residual PPO under the constraint: ``uasep-train ppo_lagrangian_residual``.

The recipe lives in the package, :mod:`uasep_env.training.ppo_lagrangian` (the residual
defaults: :data:`~uasep_env.training.ppo_lagrangian.RESIDUAL_LAGRANGIAN_DEFAULTS`).

    python train/ppo_lagrangian_residual.py [flags]
"""

from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS, run_residual

__all__ = ["RESIDUAL_LAGRANGIAN_DEFAULTS", "run_residual"]

if __name__ == "__main__":
    run_residual()
