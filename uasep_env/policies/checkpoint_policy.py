"""The project's policy checkpoints as policies: a numpy MLP actor read from a ``.zip``.

A **policy checkpoint** (``.zip``) is what training ships (``baselines/checkpoints/``): a zip
holding ``uasep_policy.json`` (format, the environment config it was trained in, its action
mode, observation layout, network shape and training facts) and ``weights.npz`` (the actor's
layers and the observation normalisation statistics, plain float arrays). The file format
and its reader with hard limits live in :mod:`uasep_env.policies.checkpoint` and
:mod:`~uasep_env.policies.checkpoint_reader`: nothing from the file is unpickled and no code
from it runs. The actor runs in numpy, so evaluating a checkpoint needs neither torch nor
stable-baselines3.

A checkpoint fits any environment that gives its network the observation layout it reads
(the K nearest UAVs and obstacles, the same features in the same order): a policy trained on
3 UAVs flies 8 or 32 when ``observation.k_uavs`` / ``k_obstacles`` are fixed to its own
(:func:`checkpoint_config` builds such a config, :func:`observed_config` gives any config
the checkpoint's observation). A permutation-invariant checkpoint (``"architecture": "set"``,
:mod:`~uasep_env.policies.set_network`) reads any K: those two keep a K the config sets.

stable-baselines3 models are another concern: :mod:`uasep_env.policies.sb3_policy`.
"""

from __future__ import annotations

import functools
import warnings
import zipfile
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.config import EnvConfig
from uasep_env.interface.actions import Residual
from uasep_env.policies.checkpoint import META, CheckpointError, PolicyCheckpoint, StoredLayout
from uasep_env.policies.checkpoint_reader import read_checkpoint
from uasep_env.policies.guard import finite_observations
from uasep_env.policies.set_network import SetNetwork, set_difference

if TYPE_CHECKING:
    from uasep_env.policies.apf import APFGains

__all__ = [
    "EnvVersionWarning",
    "LearnedPolicy",
    "checkpoint_config",
    "checkpoint_path",
    "dense",
    "dense_sums",
    "is_policy_checkpoint",
    "load_policy",
    "observed_config",
]


def dense(x: np.ndarray, wt: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One layer, ``x @ wt + b``, summed input by input in float64 and rounded to float32.

    A BLAS kernel sums in an order that depends on the CPU it dispatches to (OpenBLAS's
    Haswell and SkylakeX kernels differ in the last bits), and a closed loop grows a last bit
    into another episode. The products of float32 numbers are exact in float64 and the sum
    runs in one fixed order of elementwise IEEE operations, so every CPU and numpy version
    computes the same bits (with numba, the kernel ``dense``, the same operations).

    Args:
        x: Inputs ``(rows, n_in)``, float32.
        wt: The transposed weights ``(n_in, n_out)``, float64.
        b: The bias ``(n_out,)``, float64.

    Returns:
        ``(rows, n_out)`` float32: :func:`dense_sums` rounded once.
    """
    return dense_sums(x, wt, b).astype(np.float32)


@compiled_twin("dense")
def dense_sums(x: np.ndarray, wt: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The float64 sums of :func:`dense`, before the rounding (the kernel ``dense``'s too).

    Args:
        x: Inputs ``(rows, n_in)``, float32.
        wt: The transposed weights ``(n_in, n_out)``, float64.
        b: The bias ``(n_out,)``, float64.

    Returns:
        ``(rows, n_out)`` float64: the bias, then input ``i``'s products in the order of ``i``.
    """
    x = np.asarray(x, dtype=np.float64)
    acc = np.empty((x.shape[0], b.shape[0]), dtype=np.float64)
    acc[...] = b
    for i in range(wt.shape[0]):
        acc += x[:, i, None] * wt[i]
    return acc


_ACTIVATIONS = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
}


@finite_observations  # as every registered policy
class LearnedPolicy:
    """A checkpoint's actor (an MLP in numpy) behind the common policy interface.

    The policy acts in an environment whose config is ``config``. A residual policy
    (``residual_apf``, ``residual_mvp_region``) in a ``direct`` environment computes its base
    controller's command itself and returns the corrected command
    (:class:`~uasep_env.interface.actions.Residual`, the same numbers as the residual
    environment), so it is evaluated beside the controllers on the same seeds; in its own
    residual environment it returns its correction. (The corrected command is returned in
    float64, the precision the residual environment adds it in.)

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
        CheckpointError: When the environment does not fit the checkpoint (observation
            layout: K nearest UAVs/obstacles, features and widths; action mode), naming the
            first difference.
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
        env_layout = _check_fits(meta, trained, config)
        # The base controller flies this env (its size), with the trained action settings.
        self._residual = (
            Residual(config.replace(action=asdict(trained.action)), base_gains)
            if self.mode != "direct" and config.action.mode == "direct"
            else None
        )
        if base_gains is not None and self._residual is None:
            raise ValueError(
                f"base_gains={base_gains!r}: only a residual policy acting in a direct "
                f"environment computes its base controller (this is a {self.mode} policy in a "
                f"{config.action.mode} environment)"
            )
        # float32 as stored, kept transposed in float64 for :func:`dense`.
        self._layers = [
            (np.ascontiguousarray(np.asarray(w, np.float32).T, dtype=np.float64),
             np.asarray(b, np.float32).astype(np.float64))
            for w, b in weights
        ]  # fmt: skip
        self._act = _ACTIVATIONS[meta.activation]
        # The set network reads the env's own K (its weights fit any); the MLP the stored K.
        self._set = (
            SetNetwork(meta.observation_layout, env_layout, meta.hidden, self._act, dense,
                       weights, obs_mean if meta.obs_norm else None, obs_var,
                       meta.obs_epsilon, meta.clip_obs)
            if meta.architecture == "set" else None
        )  # fmt: skip
        if meta.obs_norm:
            self._mean = np.asarray(obs_mean, dtype=np.float64)
            self._std = np.sqrt(np.asarray(obs_var, dtype=np.float64) + meta.obs_epsilon)

    def network(self, obs: np.ndarray) -> np.ndarray:
        """The deterministic action (the Gaussian's mean) for the network's own input."""
        x = np.asarray(obs, dtype=np.float32)
        if self._set is not None:
            out = self._set(np.ascontiguousarray(x.reshape(-1, x.shape[-1])))
            return out.reshape(*x.shape[:-1], 3)
        if self.meta.obs_norm:
            x = np.clip((x - self._mean) / self._std, -self.meta.clip_obs, self.meta.clip_obs)
            x = x.astype(np.float32)
        shape = x.shape[:-1]
        x = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        for wt, b in self._layers[:-1]:
            x = self._act(dense(x, wt, b))
        x = dense(x, *self._layers[-1])
        return x.reshape(*shape, x.shape[-1])

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


def _check_fits(meta: PolicyCheckpoint, trained: EnvConfig, config: EnvConfig) -> StoredLayout:
    """The env must give the network the layout it reads (any number of UAVs/obstacles).

    The slot MLP reads its own K nearest UAVs and obstacles; a set network any K (the same
    own and slot features). Returns the env's layout.
    """
    problems = []
    if trained.action.mode == "direct" and config.action.mode != "direct":
        problems.append(f"action.mode: trained with 'direct', this env uses {config.action.mode!r}")
    elif config.action.mode not in ("direct", trained.action.mode):
        # A correction of one base added to another's command would fly neither.
        problems.append(
            f"action.mode: trained with {trained.action.mode!r}, this env uses "
            f"{config.action.mode!r}"
        )
    env_layout = StoredLayout.from_config(config.replace(action=asdict(trained.action)))
    if meta.architecture == "set":
        difference = set_difference(meta.observation_layout, env_layout)
    else:
        difference = meta.observation_layout.difference(env_layout)
    if difference is not None:
        problems.append(difference)
    if problems:
        raise CheckpointError("checkpoint does not fit this environment: " + "; ".join(problems))
    return env_layout


def _own_k(meta: PolicyCheckpoint, observation: dict[str, Any]) -> dict[str, Any]:
    """The observation's K nearest UAVs and obstacles for the checkpoint's network.

    The slot MLP's own K; a set network keeps the K that ``observation`` sets (its weights
    fit any), else takes its own.
    """
    layout = meta.observation_layout
    own = {"k_uavs": layout.k_uavs, "k_obstacles": layout.k_obstacles}
    if meta.architecture == "set":
        return {k: own[k] if observation.get(k) is None else observation[k] for k in own}
    return own


class EnvVersionWarning(UserWarning):
    """A checkpoint acts in an env whose prediction is not the one it was trained with."""


def _warn_if_other_env(meta: PolicyCheckpoint, path: Path, config: EnvConfig) -> None:
    """Warn (:class:`EnvVersionWarning`) when ``config`` predicts otherwise than training did.

    Not an error: the trade-off sweep and users play checkpoints in other envs on purpose
    (:mod:`uasep_env.policies.env_version` says which version a checkpoint plays).
    """
    fit = meta.env_config.prediction.fit
    if config.prediction.fit != fit:
        warnings.warn(
            f"{path}: trained in env -v{meta.env_version} with prediction.fit={fit!r}, this "
            f"env has prediction.fit={config.prediction.fit!r}: not the episodes it was "
            f"trained on (config=make_config(VERSION_DEFAULTS[{meta.env_version}], ...) plays "
            "its own)",
            EnvVersionWarning,
            stacklevel=3,
        )


def is_policy_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a zip in this project's checkpoint format (by its member names)."""
    try:
        with zipfile.ZipFile(path) as z:
            return META in z.namelist()
    except (OSError, zipfile.BadZipFile, ValueError, EOFError):
        return False


@functools.lru_cache(maxsize=16)
def _cached_read(path: str, mtime_ns: int, size: int) -> tuple:
    return read_checkpoint(Path(path))


def _read(path: str | Path) -> tuple:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"no policy checkpoint at {p}")
    st = p.stat()
    return _cached_read(str(p.resolve()), st.st_mtime_ns, st.st_size)


def checkpoint_config(
    path: str | Path,
    n_uavs: int | None = None,
    n_obstacles: int | None = None,
    **overrides: Any,
) -> EnvConfig:
    """The env config a checkpoint's policy can act in, at another formation size.

    The training config (``direct`` action mode, the mode policies are evaluated in) with
    ``n_uavs`` / ``n_obstacles`` replaced and the observation's K nearest UAVs and obstacles
    fixed to the checkpoint's, so the observation has the layout the network reads.

    Args:
        path: The checkpoint.
        n_uavs: Formation size (default: the training one).
        n_obstacles: Number of obstacles (default: the training one).
        **overrides: More config fields (e.g. ``scenario="random"``).

    Returns:
        The validated config (``load_policy(path, config)`` accepts it).

    Raises:
        CheckpointError: If no such config gives the checkpoint's layout (e.g. ``n_uavs``
            not above its ``k_uavs``), naming the difference.
    """
    meta = _read(path)[0]
    trained = meta.env_config
    values: dict[str, Any] = {
        "n_uavs": trained.n_uavs if n_uavs is None else n_uavs,
        "n_obstacles": trained.n_obstacles if n_obstacles is None else n_obstacles,
        **overrides,
    }
    observation = {**dict(overrides.get("observation") or {})}
    observation.update(_own_k(meta, observation))
    values["observation"] = observation
    values.setdefault("action", {"mode": "direct"})
    config = trained.replace(**values)
    _check_fits(meta, trained, config)
    return config


def checkpoint_path(spec: str | Path) -> Path | None:
    """The policy checkpoint ``spec`` names, or None for anything else.

    Args:
        spec: A path, or the name of a shipped policy (``"ppo_shared"``) when no such file
            exists.

    Returns:
        The checkpoint file, or None (a built-in name, an SB3 model, no such file).
    """
    p = Path(spec)
    if p.is_file():
        return p if is_policy_checkpoint(p) else None
    if isinstance(spec, str) and not p.exists():
        from uasep_env.policies.shipped import shipped_policy_path

        return shipped_policy_path(spec)
    return None


def observed_config(path: str | Path, config: EnvConfig) -> EnvConfig:
    """``config`` observed as the checkpoint's network reads it: its training observation.

    The observation group (K nearest UAVs and obstacles, scales, optional features) is the
    checkpoint's; everything else is ``config``'s. The observation does not move the world,
    so the episodes are the ones ``config`` gives every other policy: this is how a
    checkpoint trained on 3 UAVs flies beside the APF at 8 zero-shot (``uasep-eval
    --policy ppo_shared,apf --config n_uavs=8``, ``uasep-report``).

    Args:
        path: The checkpoint.
        config: The environment every policy of the comparison plays.

    Returns:
        The validated config (``load_policy(path, result)`` accepts it whenever the formation
        has more than ``k_uavs`` UAVs).
    """
    meta = _read(path)[0]
    # K: the stored layout's (format 2) or its training config's; a set network's: config's.
    k = _own_k(meta, asdict(config.observation))
    observation = {**asdict(meta.env_config.observation), **k}
    return config.replace(observation=observation)


def load_policy(
    path: str | Path,
    config: EnvConfig | None = None,
    name: str | None = None,
    base_gains: APFGains | None = None,
) -> LearnedPolicy:
    """Load a policy checkpoint (read once per process while the file is unchanged).

    Args:
        path: The checkpoint (``.zip``), or the name of a shipped policy (``"ppo_shared"``,
            :func:`~uasep_env.policies.shipped.shipped_policies`) when no such file exists.
        config: The environment config it will act in (default: its own, ``direct`` mode).
        name: Label in reports (default: the file's stem).
        base_gains: The gains of the APF a residual policy corrects (see
            :class:`LearnedPolicy`).

    Returns:
        The policy.

    Warns:
        EnvVersionWarning: (a ``UserWarning``) when ``config``'s prediction
            (``prediction.fit``) is not the one it was trained with: another env version's
            episodes (:mod:`uasep_env.policies.env_version`).

    Raises:
        FileNotFoundError: If ``path`` does not exist.
        CheckpointError: For a file that is not a valid checkpoint, or one that does not fit
            ``config`` (the mismatch is named).
    """
    p = Path(path)
    if not p.exists() and isinstance(path, str):
        from uasep_env.policies.shipped import shipped_policy_path

        p = shipped_policy_path(path) or p
    if not p.is_file():
        raise FileNotFoundError(f"no policy checkpoint at {p} (and no shipped policy {path!r})")
    meta, weights, mean, var = _read(p)
    if config is not None:
        _warn_if_other_env(meta, p, config)
    return LearnedPolicy(
        meta, weights, mean, var, config=config, name=name or p.stem, base_gains=base_gains
    )
