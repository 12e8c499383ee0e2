"""What an agent's action means: the action modes of ``EnvConfig.action``.

``direct`` (the default): the action is the commanded acceleration, a fraction of
``uav.max_accel`` per axis, in ``[-1, 1]^3``.

``residual_apf``: the action is a bounded correction to the paper's APF
(:class:`~uasep_env.policies.apf.APF`, default gains) acting on the same observation:
``command = clip(apf(obs) + action.residual_scale * action, -1, 1)``. A zero action flies
the APF exactly, so a learner starts from the reference controller and only learns where
to depart from it (the usual start of safety-critical RL). The observation then ends with
the APF's command (``base_action``, see :mod:`uasep_env.interface.observation`), so a policy sees
what it corrects.

:class:`ResidualAPF` is the one implementation of the mode: the environments use it to
turn actions into commands, and a learned residual policy uses it to act in a ``direct``
environment (where it is evaluated beside the APFs on the same seeds), with the same
numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from uasep_env.config import EnvConfig

if TYPE_CHECKING:
    from uasep_env.policies.apf import APFGains

__all__ = ["ResidualAPF"]


class ResidualAPF:
    """The ``residual_apf`` action mode: the APF's command plus a bounded correction.

    Args:
        config: The environment config (its ``action.residual_scale`` bounds the correction;
            its mode may be either: the APF always reads the world part of the observation).
        gains: The base APF's gains (default: the reference gains,
            :class:`~uasep_env.policies.apf.APFGains`'s field defaults, what the environments
            use, not the APF controller's tuned ``default_gains``: re-tuning a controller
            does not move an episode); other gains only to study a trained policy on another
            base (``baselines/tradeoff.py``).
    """

    def __init__(self, config: EnvConfig, gains: APFGains | None = None) -> None:
        from uasep_env.policies.apf import APF, APFGains  # here: policies imports this module

        self.scale = config.action.residual_scale
        base_gains = gains if gains is not None else APFGains()
        self.apf = APF(config.replace(action={"mode": "direct"}), base_gains)
        self.world_dim = self.apf.layout.dim

    def base(self, world_obs: np.ndarray) -> np.ndarray:
        """The APF's normalised command ``(..., 3)`` float32 for world observations."""
        return self.apf(world_obs)

    def command(self, base: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """``clip(base + residual_scale * residual, -1, 1)``: the command actually flown."""
        out = base + self.scale * residual
        return np.minimum(np.maximum(out, -1.0), 1.0)

    def observe(self, world_obs: np.ndarray, base: np.ndarray) -> np.ndarray:
        """The residual mode's observation: the world part followed by ``base_action``."""
        return np.concatenate([world_obs, base.astype(np.float32, copy=False)], axis=-1)
