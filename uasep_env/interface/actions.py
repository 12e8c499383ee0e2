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

``residual_mvp_region``: the same on MVP with obstacles resolved on their predicted regions
(:class:`~uasep_env.policies.mvp.MVP`, ``obstacle_model="region"``, its parameters' defaults:
its knee on the validation bank), the classical controller the leaderboard names best
(``docs/results.md``); ``base_action`` is then MVP's command.

:class:`Residual` is the one implementation of these modes (:data:`RESIDUAL_BASES` names
each mode's base, one row a mode): the environments use it to turn actions into commands,
and a learned residual policy uses it to act in a ``direct`` environment (where it is
evaluated beside the controllers on the same seeds), with the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.config import EnvConfig

if TYPE_CHECKING:
    from uasep_env.policies.apf import APFGains

__all__ = ["RESIDUAL_BASES", "Residual", "ResidualAPF"]


def _apf_base(config: EnvConfig, gains: APFGains | None) -> Any:
    from uasep_env.policies.apf import APF, APFGains  # here: policies imports this module

    # The reference gains (APFGains' field defaults), not the APF controller's tuned
    # default_gains: re-tuning a controller does not move an episode.
    return APF(config, gains if gains is not None else APFGains())


def _mvp_region_base(config: EnvConfig, gains: APFGains | None) -> Any:
    from uasep_env.policies.mvp import MVP, MVPParams

    if gains is not None:
        raise ValueError(f"gains={gains!r}: only the residual_apf mode's base has APF gains")
    return MVP(config, MVPParams(obstacle_model="region"))


#: Each residual action mode's base controller: ``mode -> (config, gains) -> controller``
#: (the config in ``direct`` mode; ``gains`` the APF's, None elsewhere).
RESIDUAL_BASES: dict[str, Callable[[EnvConfig, APFGains | None], Any]] = {
    "residual_apf": _apf_base,
    "residual_mvp_region": _mvp_region_base,
}


class Residual:
    """A residual action mode: the base controller's command plus a bounded correction.

    Args:
        config: The environment config: its ``action.mode`` (a key of
            :data:`RESIDUAL_BASES`) names the base, its ``action.residual_scale`` bounds the
            correction (a policy acting in a ``direct`` environment passes its trained action
            settings).
        gains: The base APF's gains in ``residual_apf`` mode (default: the reference gains,
            :class:`~uasep_env.policies.apf.APFGains`'s field defaults, what the environments
            use); other gains only to study a trained policy on another base
            (``baselines/tradeoff.py``).

    Raises:
        ValueError: ``config``'s mode is not a residual mode, or ``gains`` are given for a base
            that is not the APF.
    """

    def __init__(self, config: EnvConfig, gains: APFGains | None = None) -> None:
        mode = config.action.mode
        if mode not in RESIDUAL_BASES:
            raise ValueError(f"mode={mode!r}: not a residual action mode {tuple(RESIDUAL_BASES)}")
        self.mode = mode
        self.scale = config.action.residual_scale
        self.controller = RESIDUAL_BASES[mode](config.replace(action={"mode": "direct"}), gains)
        self.world_dim = self.controller.layout.dim

    def base(self, world_obs: np.ndarray) -> np.ndarray:
        """The base controller's normalised command ``(..., 3)`` float32 for world observations."""
        return self.controller(world_obs)

    def command(self, base: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """``clip(base + residual_scale * residual, -1, 1)``: the command actually flown."""
        out = base + self.scale * residual
        return np.minimum(np.maximum(out, -1.0), 1.0)

    def observe(self, world_obs: np.ndarray, base: np.ndarray) -> np.ndarray:
        """The residual mode's observation: the world part followed by ``base_action``."""
        return np.concatenate([world_obs, base.astype(np.float32, copy=False)], axis=-1)


#: The ``residual_apf`` mode's name before the other bases (``Residual(config)`` in that mode).
ResidualAPF = Residual
