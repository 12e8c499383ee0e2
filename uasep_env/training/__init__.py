"""Training recipes for the shared policies (``uasep-train RECIPE``): PPO, MAPPO, MAPPO-Lag.

One module per recipe, the flags they share in :mod:`~uasep_env.training.args` and the run
folder's rules in :mod:`~uasep_env.training.rundir`:

* ``ppo_shared`` (:mod:`~uasep_env.training.ppo_shared`): one PPO policy shared by every UAV;
* ``ppo_residual_apf`` (:mod:`~uasep_env.training.ppo_residual_apf`): the same, learning
  corrections to the APF's command;
* ``mappo`` (:mod:`~uasep_env.training.mappo`): skrl's MAPPO, a centralised critic;
* ``ppo_lagrangian`` and ``ppo_lagrangian_residual``
  (:mod:`~uasep_env.training.ppo_lagrangian`): PPO (pure, residual) on the task reward with
  loss of separation as a constraint (a PID Lagrange multiplier);
* ``mappo_lagrangian`` (:mod:`~uasep_env.training.mappo_lagrangian`): MAPPO with a cost
  critic and a Lagrange multiplier, the separation a constraint
  (:mod:`~uasep_env.training.constraint`).

What every recipe shares: the PID Lagrange multiplier (:mod:`~uasep_env.training.lagrangian`)
and its SB3 callback (:mod:`~uasep_env.training.sb3_lagrangian`).

torch, stable-baselines3 and skrl (the ``train`` extra) are imported when a recipe runs,
never on import, so ``uasep-train --help`` works on a core install.
"""

from __future__ import annotations

__all__ = ["RECIPES"]

#: ``uasep-train`` recipe name -> (module, one-line description).
RECIPES: dict[str, tuple[str, str]] = {
    "ppo_shared": ("uasep_env.training.ppo_shared", "PPO, one policy shared by every UAV"),
    "ppo_residual_apf": (
        "uasep_env.training.ppo_residual_apf",
        "PPO residual on the APF (a zero action flies the APF)",
    ),
    "mappo": ("uasep_env.training.mappo", "skrl's MAPPO (centralised critic, shared actor)"),
    "ppo_lagrangian": (
        "uasep_env.training.ppo_lagrangian",
        "PPO on the task reward, loss of separation as a cost constraint (PID Lagrangian)",
    ),
    "ppo_lagrangian_residual": (
        "uasep_env.training.ppo_lagrangian_residual",
        "the same, residual on the APF",
    ),
    "mappo_lagrangian": (
        "uasep_env.training.mappo_lagrangian",
        "MAPPO with a cost critic and a PID Lagrange multiplier (separation as a constraint)",
    ),
}
