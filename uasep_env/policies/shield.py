"""Safety shields: any policy, with its actions filtered by a CBF.

:class:`Shielded` wraps a policy (an APF, a learned checkpoint, your own object) and
replaces each of its actions by the nearest one, in acceleration, that satisfies the
control barrier functions of :class:`~uasep_env.policies.cbf.CBFFilter`: where the policy
already keeps the barriers its action passes unchanged. It is itself a
:class:`~uasep_env.policies.base.Policy`, so it drops into every loop, environment view and
:func:`~uasep_env.evaluation.evaluate`. By name, ``"<policy>+cbf"`` is the shielded policy
(``make_policy("ppo_shared+cbf", config)``, ``uasep-eval --policy ppo_shared+cbf``, or
``uasep-eval --shield cbf`` for every listed policy).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.policies.base import Policy
from uasep_env.policies.cbf import CBFFilter, CBFParams
from uasep_env.policies.guard import finite_observations

__all__ = ["SHIELDS", "Shielded", "split_shield"]


@finite_observations  # as every registered policy (the filter would turn NaN in into NaN out)
class Shielded:
    """A policy whose actions pass through the CBF filter.

    Args:
        policy: The policy to shield (``policy(observations) -> actions``, ``reset()``).
        config: The environment config it acts in.
        params: Filter parameters (default :class:`~uasep_env.policies.cbf.CBFParams`).

    Examples:
        >>> import uasep_env
        >>> from uasep_env.policies import APF, APFGains, Shielded
        >>> env = uasep_env.parallel_env(scenario="collision_head_on")
        >>> plan_only = APF(env.config, gains=APFGains(k_obstacle=0.0))  # does not avoid
        >>> policy = Shielded(plan_only, env.config)
        >>> observations, _ = env.reset(seed=0)
        >>> policy(observations["uav_0"]).shape
        (3,)
    """

    def __init__(self, policy: Policy, config: EnvConfig, params: CBFParams | None = None) -> None:
        if not callable(policy):
            raise TypeError(f"policy must be callable, got {type(policy).__name__}")
        self.policy = policy
        self.config = config
        self.cbf = CBFFilter(config, params)
        self.params = self.cbf.params
        self.name = f"{getattr(policy, 'name', type(policy).__name__)}+cbf"

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """The wrapped policy's actions ``(..., 3)``, filtered (float32)."""
        observations = np.asarray(observations)
        return self.cbf.filter(observations, self.policy(observations))

    def reset(self) -> None:
        """Reset the wrapped policy."""
        reset = getattr(self.policy, "reset", None)
        if reset is not None:
            reset()


#: Shields by name: a factory ``(policy, config) -> Policy``.
SHIELDS: dict[str, Callable[[Policy, EnvConfig], Policy]] = {"cbf": Shielded}


def split_shield(name: str) -> tuple[str, str | None]:
    """Split a shielded name: ``"ppo_shared+cbf"`` -> ``("ppo_shared", "cbf")``.

    A name without a shield gives ``(name, None)``.

    Only a registered shield name (:data:`SHIELDS`) after the last ``+`` counts.
    """
    base, plus, shield = name.rpartition("+")
    if plus and base and shield in SHIELDS:
        return base, shield
    return name, None
