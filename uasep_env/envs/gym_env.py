"""Gymnasium single-agent (centralised) view: joint observation and joint action."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from uasep_env.config import EnvConfig, make_config
from uasep_env.config.checks import check_seed
from uasep_env.envs._view import ViewMixin
from uasep_env.envs.core import EnvCore, check_options, clipped_counts, prepare_actions
from uasep_env.interface.costs import COST_TERMS
from uasep_env.interface.rewards import REWARD_TERMS
from uasep_env.viz.requirements import available_render_modes, checked_render_mode

__all__ = ["FormationEnv"]

#: The info keys of the agents' mean reward terms and cost terms, in table order.
_TERM_KEYS = tuple("reward_" + k for k in REWARD_TERMS)
_COST_KEYS = tuple("cost_" + k for k in COST_TERMS)


class FormationEnv(ViewMixin, gymnasium.Env):
    """All UAVs of the formation controlled by one (centralised) agent.

    The same world, observations and rewards as
    :class:`~uasep_env.envs.parallel.UAVSeparationParallelEnv`, seen jointly. Each
    registered id has a card in the documentation (``docs/envs/``).

    Action space:
        ``Box(-1, 1, (3 N,), float32)``: the UAVs' normalised accelerations, UAV-major.
        Only real numbers are actions (:class:`~uasep_env.envs.core.ActionTypeError`
        otherwise); finite values outside the box are clipped and counted per UAV in
        ``info["clipped_actions"]``, or raise ``ValueError`` with ``action={"strict": True}``.

    Observation space:
        ``Box(-clip, clip, (N D,), float32)``: the agents' observations concatenated.

    Rewards:
        The mean of the agents' rewards; ``info["rewards"]`` has each agent's reward and
        ``info["reward_<term>"]`` the mean of each named term (flat keys, so that vector
        wrappers and TorchRL batch them; the PettingZoo view nests them in
        ``reward_terms``).

    Cost:
        ``info["cost"]``: the mean of the agents' costs (:mod:`uasep_env.interface.costs`; > 0
        exactly when a UAV has lost separation, with the default ``cost`` weights),
        ``info["costs"]`` each agent's and ``info["cost_<term>"]`` the mean of each named
        term. In no reward.

    Episode end:
        Terminated on a collision (within ``uav.collision_distance``) or when a UAV is
        lost, farther than ``uav.lost_distance`` (300 m) from its planned position
        (``info["lost"]``; uniformly random actions end most episodes so). Truncated at the
        time limit ``episode_duration`` or the end of the plan. The registered ids declare it
        as ``spec.max_episode_steps`` (1000 steps at the default 200 s), so
        ``gymnasium.make`` adds a ``TimeLimit`` at the same step; for longer episodes pass
        ``max_episode_steps`` to ``gymnasium.make`` as well (the earlier limit wins).
        Stepping a finished episode raises ``RuntimeError`` until :meth:`reset`.

    Configuration:
        Any :class:`~uasep_env.config.EnvConfig` field as a keyword, validated.
    """

    # The render modes this installation can draw (none without matplotlib, the viz extra).
    metadata = {  # noqa: RUF012
        "render_modes": available_render_modes(("human", "rgb_array")),
        "render_fps": 10,
    }

    def __init__(self, config: EnvConfig | dict | None = None, **kwargs: Any) -> None:
        self.config = make_config(config, **kwargs)
        self.render_mode = checked_render_mode(self.config.render_mode)
        self.core = EnvCore(self.config, n_envs=1)
        n, d = self.config.n_uavs, self.core.obs_dim
        clip = self.config.observation.clip
        self.observation_space = gymnasium.spaces.Box(-clip, clip, (n * d,), np.float32)
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (n * 3,), np.float32)
        self._renderer: Any = None
        self._done = True  # no episode yet

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Start an episode; ``seed`` fixes it.

        Raises:
            TypeError: ``seed`` is not None or an int, or ``options`` is not a dict.
            ValueError: A negative seed, or any option (none is supported).
        """
        self.check_open("reset")
        check_seed(seed)
        check_options(options, ())
        super().reset(seed=None if seed is None else int(seed))
        obs = self.core.reset(seed=seed)
        self._done = False
        if self.render_mode == "human":
            self.render()
        return obs[0].reshape(-1), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Advance one step with the joint action.

        Raises:
            RuntimeError: The episode has ended (or none was started): call ``reset``.
            ValueError: A bad action (named); see the class docstring.
        """
        self.check_open("step")
        if self._done:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        n = self.config.n_uavs
        a, outside = prepare_actions(action, (n * 3,), "action", self.config.action.strict)
        res = self.core.step(a.reshape(1, n, 3), validate=False)
        # Every mean over the agents in one reduction (each row's numpy mean, the same bits):
        # thirteen numpy means on three values were a sixth of the step.
        rows = [
            res.rewards[0],
            res.cost[0],
            *(res.terms[k][0] for k in REWARD_TERMS),
            *(res.cost_terms[k][0] for k in COST_TERMS),
        ]
        reward, cost, *means = np.stack(rows).mean(axis=1).tolist()
        info: dict[str, Any] = {
            "rewards": res.rewards[0].copy(),
            **dict(zip(_TERM_KEYS, means[: len(REWARD_TERMS)], strict=True)),
            **{k: v[0].copy() for k, v in res.safety.items()},
            "cost": cost,
            "costs": res.cost[0].copy(),
            **dict(zip(_COST_KEYS, means[len(REWARD_TERMS) :], strict=True)),
            "clipped_actions": clipped_counts(outside, (n,)),
        }
        terminated, truncated = bool(res.terminated[0]), bool(res.truncated[0])
        self._done = terminated or truncated
        if self.render_mode == "human":
            self.render()
        return (
            res.obs[0].reshape(-1),
            reward,
            terminated,
            truncated,
            info,
        )
