"""Train a PPO residual on the APF: ``uasep-train ppo_residual_apf`` in a checkout.

The recipe lives in the package, :mod:`uasep_env.training.ppo_residual_apf` (the PPO recipe
with the residual defaults :data:`RESIDUAL_DEFAULTS`); every flag of ``train/ppo_shared.py``
applies.

    python train/ppo_residual_apf.py [--total-timesteps N] [--max-minutes M] ...
"""

from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS, run
from uasep_env.training.ppo_shared import Args, cli

__all__ = ["RESIDUAL_DEFAULTS", "Args", "cli", "run"]

if __name__ == "__main__":
    run()
