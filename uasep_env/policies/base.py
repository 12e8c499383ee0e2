"""The policy interface shared by reference and learned controllers.

A policy maps observations ``(..., obs_dim)`` (one or many agents, any batch shape) to
normalised actions ``(..., 3)`` in ``[-1, 1]``: ``actions = policy(observations)``. The
PettingZoo env's per-agent observations, the vector env's and the SB3 adapter's arrays all
fit, so the same object drives every view, batched or not.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.policies.registry import register_policy

__all__ = ["Policy", "RandomPolicy", "ZeroPolicy"]


@runtime_checkable
class Policy(Protocol):
    """``policy(observations) -> actions``; ``reset()`` between episodes."""

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions ``(..., 3)`` in ``[-1, 1]`` for observations ``(..., obs_dim)``."""
        ...

    def reset(self) -> None:
        """Forget any internal state (called at the start of every episode)."""
        ...


@register_policy("zero")
class ZeroPolicy:
    """Commands zero acceleration: the UAVs coast (a lower baseline)."""

    name = "zero"

    def __init__(self, config: EnvConfig | None = None) -> None:
        self.config = config

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Zeros of shape ``(..., 3)``."""
        obs = np.asarray(observations)
        return np.zeros((*obs.shape[:-1], 3), dtype=np.float32)

    def reset(self) -> None:
        """Stateless."""


@register_policy("random")
class RandomPolicy:
    """Uniform random actions from its own seeded generator.

    Args:
        config: Unused (for a uniform constructor).
        seed: Seed of the policy's generator.
    """

    name = "random"

    def __init__(self, config: EnvConfig | None = None, seed: int | None = 0) -> None:
        self.config = config
        self.rng = np.random.default_rng(seed)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Uniform samples in ``[-1, 1]^3``."""
        obs = np.asarray(observations)
        return self.rng.uniform(-1.0, 1.0, size=(*obs.shape[:-1], 3)).astype(np.float32)

    def reset(self) -> None:
        """Keep the generator running (episodes differ)."""
