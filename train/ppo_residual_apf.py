"""Train a PPO residual on the APF: the shared policy learns corrections to the APF's command.

The recipe of :mod:`ppo_shared` with ``action.mode="residual_apf"`` (see
:mod:`uasep_env.actions`): a zero action flies the paper's APF, so training starts from the
reference controller. Every flag of ``train/ppo_shared.py`` applies.

    python train/ppo_residual_apf.py [--total-timesteps N] [--max-minutes M] ...
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ppo_shared import Args, cli

#: The residual recipe's defaults (where they differ from the pure policy's).
RESIDUAL_DEFAULTS = Args(
    action_mode="residual_apf",
    residual_scale=0.5,
    log_std_init=-1.0,
    learning_rate=1e-4,
    target_kl=0.02,
    critic_warmup=10,
    out_dir="runs/ppo_residual_apf",
)

if __name__ == "__main__":
    cli(defaults=RESIDUAL_DEFAULTS)
