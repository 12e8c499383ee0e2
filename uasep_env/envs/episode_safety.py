"""The running episodes' safety summaries that the training loops report as they go.

Both trainers' views of the core (the SB3 view, :mod:`uasep_env.envs.sb3`, and the lean PPO
loop, :mod:`uasep_env.training.ppo_lean`) fold every step into these, so that their
learning curves mean the same: a finished episode's ``collision`` and
``loss_of_separation`` (any UAV, any step) and ``max_deviation`` (m, the largest true
distance of a UAV from its planned position once the formation has formed up, as in
:mod:`uasep_env.metrics`).
"""

from __future__ import annotations

import numpy as np

from uasep_env.rollout import DEFAULT_SETTLE_TIME_S

__all__ = ["EpisodeSafety"]


class EpisodeSafety:
    """Per-environment safety of the running episodes of a batch.

    Args:
        n_envs: Environments in the batch.
    """

    def __init__(self, n_envs: int) -> None:
        self.collided = np.zeros(n_envs, dtype=bool)
        self.lost_separation = np.zeros(n_envs, dtype=bool)
        self.max_deviation = np.zeros(n_envs)

    def track(self, world: object, safety: dict[str, np.ndarray]) -> None:
        """Fold one step (its :class:`~uasep_env.envs.core.StepResult` ``safety``) in.

        Call it after the step and before the ended environments are reset: ``world``'s
        positions are the step's.
        """
        self.collided |= safety["collision"].any(axis=1)
        self.lost_separation |= (
            safety["loss_of_separation_uav"] | safety["loss_of_separation_obstacle"]
        ).any(axis=1)
        d = world.uav_pos - world.plan_pos  # type: ignore[attr-defined]
        dev = np.sqrt(np.einsum("eni,eni->en", d, d)).max(axis=1)
        settled = world.time >= DEFAULT_SETTLE_TIME_S  # type: ignore[attr-defined]
        np.maximum(self.max_deviation, np.where(settled, dev, 0.0), out=self.max_deviation)

    def summary(self, env: int) -> dict[str, bool | float]:
        """Environment ``env``'s episode so far, as the SB3 view's ``episode_safety``."""
        return {
            "collision": bool(self.collided[env]),
            "loss_of_separation": bool(self.lost_separation[env]),
            "max_deviation": float(self.max_deviation[env]),
        }

    def clear(self, envs: np.ndarray | slice = slice(None)) -> None:
        """Start new episodes in ``envs`` (a mask or index; all by default)."""
        self.collided[envs] = self.lost_separation[envs] = False
        self.max_deviation[envs] = 0.0
