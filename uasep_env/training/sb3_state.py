"""Where an SB3 run's rollouts stand: what a checkpoint keeps so that ``--resume`` is exact.

An SB3 recipe's checkpoint (:func:`uasep_env.training.ppo_shared.save_checkpoint`) is saved at
a rollout boundary: when the next rollout starts, after the last one's updates (the
multiplier's at its end, then PPO's weights), so the rollout buffer is empty and nothing of
a rollout in progress needs keeping. What the weights, the optimiser, torch's random state
and the normalisation statistics (``state.pt``, ``normalization.npz``) do not hold is here,
as plain arrays in ``env_state.npz`` (:func:`env_state_bytes`; read back with
``allow_pickle=False`` by :func:`uasep_env.training.checkpoint_readers.read_env_state`):

* ``env.*``: the environments' episodes in progress
  (:meth:`uasep_env.envs.sb3.UAVSharedVecEnv.state_dict`: the world's arrays, its
  generators' states, the last observations, the episodes' safety so far);
* ``monitor.*``: ``VecMonitor``'s running episode returns and lengths (``progress.csv``'s
  returns and lengths); ``normalize.returns``: ``VecNormalize``'s discounted returns
  (the return statistics it updates);
* ``model.*``: SB3's last observations and episode starts (what the next rollout starts
  from, instead of a reset) and its update count;
* ``numpy.*``: numpy's global random state (SB3 draws the minibatches' order from it).

skrl's MAPPO loop (:mod:`uasep_env.training.mappo`) keeps the same environment stack's
state (:func:`venv_state`) with its own arrays in place of SB3's
(:meth:`uasep_env.training.mappo.SkrlView.rollout_state`: ``skrl.obs``, ``skrl.timestep``).

With them a resumed run continues exactly: the same weights, multiplier, ``progress.csv``
(but its wall times) and ``cost_progress.csv`` as an uninterrupted run, bit for bit.
SB3's episode-info buffer is not kept (it feeds only SB3's own logger, not the CSVs).

This module imports stable-baselines3; the rest of the package does not.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from uasep_env.envs.sb3 import UAVSharedVecEnv
from uasep_env.sim.snapshot import check_arrays, check_range, copy_arrays

__all__ = [
    "ENV_OPTIONS",
    "ENV_STATE_FILE",
    "continues_episodes",
    "env_state_bytes",
    "load_rollout_state",
    "load_venv_state",
    "npz_bytes",
    "rollout_state",
    "venv_state",
]

#: The checkpoint file of :func:`env_state_bytes`.
ENV_STATE_FILE = "env_state.npz"
#: The options that make the environments and what they observe: a checkpoint's episodes
#: continue only under the same ones (:func:`continues_episodes`).
ENV_OPTIONS = ("n_envs", "seed", "n_uavs", "n_obstacles", "k_uavs", "k_obstacles",
               "episode_duration", "residual_scale", "scenario", "config", "action_mode",
               "norm_obs")  # fmt: skip
#: numpy's global generator (MT19937): its key's length.
_MT_WORDS = 624


def continues_episodes(args: Any, resumed: dict, folder: Path) -> bool:
    """Whether a run resumed from ``folder`` continues its environments' episodes.

    It does where the checkpoint has their state (:data:`ENV_STATE_FILE`) and the run has
    the checkpoint's :data:`ENV_OPTIONS` (``resumed``: its ``state.json``); otherwise (a
    checkpoint of an older version, ``--n-envs`` or the environment changed) the
    environments restart their episodes from their seeds.
    """
    theirs = resumed.get("args", {})
    same = all(theirs.get(k) == getattr(args, k) for k in ENV_OPTIONS)
    return same and os.path.lexists(Path(folder) / ENV_STATE_FILE)


def _layers(venv: Any) -> tuple[UAVSharedVecEnv, VecMonitor | None, VecNormalize | None]:
    """The adapter under ``venv`` and the monitor and normaliser on the way (if any)."""
    monitor = normalize = None
    env = venv
    while not isinstance(env, UAVSharedVecEnv):
        if isinstance(env, VecMonitor):
            monitor = env
        elif isinstance(env, VecNormalize):
            normalize = env
        env = getattr(env, "venv", None)
        if env is None:
            raise TypeError(f"{venv!r} does not wrap a UAVSharedVecEnv")
    return env, monitor, normalize


def _wrappers(venv: Any) -> dict[str, np.ndarray]:
    """The arrays outside the adapter and the trainer: live where they exist.

    ``VecMonitor``'s and ``VecNormalize``'s running figures (live) and numpy's global
    random state (arrays of its shapes and dtypes).
    """
    _, monitor, normalize = _layers(venv)
    arrays = {
        "numpy.key": np.zeros(_MT_WORDS, dtype=np.uint32),
        "numpy.pos": np.zeros((), dtype=np.int64),
        "numpy.has_gauss": np.zeros((), dtype=np.int64),
        "numpy.gauss": np.zeros((), dtype=np.float64),
    }
    if monitor is not None:
        arrays["monitor.episode_returns"] = monitor.episode_returns
        arrays["monitor.episode_lengths"] = monitor.episode_lengths
        arrays["monitor.episode_count"] = np.zeros((), dtype=np.int64)
    if normalize is not None:
        arrays["normalize.returns"] = normalize.returns
    return arrays


def venv_state(venv: Any, trainer: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The environment stack's state (module docstring) and the ``trainer``'s arrays, copied.

    Args:
        venv: ``VecNormalize`` over ``VecMonitor`` over
            :class:`~uasep_env.envs.sb3.UAVSharedVecEnv` (either wrapper may be absent).
        trainer: What the trainer adds (its last observations, its counters), by name.
    """
    env, monitor, _ = _layers(venv)
    state = {f"env.{k}": v for k, v in env.state_dict().items()}
    state |= {k: np.array(v) for k, v in _wrappers(venv).items()}  # copies
    if monitor is not None:
        state["monitor.episode_count"] = np.array(monitor.episode_count, dtype=np.int64)
    rng = np.random.get_state(legacy=False)  # noqa: NPY002 (SB3's minibatches draw from it)
    state["numpy.key"] = np.asarray(rng["state"]["key"], dtype=np.uint32).copy()
    state["numpy.pos"] = np.array(rng["state"]["pos"], dtype=np.int64)
    state["numpy.has_gauss"] = np.array(rng["has_gauss"], dtype=np.int64)
    state["numpy.gauss"] = np.array(rng["gauss"], dtype=np.float64)
    return state | {k: np.array(v) for k, v in trainer.items()}


def load_venv_state(
    venv: Any, state: dict[str, np.ndarray], trainer: dict[str, np.ndarray], counters: tuple = ()
) -> dict[str, np.ndarray]:
    """Continue ``venv`` from a :func:`venv_state`; the trainer's arrays, checked, for it to use.

    Everything is checked before anything is written: the adapter's arrays
    (:meth:`~uasep_env.envs.sb3.UAVSharedVecEnv.load_state_dict`), the wrappers' and the
    trainer's, each of the shape and dtype of ``trainer``'s (arrays of the run's own shapes
    and dtypes), finite, the ``counters`` among them >= 0.

    Returns:
        Copies of the trainer's arrays (the names of ``trainer``).

    Raises:
        ValueError: One line naming the array.
    """
    env, monitor, _ = _layers(venv)
    live = _wrappers(venv)
    like = live | trainer
    ours = {k: v for k, v in state.items() if not k.startswith("env.")}
    check_arrays(ours, like)
    for name in (*counters, "monitor.episode_count", "monitor.episode_lengths"):
        if name in ours:
            check_range(name, ours[name], 0, 2**62)
    check_range("numpy.pos", ours["numpy.pos"], 0, _MT_WORDS)
    check_range("numpy.has_gauss", ours["numpy.has_gauss"], 0, 1)
    try:
        env.load_state_dict({k[4:]: v for k, v in state.items() if k.startswith("env.")})
    except ValueError as err:  # named as in this state
        raise ValueError(f"env.{err}") from None
    inplace = [k for k in ("monitor.episode_returns", "monitor.episode_lengths",
                           "normalize.returns") if k in live]  # fmt: skip
    copy_arrays({k: ours[k] for k in inplace}, {k: live[k] for k in inplace})
    if monitor is not None:
        monitor.episode_count = int(ours["monitor.episode_count"])
    np.random.set_state(  # noqa: NPY002
        {"bit_generator": "MT19937",
         "state": {"key": ours["numpy.key"].copy(), "pos": int(ours["numpy.pos"])},
         "has_gauss": int(ours["numpy.has_gauss"]), "gauss": float(ours["numpy.gauss"])}
    )  # fmt: skip
    return {k: ours[k].copy() for k in trainer}


def _model_like(venv: Any) -> dict[str, np.ndarray]:
    """SB3's arrays: of their shapes and dtypes."""
    n = venv.num_envs
    return {
        "model.last_obs": np.zeros((n, *venv.observation_space.shape), np.float32),
        "model.last_episode_starts": np.zeros(n, dtype=bool),
        "model.n_updates": np.zeros((), dtype=np.int64),
    }


def rollout_state(model: Any, venv: Any) -> dict[str, np.ndarray]:
    """Everything :func:`load_rollout_state` needs, as arrays (module docstring).

    Args:
        model: The SB3 on-policy algorithm, between two rollouts.
        venv: Its environment stack (:func:`venv_state`).
    """
    return venv_state(
        venv,
        {
            "model.last_obs": np.asarray(model._last_obs, dtype=np.float32),
            "model.last_episode_starts": np.asarray(model._last_episode_starts, bool),
            "model.n_updates": np.array(model._n_updates, dtype=np.int64),
        },
    )


def env_state_bytes(model: Any, venv: Any) -> bytes:
    """A checkpoint's ``env_state.npz``: :func:`rollout_state` as an uncompressed npz."""
    return npz_bytes(rollout_state(model, venv))


def npz_bytes(state: dict[str, np.ndarray]) -> bytes:
    """``state`` as an uncompressed npz (an ``env_state.npz``)."""
    buf = io.BytesIO()
    np.savez(buf, **state)
    return buf.getvalue()


def load_rollout_state(model: Any, venv: Any, state: dict[str, np.ndarray]) -> None:
    """Continue ``model`` and ``venv`` from a :func:`rollout_state` (read from a checkpoint).

    Everything is checked before anything is written (:func:`load_venv_state`). The next
    rollout then starts where the checkpoint's run was, without a reset.

    Raises:
        ValueError: One line naming the array.
    """
    own = load_venv_state(venv, state, _model_like(venv), counters=("model.n_updates",))
    model._last_obs = own["model.last_obs"]
    model._last_episode_starts = own["model.last_episode_starts"]
    model._n_updates = int(own["model.n_updates"])
