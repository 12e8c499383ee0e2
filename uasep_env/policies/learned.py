"""Learned policies: a stable-baselines3 model behind the common policy interface.

Importing this module does not import stable-baselines3 or torch; loading a model does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.observation import ObservationLayout

__all__ = ["SB3Policy", "load_sb3_policy"]

_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")


class SB3Policy:
    """A shared-parameter SB3 policy acting on per-agent observations.

    Args:
        model: A loaded SB3 algorithm whose observation space is one agent's observation.
        config: The environment config (checks the observation width).
        deterministic: Use the deterministic action.
    """

    def __init__(self, model: Any, config: EnvConfig, deterministic: bool = True) -> None:
        width = ObservationLayout.from_config(config).dim
        shape = getattr(model.observation_space, "shape", None)
        if shape != (width,):
            raise ValueError(
                f"model observation shape {shape} does not match this config's ({width},)"
            )
        self.model = model
        self.config = config
        self.deterministic = deterministic
        self.name = f"sb3:{type(model).__name__}"

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions ``(..., 3)`` in ``[-1, 1]`` for observations ``(..., obs_dim)``."""
        obs = np.asarray(observations, dtype=np.float32)
        flat = obs.reshape(-1, obs.shape[-1])
        actions, _ = self.model.predict(flat, deterministic=self.deterministic)
        return np.clip(actions, -1.0, 1.0).reshape(*obs.shape[:-1], 3).astype(np.float32)

    def reset(self) -> None:
        """MLP policies are memoryless."""


def load_sb3_policy(path: str | Path, config: EnvConfig, algorithm: str | None = None) -> SB3Policy:
    """Load a saved stable-baselines3 model (``.zip``) as a policy.

    Args:
        path: The saved model.
        config: The environment config it will act in.
        algorithm: ``"PPO"``, ``"SAC"``, ... (default: try each).

    Returns:
        The policy.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        ValueError: If no algorithm can load it or the spaces do not match.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"no saved model at {p}")
    import stable_baselines3 as sb3  # lazy: heavy, optional dependency

    names = [algorithm] if algorithm else list(_ALGORITHMS)
    errors = []
    for name in names:
        cls = getattr(sb3, name, None)
        if cls is None:
            raise ValueError(f"unknown SB3 algorithm {name!r}; choose from {_ALGORITHMS}")
        try:
            model = cls.load(str(p), device="cpu")
        except Exception as err:
            errors.append(f"{name}: {err}")
            continue
        return SB3Policy(model, config)
    raise ValueError(f"could not load {p} with any of {names}: {errors}")
