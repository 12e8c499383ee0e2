"""The policy checkpoint file format: its description, observation layout, and writer.

A checkpoint is a zip of exactly two members: ``uasep_policy.json`` (the description: format,
training config, observation layout, network shape, normalisation, training facts) and
``weights.npz`` (a zip of ``.npy`` float arrays: ``layer<k>.weight``, ``layer<k>.bias``,
``obs_mean``, ``obs_var``; a ``"set"`` network's tensors by the names of
:mod:`~uasep_env.policies.set_network`). Nothing is unpickled and no code from the file runs.

Reading (:mod:`uasep_env.policies.checkpoint_reader`) treats the file as hostile: limits
are checked before anything is decompressed or parsed, and every failure is a
:class:`CheckpointError` with a one-line message.

Formats: ``uasep-policy/2`` (written now) records the observation layout (K nearest UAVs and
obstacles, the feature names and widths in order); ``uasep-policy/1`` files keep loading, their
layout derived from their stored config.
"""

from __future__ import annotations

import io
import re
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.config import VERSION_DEFAULTS, EnvConfig, make_config
from uasep_env.interface.observation import ObservationLayout
from uasep_env.runtime.atomic import atomic_output
from uasep_env.runtime.jsonio import dumps

__all__ = [
    "ALGORITHMS",
    "CHECKPOINT_FORMAT",
    "META",
    "READABLE_FORMATS",
    "UNRECORDED_ENV_VERSION",
    "CheckpointError",
    "PolicyCheckpoint",
    "StoredLayout",
    "save_policy",
]

#: Format tag written into every new checkpoint's JSON.
CHECKPOINT_FORMAT = "uasep-policy/2"
#: Formats that load (version 1: no stored layout; it is derived from the config).
READABLE_FORMATS = ("uasep-policy/1", CHECKPOINT_FORMAT)
META = "uasep_policy.json"
WEIGHTS = "weights.npz"
ACTIVATIONS = ("tanh", "relu")
ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")
#: The env version of a checkpoint whose ``info`` does not record one: files were written
#: without it before ``-v3``, so in ``-v2`` (or earlier, which no shipped file is).
UNRECORDED_ENV_VERSION = 2
#: What a checkpoint's ``algorithm`` may say: the SB3 algorithms, and MAPPO (train/mappo.py).
CHECKPOINT_ALGORITHMS = (*ALGORITHMS, "MAPPO")


class CheckpointError(ValueError):
    """A file that is not a usable policy checkpoint, or one that does not fit the env."""


@dataclass(frozen=True, kw_only=True)
class StoredLayout:
    """The observation layout a network reads: K nearest UAVs and obstacles, features in order.

    Attributes:
        k_uavs: Nearest UAVs observed.
        k_obstacles: Nearest obstacles observed.
        features: ``(name, width)`` of each feature, in vector order (``uav0.rel_pos`` is the
            nearest UAV's relative position).
    """

    k_uavs: int
    k_obstacles: int
    features: tuple[tuple[str, int], ...]

    @classmethod
    def of(cls, layout: ObservationLayout) -> StoredLayout:
        """Group :meth:`ObservationLayout.feature_names` (one name per entry) into features."""
        features: list[list[Any]] = []
        for entry in layout.feature_names():
            name = re.sub(r"\[\d+\]$", "", entry)
            if features and features[-1][0] == name:
                features[-1][1] += 1
            else:
                features.append([name, 1])
        return cls(
            k_uavs=layout.k_uavs,
            k_obstacles=layout.k_obstacles,
            features=tuple((n, w) for n, w in features),
        )

    @classmethod
    def from_config(cls, config: EnvConfig) -> StoredLayout:
        """The layout an environment with ``config`` produces."""
        return cls.of(ObservationLayout.from_config(config))

    @property
    def dim(self) -> int:
        """Width of the observation vector."""
        return sum(w for _, w in self.features)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form stored in a checkpoint."""
        return {
            "k_uavs": self.k_uavs,
            "k_obstacles": self.k_obstacles,
            "features": [[n, w] for n, w in self.features],
        }

    def difference(self, env: StoredLayout) -> str | None:
        """What first differs between this (the network's) layout and ``env``'s, or None."""
        if self.k_uavs != env.k_uavs:
            return (
                f"k_uavs: the network reads the {self.k_uavs} nearest UAVs, this env gives "
                f"{env.k_uavs} (set observation.k_uavs={self.k_uavs}; needs n_uavs > "
                f"{self.k_uavs})"
            )
        if self.k_obstacles != env.k_obstacles:
            return (
                f"k_obstacles: the network reads the {self.k_obstacles} nearest obstacles, this "
                f"env gives {env.k_obstacles} (set observation.k_obstacles={self.k_obstacles})"
            )
        col = 0
        for k, (mine, theirs) in enumerate(zip(self.features, env.features, strict=False)):
            if mine != theirs:
                return (
                    f"observation feature {k} (column {col}): the network reads "
                    f"{mine[0]!r} ({mine[1]} wide), this env gives {theirs[0]!r} ({theirs[1]} wide)"
                )
            col += mine[1]
        if len(self.features) != len(env.features):
            n = min(len(self.features), len(env.features))
            mine = self.features[n][0] if len(self.features) > n else "nothing"
            theirs = env.features[n][0] if len(env.features) > n else "nothing"
            return (
                f"observation width: the network reads {self.dim}, this env gives {env.dim} "
                f"(feature {n}: the network reads {mine!r}, this env gives {theirs!r})"
            )
        return None


@dataclass(frozen=True, kw_only=True)
class PolicyCheckpoint:
    """What a policy checkpoint holds besides its weights.

    Attributes:
        config: The environment config it was trained in (``EnvConfig.to_dict()``).
        obs_dim: Width of the observation the network reads.
        activation: Hidden-layer activation (``"tanh"`` or ``"relu"``).
        hidden: Widths of the hidden layers.
        obs_norm: Whether observations are normalised by the stored mean and variance.
        clip_obs: Bound of the normalised observations.
        obs_epsilon: Added to the variance before its square root.
        algorithm: The algorithm that trained it (for the record).
        info: Training facts (agent-steps, wall time, seed, ...), JSON values.
        format: The file format (:data:`CHECKPOINT_FORMAT` for new files).
        layout: The observation layout the network reads (``None``: the training config's,
            what version-1 files imply and what :func:`save_policy` records).
        architecture: ``"mlp"`` (the slot MLP: ``layer<k>`` tensors; files that do not say)
            or ``"set"`` (the permutation-invariant network of
            :mod:`~uasep_env.policies.set_network`, its tensors named there; it acts with
            any K nearest UAVs and obstacles).
    """

    config: dict[str, Any]
    obs_dim: int
    activation: str
    hidden: tuple[int, ...]
    obs_norm: bool
    clip_obs: float = 10.0
    obs_epsilon: float = 1e-8
    algorithm: str = "PPO"
    info: dict[str, Any] = field(default_factory=dict)
    format: str = CHECKPOINT_FORMAT
    layout: StoredLayout | None = None
    architecture: str = "mlp"

    @property
    def env_config(self) -> EnvConfig:
        """The training config, validated."""
        return make_config(_tuples(self.config))

    @property
    def env_version(self) -> int:
        """The env version it was trained in (``info["env_version"]``, or 2 if unrecorded).

        :func:`save_policy` records it; files written before it did (before ``-v3``) say
        :data:`UNRECORDED_ENV_VERSION`.
        """
        return int(self.info.get("env_version", UNRECORDED_ENV_VERSION))

    @property
    def action_mode(self) -> str:
        """``"direct"`` or a residual mode (``"residual_apf"``, ``"residual_mvp_region"``)."""
        return self.env_config.action.mode

    @property
    def observation_layout(self) -> StoredLayout:
        """The layout the network reads (stored, or derived from the training config)."""
        return self.layout or StoredLayout.from_config(self.env_config)


def _tuples(value: Any) -> Any:
    """JSON lists back to the tuples the config uses (``formation``, ``wind``)."""
    if isinstance(value, Mapping):
        return {k: _tuples(v) for k, v in value.items()}
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


def save_policy(
    path: str | Path,
    meta: PolicyCheckpoint,
    weights: Sequence[tuple[np.ndarray, np.ndarray]],
    obs_mean: np.ndarray | None = None,
    obs_var: np.ndarray | None = None,
) -> Path:
    """Write a policy checkpoint (JSON description + ``.npz`` arrays in one zip), atomically.

    The current format (:data:`CHECKPOINT_FORMAT`) is written, with the observation layout
    (``meta.layout``, or the training config's) and the env version it was trained in
    (``info["env_version"]``: ``meta.info``'s, else this package's,
    :data:`~uasep_env.registration.ENV_VERSION`, so every recipe records it).

    A ``"set"`` network's ``weights`` come in the order of
    :func:`~uasep_env.policies.set_network.tensor_shapes`, and are stored by its names; an
    MLP's as ``layer<k>``. ``architecture`` is written only for a set network (an MLP file
    reads as before, in this version and earlier ones).

    Returns:
        The path written.
    """
    from uasep_env.policies.set_network import tensor_shapes

    names = (
        list(tensor_shapes(meta.observation_layout, meta.hidden))
        if meta.architecture == "set"
        else [f"layer{k}" for k in range(len(weights))]
    )
    if len(names) != len(weights):
        raise ValueError(
            f"{len(weights)} layers given, the {meta.architecture} network has {len(names)}"
        )
    arrays: dict[str, np.ndarray] = {}
    for name, (w, b) in zip(names, weights, strict=True):
        arrays[f"{name}.weight"] = np.asarray(w, np.float32)
        arrays[f"{name}.bias"] = np.asarray(b, np.float32)
    if meta.obs_norm:
        arrays["obs_mean"] = np.asarray(obs_mean, np.float64)
        arrays["obs_var"] = np.asarray(obs_var, np.float64)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    desc = {
        **asdict(meta),
        # The current env version: the newest VERSION_DEFAULTS has (registration.ENV_VERSION).
        "info": {"env_version": max(VERSION_DEFAULTS), **meta.info},
        "format": CHECKPOINT_FORMAT,
        "hidden": list(meta.hidden),
        "n_layers": len(weights),
        "layout": meta.observation_layout.to_dict(),
    }
    if meta.architecture == "mlp":
        del desc["architecture"]
    with atomic_output(path) as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(META, dumps(desc, indent=2, sort_keys=True))
        z.writestr(WEIGHTS, buf.getvalue())
    return Path(path)
