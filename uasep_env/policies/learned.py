"""Learned policies: the project's checkpoint format, and stable-baselines3 models.

A **policy checkpoint** (``.zip``) is what training ships (``baselines/checkpoints/``): a zip
holding ``uasep_policy.json`` (format, the environment config it was trained in, its action
mode, observation width, network shape and training facts) and ``weights.npz`` (the actor's
layers and the observation normalisation statistics, plain float arrays). Loading reads JSON
and ``numpy.load(..., allow_pickle=False)``: nothing from the file is unpickled and no code
from it runs. The actor runs in numpy, so evaluating a checkpoint needs neither torch nor
stable-baselines3.

A stable-baselines3 ``.zip`` is different: SB3's loader unpickles (runs) objects stored in
the file. :func:`load_sb3_policy` therefore refuses it unless the caller opts in with
``allow_pickle=True`` (``uasep-eval --allow-pickle``), for files they trust.

Importing this module does not import stable-baselines3 or torch.
"""

from __future__ import annotations

import functools
import io
import json
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.actions import ResidualAPF
from uasep_env.config import EnvConfig, make_config
from uasep_env.jsonio import dumps
from uasep_env.observation import ObservationLayout

if TYPE_CHECKING:
    from uasep_env.policies.apf import APFGains

__all__ = [
    "CHECKPOINT_FORMAT",
    "CheckpointError",
    "LearnedPolicy",
    "PolicyCheckpoint",
    "SB3Policy",
    "is_policy_checkpoint",
    "load_policy",
    "load_sb3_policy",
    "save_policy",
]

#: Format tag written into every checkpoint's JSON.
CHECKPOINT_FORMAT = "uasep-policy/1"
_META = "uasep_policy.json"
_WEIGHTS = "weights.npz"
_ACTIVATIONS = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
}
_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")


class CheckpointError(ValueError):
    """A file that is not a usable policy checkpoint, or one that does not fit the env."""


@dataclass(frozen=True)
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
        format: :data:`CHECKPOINT_FORMAT`.
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

    @property
    def env_config(self) -> EnvConfig:
        """The training config, validated."""
        return make_config(_tuples(self.config))

    @property
    def action_mode(self) -> str:
        """``"direct"`` or ``"residual_apf"``."""
        return self.env_config.action.mode


def _tuples(value: Any) -> Any:
    """JSON lists back to the tuples the config uses (``formation``, ``wind``)."""
    if isinstance(value, Mapping):
        return {k: _tuples(v) for k, v in value.items()}
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


class LearnedPolicy:
    """A checkpoint's actor (an MLP in numpy) behind the common policy interface.

    The policy acts in an environment whose config is ``config``. A ``residual_apf``
    policy in a ``direct`` environment computes the APF's command itself and returns the
    corrected command (:class:`~uasep_env.actions.ResidualAPF`, the same numbers as the
    ``residual_apf`` environment), so it is evaluated beside the APFs on the same seeds;
    in a ``residual_apf`` environment it returns its correction. (The corrected command is
    returned in float64, the precision the residual environment adds it in.)

    Args:
        meta: The checkpoint's description.
        weights: ``[(W, b), ...]`` float32 layers, the last one the action head.
        obs_mean: Observation mean (``obs_dim``) when ``meta.obs_norm``.
        obs_var: Observation variance when ``meta.obs_norm``.
        config: The environment config it will act in (default: its training config in
            ``direct`` mode).
        name: Label in reports.
        base_gains: For a ``residual_apf`` policy acting in a ``direct`` environment, the
            gains of the APF it corrects (default: the environments' default gains, which
            it was trained on). Anywhere else it is an error (nothing would use it).

    Raises:
        CheckpointError: When the environment does not fit the checkpoint (number of UAVs,
            observation width, action mode), naming the mismatch.
    """

    def __init__(
        self,
        meta: PolicyCheckpoint,
        weights: Sequence[tuple[np.ndarray, np.ndarray]],
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        config: EnvConfig | None = None,
        name: str = "learned",
        base_gains: APFGains | None = None,
    ) -> None:
        trained = meta.env_config
        if config is None:
            config = trained.replace(action={"mode": "direct"})
        self.meta = meta
        self.config = config
        self.name = name
        self.mode = trained.action.mode
        _check_fits(meta, trained, config)
        self._residual = (
            ResidualAPF(trained, base_gains)
            if self.mode == "residual_apf" and config.action.mode == "direct"
            else None
        )
        if base_gains is not None and self._residual is None:
            raise ValueError(
                f"base_gains={base_gains!r}: only a residual_apf policy acting in a direct "
                f"environment computes its base APF (this is a {self.mode} policy in a "
                f"{config.action.mode} environment)"
            )
        self._layers = [(np.asarray(w, np.float32), np.asarray(b, np.float32)) for w, b in weights]
        self._act = _ACTIVATIONS[meta.activation]
        if meta.obs_norm:
            self._mean = np.asarray(obs_mean, dtype=np.float64)
            self._std = np.sqrt(np.asarray(obs_var, dtype=np.float64) + meta.obs_epsilon)

    def network(self, obs: np.ndarray) -> np.ndarray:
        """The deterministic action (the Gaussian's mean) for the network's own input."""
        x = np.asarray(obs, dtype=np.float32)
        if self.meta.obs_norm:
            x = np.clip((x - self._mean) / self._std, -self.meta.clip_obs, self.meta.clip_obs)
            x = x.astype(np.float32)
        for w, b in self._layers[:-1]:
            x = self._act(x @ w.T + b)
        w, b = self._layers[-1]
        return x @ w.T + b

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Actions ``(..., 3)`` in ``[-1, 1]`` for observations ``(..., obs_dim)``."""
        obs = np.asarray(observations, dtype=np.float32)
        if self._residual is None:
            return np.clip(self.network(obs), -1.0, 1.0).astype(np.float32)
        base = self._residual.base(obs)
        residual = np.clip(self.network(self._residual.observe(obs, base)), -1.0, 1.0)
        # As the residual env would take it: a float32 action, then float64 arithmetic.
        residual = residual.astype(np.float32).astype(np.float64)
        return self._residual.command(base, residual)

    def reset(self) -> None:
        """MLP policies are memoryless."""


def _check_fits(meta: PolicyCheckpoint, trained: EnvConfig, config: EnvConfig) -> None:
    problems = []
    if trained.action.mode == "direct" and config.action.mode != "direct":
        problems.append(f"action.mode: trained with 'direct', this env uses {config.action.mode!r}")
    env_layout = ObservationLayout.from_config(config.replace(action=asdict(trained.action)))
    if env_layout.dim != meta.obs_dim:
        # Only the layout matters (a fixed-K policy flies any n_uavs); name n_uavs if it moved.
        if config.n_uavs != trained.n_uavs:
            problems.append(f"n_uavs: trained with {trained.n_uavs}, this env has {config.n_uavs}")
        problems.append(
            f"observation width: the network reads {meta.obs_dim}, this env gives "
            f"{env_layout.dim} (k_uavs/k_obstacles/n_obstacles differ)"
        )
    if problems:
        raise CheckpointError("checkpoint does not fit this environment: " + "; ".join(problems))


def is_policy_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a zip in this project's checkpoint format."""
    try:
        with zipfile.ZipFile(path) as z:
            return _META in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def save_policy(
    path: str | Path,
    meta: PolicyCheckpoint,
    weights: Sequence[tuple[np.ndarray, np.ndarray]],
    obs_mean: np.ndarray | None = None,
    obs_var: np.ndarray | None = None,
) -> Path:
    """Write a policy checkpoint (JSON description + ``.npz`` arrays in one zip).

    Returns:
        The path written.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {}
    for k, (w, b) in enumerate(weights):
        arrays[f"layer{k}.weight"] = np.asarray(w, np.float32)
        arrays[f"layer{k}.bias"] = np.asarray(b, np.float32)
    if meta.obs_norm:
        arrays["obs_mean"] = np.asarray(obs_mean, np.float64)
        arrays["obs_var"] = np.asarray(obs_var, np.float64)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    desc = {**asdict(meta), "hidden": list(meta.hidden), "n_layers": len(weights)}
    tmp = p.with_name(p.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(_META, dumps(desc, indent=2, sort_keys=True))
        z.writestr(_WEIGHTS, buf.getvalue())
    tmp.replace(p)
    return p


def _read_checkpoint(
    p: Path,
) -> tuple[PolicyCheckpoint, list[tuple[np.ndarray, np.ndarray]], Any, Any]:
    """Parse a checkpoint file; every failure is a one-line :class:`CheckpointError`."""
    try:
        with zipfile.ZipFile(p) as z:
            desc = json.loads(z.read(_META).decode("utf-8"))
            raw = z.read(_WEIGHTS)
    except (zipfile.BadZipFile, KeyError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CheckpointError(f"{p} is not a uasep policy checkpoint ({err})") from err
    if not isinstance(desc, dict) or desc.get("format") != CHECKPOINT_FORMAT:
        got = desc.get("format") if isinstance(desc, dict) else type(desc).__name__
        raise CheckpointError(
            f"{p}: unknown checkpoint format {got!r}, expected {CHECKPOINT_FORMAT}"
        )
    n_layers = desc.pop("n_layers", None)
    try:
        meta = PolicyCheckpoint(**{**desc, "hidden": tuple(desc.get("hidden", ()))})
        meta.env_config  # noqa: B018 (validates the stored config)
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{p}: invalid checkpoint description ({err})") from err
    if meta.activation not in _ACTIVATIONS:
        raise CheckpointError(f"{p}: unknown activation {meta.activation!r}")
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (ValueError, OSError, zipfile.BadZipFile) as err:
        raise CheckpointError(f"{p}: unreadable weights ({err})") from err
    try:
        weights = [
            (arrays[f"layer{k}.weight"], arrays[f"layer{k}.bias"]) for k in range(int(n_layers))
        ]
        mean = arrays["obs_mean"] if meta.obs_norm else None
        var = arrays["obs_var"] if meta.obs_norm else None
    except (KeyError, TypeError) as err:
        raise CheckpointError(f"{p}: missing weights ({err})") from err
    _check_shapes(p, meta, weights, mean, var)
    return meta, weights, mean, var


def _check_shapes(
    p: Path,
    meta: PolicyCheckpoint,
    weights: list[tuple[np.ndarray, np.ndarray]],
    mean: np.ndarray | None,
    var: np.ndarray | None,
) -> None:
    width = meta.obs_dim
    sizes = [*meta.hidden, 3]
    if len(weights) != len(sizes):
        raise CheckpointError(f"{p}: {len(weights)} layers stored, the description says {sizes}")
    for k, ((w, b), out) in enumerate(zip(weights, sizes, strict=True)):
        if w.shape != (out, width) or b.shape != (out,):
            raise CheckpointError(
                f"{p}: layer {k} has shapes {w.shape}/{b.shape}, expected ({out}, {width})/({out},)"
            )
        if w.dtype.kind != "f" or not (np.isfinite(w).all() and np.isfinite(b).all()):
            raise CheckpointError(f"{p}: layer {k} holds non-finite or non-float values")
        width = out
    if meta.obs_norm:
        for name, a in (("obs_mean", mean), ("obs_var", var)):
            if a is None or a.shape != (meta.obs_dim,) or not np.isfinite(a).all():
                raise CheckpointError(f"{p}: {name} must be {meta.obs_dim} finite values")
        if (var < 0).any():
            raise CheckpointError(f"{p}: obs_var has negative entries")


@functools.lru_cache(maxsize=16)
def _cached_read(path: str, mtime_ns: int, size: int) -> tuple:
    return _read_checkpoint(Path(path))


def load_policy(
    path: str | Path,
    config: EnvConfig | None = None,
    name: str | None = None,
    base_gains: APFGains | None = None,
) -> LearnedPolicy:
    """Load a policy checkpoint (read once per process while the file is unchanged).

    Args:
        path: The checkpoint (``.zip``).
        config: The environment config it will act in (default: its own, ``direct`` mode).
        name: Label in reports (default: the file's stem).
        base_gains: The gains of the APF a residual policy corrects (see
            :class:`LearnedPolicy`).

    Returns:
        The policy.

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        CheckpointError: For a file that is not a valid checkpoint, or one that does not fit
            ``config`` (the mismatch is named).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no policy checkpoint at {p}")
    st = p.stat()
    meta, weights, mean, var = _cached_read(str(p.resolve()), st.st_mtime_ns, st.st_size)
    return LearnedPolicy(
        meta, weights, mean, var, config=config, name=name or p.stem, base_gains=base_gains
    )


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
    if name not in _ALGORITHMS:
        raise CheckpointError(f"unknown SB3 algorithm {name!r}; choose from {_ALGORITHMS}")
    model = _load_sb3(str(p.resolve()), p.stat().st_mtime_ns, name)
    return SB3Policy(model, config)


@functools.lru_cache(maxsize=4)
def _load_sb3(path: str, mtime_ns: int, algorithm: str) -> Any:
    import stable_baselines3 as sb3  # lazy: heavy, optional dependency

    try:
        return getattr(sb3, algorithm).load(path, device="cpu")
    except Exception as err:  # SB3 raises many types for a bad file
        raise CheckpointError(f"could not load {path} as {algorithm}: {err}") from err
