"""A native Gymnasium vector environment over the batched core.

``gymnasium.make_vec("uasep/Formation-v1", num_envs=4096)`` returns
:class:`FormationVectorEnv`: one :class:`~uasep_env.world.World` of ``num_envs``
environments stepped by array operations, with no Python loop over environments. Each
environment is the centralised view of :class:`~uasep_env.envs.gym_env.FormationEnv`
(joint observation and action of its UAVs).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from uasep_env.config import EnvConfig, make_config
from uasep_env.envs.core import EnvCore, check_options, clipped_counts, prepare_actions
from uasep_env.rewards import REWARD_TERMS, team_mean
from uasep_env.world import check_seed

__all__ = ["FormationVectorEnv"]


class FormationVectorEnv(VectorEnv):
    """``num_envs`` centralised formation environments in one batched world.

    Args:
        num_envs: Number of environments.
        config: Base config (or dict); keyword arguments override it, validated.
        autoreset_mode: ``"NextStep"`` (Gymnasium's default: an environment that ended is
            reset on the following ``step``, whose action for it is ignored),
            ``"SameStep"`` (reset in the same step; the final observation and info are in
            ``infos["final_obs"]`` / ``infos["final_info"]``) or ``"Disabled"`` (reset
            ended environments with ``reset(options={"reset_mask": mask})``).
        **kwargs: :class:`~uasep_env.config.EnvConfig` fields.

    Infos are dicts of arrays with Gymnasium's ``_key`` masks: ``rewards`` (per UAV),
    ``reward_terms`` (team mean of each term), the safety figures per UAV and
    ``clipped_actions`` (per UAV, the action components clipped to ``[-1, 1]``; with
    ``action={"strict": True}`` out-of-box actions raise ``ValueError`` instead).

    Stepping before the first :meth:`reset`, or (``"Disabled"`` mode) stepping an
    environment whose episode ended and was not reset, raises ``RuntimeError``.
    """

    def __init__(
        self,
        num_envs: int = 1,
        config: EnvConfig | dict | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ) -> None:
        if (
            not isinstance(num_envs, (int, np.integer))
            or isinstance(num_envs, bool)
            or num_envs < 1
        ):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.config = make_config(config, **kwargs)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as err:
            raise ValueError(
                f"autoreset_mode {autoreset_mode!r} must be one of "
                f"{[m.value for m in AutoresetMode]}"
            ) from err
        self.metadata = {
            "render_modes": ["rgb_array"],
            "render_fps": 10,
            "autoreset_mode": self.autoreset_mode,
        }
        self.render_mode = self.config.render_mode
        self.num_envs = int(num_envs)
        self.core = EnvCore(self.config, n_envs=self.num_envs)
        n, d = self.config.n_uavs, self.core.obs_dim
        clip = self.config.observation.clip
        self.single_observation_space = gymnasium.spaces.Box(-clip, clip, (n * d,), np.float32)
        self.single_action_space = gymnasium.spaces.Box(-1.0, 1.0, (n * 3,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._started = False
        self._renderer: Any = None

    @property
    def world(self) -> Any:
        """The underlying batched :class:`~uasep_env.world.World`."""
        return self.core.world

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Reset every environment (or those in ``options["reset_mask"]``).

        Args:
            seed: One int (environment ``i`` gets ``seed + i``) or one seed per environment.
            options: ``{"reset_mask": bool array}`` to reset only some environments.

        Raises:
            TypeError: A seed that is not None, an int or a list of them; ``options`` not
                a dict.
            ValueError: A negative seed, the wrong number of seeds, an unknown option or a
                bad mask.
        """
        check_seed(seed, self.num_envs)
        mask = None
        if check_options(options, ("reset_mask",)):
            mask = np.asarray(options["reset_mask"])  # type: ignore[index]
            if mask.shape != (self.num_envs,) or mask.dtype != bool:
                raise ValueError(
                    f"options['reset_mask'] must be a bool array of shape ({self.num_envs},), "
                    f"got {options['reset_mask']!r}"  # type: ignore[index]
                )
            if not self._started and not mask.all():
                raise RuntimeError("the first reset must reset every environment")
        if seed is not None:
            self._np_random_seed = seed if isinstance(seed, int) else -1
        obs = self.core.reset(seed=seed, mask=mask)
        self._started = True
        if mask is None:
            self._needs_reset[:] = False
        else:
            self._needs_reset[mask] = False
        return obs.reshape(self.num_envs, -1), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Step every environment with ``actions`` of shape ``(num_envs, 3 N)``.

        Raises:
            RuntimeError: Before the first reset, or (``"Disabled"`` mode) an environment
                whose episode ended has not been reset.
            ValueError: A bad action (named with its index in ``actions``).
        """
        if not self._started:
            raise RuntimeError("step() called before reset()")
        if self.autoreset_mode == AutoresetMode.DISABLED and self._needs_reset.any():
            raise RuntimeError(
                f"environments {np.flatnonzero(self._needs_reset).tolist()} have finished "
                "episodes (autoreset is disabled); reset them with "
                "reset(options={'reset_mask': mask}) before stepping"
            )
        n = self.config.n_uavs
        a, outside = prepare_actions(
            actions, (self.num_envs, n * 3), "actions", self.config.action.strict
        )
        a = a.reshape(self.num_envs, n, 3)
        pending = (
            self._needs_reset.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else None
        )
        some_pending = pending is not None and bool(pending.any())
        if some_pending:
            # Environments that ended last step: reset now and hold them still during the
            # step (their action is ignored), so one observation pass serves both.
            self.core.world.reset(mask=pending)
        res = self.core.step(a, validate=False, active=~pending if some_pending else None)
        obs = res.obs.reshape(self.num_envs, -1)
        rewards = team_mean(res.rewards)
        terminated = res.terminated.copy()
        truncated = res.truncated.copy()
        infos = self._infos(res)
        infos["clipped_actions"] = clipped_counts(outside, (self.num_envs, n))
        infos["_clipped_actions"] = infos["_rewards"]
        done = terminated | truncated
        if some_pending:
            rewards[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
            done = terminated | truncated
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._needs_reset = done
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            infos["final_obs"] = np.where(done[:, None], obs, 0.0).astype(np.float32)
            infos["_final_obs"] = done.copy()
            infos["final_info"] = {k: v for k, v in infos.items() if not k.startswith("final")}
            infos["_final_info"] = done.copy()
            obs[done] = self.core.reset_some(done).reshape(int(done.sum()), -1)
        elif self.autoreset_mode == AutoresetMode.DISABLED:
            self._needs_reset = self._needs_reset | done
        return obs, rewards, terminated, truncated, infos

    def _infos(self, res: Any) -> dict[str, Any]:
        ones = np.ones(self.num_envs, dtype=bool)
        # The step's arrays are its own (fresh each step): no copies needed.
        infos: dict[str, Any] = {"rewards": res.rewards, "_rewards": ones}
        means = team_mean(np.stack([res.terms[k] for k in REWARD_TERMS]))
        infos["reward_terms"] = dict(zip(REWARD_TERMS, means, strict=True))
        infos["_reward_terms"] = ones
        for k, v in res.safety.items():
            infos[k] = v
            infos["_" + k] = ones
        return infos

    def render(self) -> np.ndarray | None:
        """An RGB frame of environment 0 (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            from uasep_env.rendering import Renderer

            self._renderer = Renderer(self.config, mode="rgb_array")
        return self._renderer.render(self.core.world, env=0)

    def close_extras(self, **kwargs: Any) -> None:
        """Close the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
