"""Training under the shield: the CBF filter in the lean loop, its interventions as a cost.

``uasep-train <recipe> --trainer lean --shield cbf`` flies every action the policy samples
through :class:`~uasep_env.policies.cbf.CBFFilter` before the batched core steps (the
filter :class:`~uasep_env.policies.shield.Shielded` applies at evaluation, on the same raw
observations), so the policy learns in the world it will be deployed in: shielded. PPO
still learns from the action it sampled (its log-probability is that action's), as a
post-posed shield does (Alshiekh et al., 2018). Each agent-step where the filter changed
the action (by more than :data:`INTERVENTION_TOLERANCE` in any axis) counts one
intervention; the PPO-Lagrangian recipes constrain their count with ``--cost shield``
(:class:`~uasep_env.training.constraint.LeanCost`), so the policy learns to need the shield
less and the shield's conservative deviations (``docs/results.md``) shrink.

A policy trained so is evaluated shielded: ``<checkpoint>+cbf`` (the seed studies and the
checkpoint selection read ``--shield cbf`` from the recipe's flags).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["INTERVENTION_TOLERANCE", "SHIELD_COST", "ShieldInLoop", "deployed", "trained_shield"]

#: The ``--cost`` that constrains the shield's interventions.
SHIELD_COST = "shield"

#: A change of the action (normalised, any axis) above this is an intervention: well above
#: the float32 rounding of a residual turned into a command and back (~1e-7).
INTERVENTION_TOLERANCE = 1e-3


class ShieldInLoop:
    """The CBF filter between the lean loop's sampled actions and the core.

    Args:
        config: The environment config the run trains in (its action mode: the filter
            turns a residual into a command and back, as when evaluating).
    """

    def __init__(self, config: Any) -> None:
        from uasep_env.policies.cbf import CBFFilter

        self.cbf = CBFFilter(config)
        #: ``(E * N,)`` 1.0 where the last step's action was changed, else 0.0.
        self.interventions = np.zeros(0)
        self.steps = 0
        self.count = 0

    def act(self, actions: np.ndarray, observations: np.ndarray) -> np.ndarray:
        """The actions flown ``(E, N, 3)`` float32: ``actions`` filtered for ``observations``.

        Args:
            actions: ``(E, N, 3)`` the sampled actions, clipped to ``[-1, 1]``.
            observations: ``(E, N, obs_dim)`` the raw (not normalised) observations they
                were sampled for.
        """
        filtered = self.cbf.filter(observations, actions)
        changed = np.abs(filtered - actions).max(axis=-1) > INTERVENTION_TOLERANCE
        self.interventions = changed.reshape(-1).astype(np.float64)
        self.steps += changed.size
        self.count += int(changed.sum())
        return filtered

    def rate(self) -> float:
        """Interventions per agent-step so far in this process (NaN: none stepped)."""
        return self.count / self.steps if self.steps else float("nan")


def trained_shield(meta: Any) -> str | None:
    """The shield a checkpoint was trained under (``"cbf"``), or None, from its recorded flags.

    Args:
        meta: The checkpoint's :class:`~uasep_env.policies.checkpoint.PolicyCheckpoint`.
    """
    args = meta.info.get("args") if isinstance(meta.info, dict) else None
    shield = args.get("shield", "none") if isinstance(args, dict) else "none"
    return None if shield in (None, "none") else str(shield)


def deployed(path: Any, meta: Any = None) -> str:
    """The policy spec a checkpoint is evaluated as: ``"<path>+cbf"`` if trained shielded.

    Args:
        path: The checkpoint.
        meta: Its description, if the caller has loaded it (else it is read here).
    """
    if meta is None:
        from uasep_env.policies import load_policy

        meta = load_policy(path).meta
    shield = trained_shield(meta)
    return str(path) if shield is None else f"{path}+{shield}"
