"""A stable-baselines3 ``VecEnv`` for parameter sharing over the batched core.

Every UAV of every environment is one SB3 sub-environment (the observation and action of
one agent), so ``PPO("MlpPolicy", UAVSharedVecEnv(n_envs=...))`` trains one policy shared
by all UAVs. Sub-environment ``e * n_uavs + i`` is UAV ``i`` of environment ``e``. Episodes
end for all UAVs of an environment together; the environment is then reset in the same
step, and each of its agents' infos carries ``terminal_observation`` and
``TimeLimit.truncated`` as SB3 expects, and ``episode_safety``: the finished episode's
``collision`` and ``loss_of_separation`` (bools, any UAV) and ``max_deviation`` (m, the
largest true distance of a UAV from its planned position once the formation has formed
up, as in :mod:`uasep_env.metrics`), which training scripts report as they go. Every
agent's info has ``clipped_actions``: how many components of its action were clipped to
``[-1, 1]`` (with ``action={"strict": True}``, out-of-box actions raise ``ValueError``
instead), ``cost`` (float, the agent's cost of the step, :mod:`uasep_env.interface.costs`; in no
reward) and ``cost_terms`` (its named terms, floats).

This module imports stable-baselines3; the rest of the package does not.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from uasep_env.config import EnvConfig, make_config
from uasep_env.config.checks import check_seed
from uasep_env.envs._infos import row_dicts
from uasep_env.envs.core import EnvCore, prepare_actions
from uasep_env.envs.episode_safety import EpisodeSafety
from uasep_env.interface.costs import COST_TERMS

__all__ = ["UAVSharedVecEnv"]


#: An agent's info dict from its columns (clipped action components, cost, cost terms): the
#: keys written out once (:func:`uasep_env.envs._infos.row_dicts`).
_agent_infos = row_dicts(("clipped_actions", "cost", ("cost_terms", COST_TERMS)))


class UAVSharedVecEnv(VecEnv):
    """All agents of ``n_envs`` batched environments as one SB3 ``VecEnv``.

    Args:
        n_envs: Number of environments (``num_envs`` of the VecEnv is ``n_envs * n_uavs``).
        config: Base config (or dict); keyword arguments override it.
        seed: Seed of the first reset (environment ``e`` gets ``seed + e``).
        **kwargs: :class:`~uasep_env.config.EnvConfig` fields.
    """

    def __init__(
        self,
        n_envs: int = 1,
        config: EnvConfig | dict | None = None,
        seed: int | None = None,
        **kwargs: Any,
    ) -> None:
        self.config = make_config(config, **kwargs)
        check_seed(seed)
        self.core = EnvCore(self.config, n_envs=n_envs)
        self.n_envs = n_envs
        self.n_uavs = self.config.n_uavs
        clip = self.config.observation.clip
        obs_space = gymnasium.spaces.Box(-clip, clip, (self.core.obs_dim,), np.float32)
        act_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.render_mode = None
        super().__init__(n_envs * self.n_uavs, obs_space, act_space)
        self._seed = seed
        self._actions: np.ndarray | None = None
        self._episodes = EpisodeSafety(n_envs)  # the running episodes (``episode_safety``)
        self._clipped = np.zeros(self.num_envs, dtype=np.int64)
        self._started = False
        self._closed = False

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next reset (environment ``e`` gets ``seed + e``).

        Raises:
            TypeError: ``seed`` is not None or an int.
            ValueError: A negative seed.
        """
        check_seed(seed)
        self._seed = seed
        return [seed] * self.num_envs

    def reset(self) -> np.ndarray:
        """Reset every environment; observations ``(n_envs * n_uavs, obs_dim)``."""
        self._check_open("reset")
        obs = self.core.reset(seed=self._seed)
        self._seed = None
        self._episodes.clear()
        self._started = True
        return obs.reshape(self.num_envs, -1)

    def step_async(self, actions: np.ndarray) -> None:
        """Check and store the actions ``(n_envs * n_uavs, 3)``.

        Raises:
            ValueError: A bad action, named by its index in ``actions``
                (:class:`~uasep_env.envs.core.ActionTypeError` for values that are not
                real numbers).
        """
        self._check_open("step_async")
        acts, outside = prepare_actions(
            actions, (self.num_envs, 3), "actions", self.config.action.strict
        )
        self._actions = acts
        self._clipped = (
            np.zeros(self.num_envs, np.int64) if outside is None else outside.sum(axis=-1)
        )

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step all environments; reset those that ended (same step).

        Raises:
            RuntimeError: Before the first reset, or without ``step_async``.
        """
        self._check_open("step_wait")
        if not self._started:
            raise RuntimeError("step_wait() called before reset()")
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        acts = self._actions
        self._actions = None
        res = self.core.step(acts.reshape(self.n_envs, self.n_uavs, 3), validate=False)
        obs = res.obs.reshape(self.num_envs, -1)
        rewards = res.rewards.reshape(-1).astype(np.float32)
        done_env = res.terminated | res.truncated
        dones = np.repeat(done_env, self.n_uavs)
        self._episodes.track(self.core.world, res.safety)
        infos = _agent_infos(
            self._clipped.tolist(),
            res.cost.reshape(-1).tolist(),
            *(res.cost_terms[k].reshape(-1).tolist() for k in COST_TERMS),
        )
        if done_env.any():
            for e in np.flatnonzero(done_env):
                trunc = bool(res.truncated[e] and not res.terminated[e])
                safety = self._episodes.summary(e)
                for i in range(self.n_uavs):
                    k = e * self.n_uavs + i
                    infos[k]["terminal_observation"] = obs[k].copy()
                    infos[k]["TimeLimit.truncated"] = trunc
                    infos[k]["episode_safety"] = safety
            obs[dones] = self.core.reset_some(done_env).reshape(-1, obs.shape[1])
            self._episodes.clear(done_env)
        return obs, rewards, dones, infos

    def state_dict(self) -> dict[str, np.ndarray]:
        """Where every environment's episode stands, as arrays (copies).

        The core's state (``world.*``, ``core.*``: :meth:`EnvCore.state_dict
        <uasep_env.envs.core.EnvCore.state_dict>`), the running episodes' safety
        (``episodes.*``) and whether the first reset was done (``started``). A view that
        loads it (:meth:`load_state_dict`) steps on exactly as this one would: what an SB3
        run's checkpoint keeps so that a resumed run is the uninterrupted one, bit for bit.
        """
        state = self.core.state_dict()
        state |= {f"episodes.{k}": v.copy() for k, v in vars(self._episodes).items()}
        state["started"] = np.array(self._started)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a :meth:`state_dict` of a view of the same config and size.

        Everything is checked before anything is written; the seed given to the constructor
        is then spent (the restored episodes continue their generators).

        Raises:
            ValueError: One line naming the array (wrong shape or dtype, NaN, out of range).
        """
        from uasep_env.sim.snapshot import check_arrays, copy_arrays

        live = {f"episodes.{k}": v for k, v in vars(self._episodes).items()}
        ours = {k: v for k, v in state.items() if k.startswith("episodes.")}
        check_arrays(ours, live)
        started = state.get("started")
        if not isinstance(started, np.ndarray) or started.shape != () or started.dtype != bool:
            raise ValueError(f"started: {started!r:.40}, not a bool")
        self.core.load_state_dict(
            {k: v for k, v in state.items() if not k.startswith("episodes.") and k != "started"}
        )
        copy_arrays(ours, live)
        self._started = bool(started)
        self._seed = None
        self._actions = None

    def close(self) -> None:
        """Mark the env closed: later ``reset``/``step`` calls raise (Gymnasium's rule)."""
        self._closed = True

    def _check_open(self, method: str) -> None:
        if self._closed:
            from gymnasium.error import ClosedEnvironmentError

            raise ClosedEnvironmentError(
                f"UAVSharedVecEnv.{method}() called after close(); create a new environment"
            )

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Rendering is done by the Gymnasium/PettingZoo views."""
        return [None] * self.num_envs

    def _indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Attributes are the same for every sub-environment (``render_mode``, ``config``...)."""
        value = getattr(self, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute on the adapter."""
        setattr(self, attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Call a method of the adapter once per requested index."""
        method = getattr(self, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        """No sub-environment is wrapped."""
        return [False for _ in self._indices(indices)]
