"""Train a PPO residual on the APF: the shared policy learns corrections to the APF's command.

The recipe of :mod:`~uasep_env.training.ppo_shared` with ``action.mode="residual_apf"`` (see
:mod:`uasep_env.interface.actions`): a zero action flies the paper's APF, so training starts from
the reference controller. Every flag of ``uasep-train ppo_shared`` applies; the defaults that
differ are :data:`RESIDUAL_DEFAULTS`.

    uasep-train ppo_residual_apf [--total-timesteps N] [--max-minutes M] ...

(``python train/ppo_residual_apf.py`` in a checkout is the same command.)
"""

from __future__ import annotations

from uasep_env.training.ppo_shared import Args, cli

__all__ = ["RESIDUAL_DEFAULTS", "run"]

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


def run(argv: list[str] | None = None) -> None:
    """Train the residual recipe (:func:`uasep_env.training.ppo_shared.cli`)."""
    cli(defaults=RESIDUAL_DEFAULTS, argv=argv)
