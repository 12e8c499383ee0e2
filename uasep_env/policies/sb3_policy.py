"""stable-baselines3 models as policies (loading one unpickles it: an explicit opt-in).

A stable-baselines3 ``.zip`` is not this project's policy checkpoint
(:mod:`uasep_env.policies.checkpoint_policy`): SB3's loader unpickles (runs) objects stored
in the file. :func:`load_sb3_policy` therefore refuses it unless the caller opts in with
``allow_pickle=True`` (``uasep-eval --allow-pickle``), for files they trust.

Importing this module does not import stable-baselines3 or torch.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies.checkpoint import ALGORITHMS, CheckpointError
from uasep_env.policies.guard import finite_observations

__all__ = ["SB3Policy", "load_sb3_policy"]


@finite_observations  # as every registered policy
class SB3Policy:
    """A shared-parameter SB3 policy acting on per-agent observations.

    Args:
        model: A loaded SB3 algorithm whose observation space is one agent's observation.
        config: The environment config (checks the observation width).
        deterministic: Use the deterministic action.
        obs_normalizer: Optional ``obs -> normalised obs`` (e.g. ``VecNormalize.normalize_obs``).
    """

    def __init__(
        self,
        model: Any,
        config: EnvConfig,
        deterministic: bool = True,
        obs_normalizer: Any = None,
    ) -> None:
        width = ObservationLayout.from_config(config).dim
        shape = getattr(model.observation_space, "shape", None)
        if shape != (width,):
            raise CheckpointError(
                f"model observation shape {shape} does not match this config's ({width},)"
            )
        self.model = model
        self.config = config
        self.deterministic = deterministic
        self.obs_normalizer = obs_normalizer
        self.name = f"sb3:{type(model).__name__}"

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions ``(..., 3)`` in ``[-1, 1]`` for observations ``(..., obs_dim)``."""
        obs = np.asarray(observations, dtype=np.float32)
        flat = obs.reshape(-1, obs.shape[-1])
        if self.obs_normalizer is not None:
            flat = self.obs_normalizer(flat)
        actions, _ = self.model.predict(flat, deterministic=self.deterministic)
        return np.clip(actions, -1.0, 1.0).reshape(*obs.shape[:-1], 3).astype(np.float32)

    def reset(self) -> None:
        """MLP policies are memoryless."""


def load_sb3_policy(
    path: str | Path,
    config: EnvConfig,
    algorithm: str | None = None,
    allow_pickle: bool = False,
) -> SB3Policy:
    """Load a saved stable-baselines3 model (``.zip``) as a policy.

    SB3's loader unpickles objects stored in the file, which runs code from it; it is
    only called with ``allow_pickle=True``. Prefer this project's checkpoints
    (:func:`load_policy`), which load without unpickling.

    Args:
        path: The saved model.
        config: The environment config it will act in.
        algorithm: ``"PPO"``, ``"SAC"``, ... (default: ``PPO``).
        allow_pickle: Opt in to unpickling the file (only for files you trust).

    Returns:
        The policy.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        CheckpointError: Without ``allow_pickle``, if the file cannot be loaded or the
            spaces do not match.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no saved model at {p}")
    if not allow_pickle:
        raise CheckpointError(
            f"{p} is not a uasep policy checkpoint; loading it as a stable-baselines3 model "
            "would unpickle (run) code from the file: pass allow_pickle=True "
            "(uasep-eval --allow-pickle) only for a file you trust"
        )
    name = algorithm or "PPO"
    if name not in ALGORITHMS:
        raise CheckpointError(f"unknown SB3 algorithm {name!r}; choose from {ALGORITHMS}")
    model = _load_sb3(str(p.resolve()), p.stat().st_mtime_ns, name)
    return SB3Policy(model, config)


@functools.lru_cache(maxsize=4)
def _load_sb3(path: str, mtime_ns: int, algorithm: str) -> Any:
    import stable_baselines3 as sb3  # lazy: heavy, optional dependency

    try:
        return getattr(sb3, algorithm).load(path, device="cpu")
    except Exception as err:  # SB3 raises many types for a bad file
        raise CheckpointError(
            f"could not load {path} as {algorithm} (saved by another algorithm? choose it with "
            f"algorithm= / uasep-eval --algorithm, one of {ALGORITHMS}): {err}"
        ) from err
