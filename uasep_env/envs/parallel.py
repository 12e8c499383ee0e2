"""The PettingZoo parallel environment (the primary API)."""

from __future__ import annotations

import math
import warnings
from typing import Any

import gymnasium
import numpy as np
from pettingzoo import ParallelEnv

from uasep_env.config import EnvConfig, make_config
from uasep_env.config.checks import check_positive_int, check_seed
from uasep_env.envs._view import ViewMixin
from uasep_env.envs.core import (
    EnvCore,
    StepResult,
    _short,
    action_array,
    check_options,
    prepare_actions,
)
from uasep_env.interface.observation import ObservationLayout, state_dim
from uasep_env.registration import ENV_VERSION
from uasep_env.viz.requirements import available_render_modes, checked_render_mode

__all__ = ["UAVSeparationParallelEnv", "env", "parallel_env"]

# Config keys that change the spaces: they cannot be changed at reset.
_SPACE_KEYS = ("n_uavs", "n_obstacles", "observation")


class UAVSeparationParallelEnv(ViewMixin, ParallelEnv):
    """A formation of UAVs keeping separation from each other and non-cooperative obstacles.

    ``N`` cooperative UAVs (agents ``uav_0 ... uav_{N-1}``) fly a planned trajectory in a
    formation (the behaviour method, paper eqs. 5-7) through airspace with ``M``
    non-cooperative obstacles that fly a 3D Dubins model and change course at random.
    Each UAV only knows Kalman-filtered estimates of the states and, for each obstacle, the
    predicted reachable ellipsoid over the horizon (eqs. 8-18). The agents must keep
    separation from each other and from the obstacles while deviating as little as possible
    from their planned trajectories. The reference policy is the paper's APF
    (:class:`uasep_env.policies.APF`). Each registered id has a card in the documentation
    (``docs/envs/``) with its spaces, shapes and an episode.

    Action space:
        ``Box(-1, 1, (3,), float32)`` per agent: the commanded acceleration along north,
        east and down as a fraction of ``uav.max_accel`` (m/s^2). Only real numbers are
        actions (integer or floating arrays, Python numbers): other types raise
        :class:`~uasep_env.envs.core.ActionTypeError` (a ``TypeError`` and a
        ``ValueError``); the wrong shape, non-finite values, missing agents or unknown
        agents raise ``ValueError``. Finite values outside ``[-1, 1]`` are clipped to it and
        counted in ``infos[agent]["clipped_actions"]``; with ``action={"strict": True}`` they
        raise ``ValueError`` instead.

    Observation space:
        ``Box(-clip, clip, (D,), float32)`` per agent, normalised; the features are listed
        in :mod:`uasep_env.interface.observation_layout` (own slot/plan offsets and velocities,
        formation goal, the nearest UAVs, and the nearest obstacles' reachable ellipsoids
        with presence masks). :meth:`state` returns the global true state.

    Rewards:
        Named terms per agent (:mod:`uasep_env.interface.rewards`): separation between UAVs, from
        the obstacles and from their reachable regions, deviation from the plan, control effort,
        smoothness, collision and an alive bonus, combined by ``reward`` weights. Each
        agent's unweighted terms are in ``infos[agent]["reward_terms"]``.

    Episode end:
        Termination, for every agent at once (the formation's mission fails): any UAV comes
        within ``uav.collision_distance`` of another UAV or an obstacle, or a UAV is lost,
        farther than ``uav.lost_distance`` (300 m) from its planned position
        (``infos[agent]["lost"]``; uniformly random actions end most episodes so). Truncation: the
        time limit ``episode_duration``, or the end of the planned trajectory.

    Info:
        ``reward_terms``, ``min_uav_distance``, ``min_obstacle_distance``,
        ``min_region_distance`` (m), the flags ``loss_of_separation_uav``,
        ``loss_of_separation_obstacle``, ``in_reachable_region``, ``collision``, ``lost``,
        ``clipped_actions``: how many components of the agent's action were clipped to the
        box, and the cost channel: ``cost`` and its unweighted ``cost_terms``
        (:mod:`uasep_env.interface.costs`; > 0 exactly when the UAV has lost separation, with the
        default ``cost`` weights; in no reward).

    Configuration:
        Any :class:`~uasep_env.config.EnvConfig` field as a keyword (nested dicts for the
        sub-configs), e.g. ``parallel_env(n_uavs=5, scenario="crossing", noise=False)``.
        Unknown keys raise ``TypeError``. ``max_cycles`` (PettingZoo's convention) sets the
        episode length in steps (``episode_duration = max_cycles * step_duration``).
        ``reset(options={"config": {...}})`` changes the config for the next episodes,
        except what would change the spaces (``n_uavs``, ``n_obstacles``, ``observation``,
        or an ``action.mode`` that changes the observation width): spaces are fixed for an
        environment's life, as Gymnasium and PettingZoo code assumes, so such a change is a
        ``ValueError`` naming the widths (create a new environment instead). After
        :meth:`close`, ``reset`` and ``step`` raise
        ``gymnasium.error.ClosedEnvironmentError``.

    Reset options:
        ``"config"`` is the one documented option. Other keys are ignored with a
        ``UserWarning`` naming them, not an error as in the Gymnasium views: PettingZoo's
        own ``parallel_api_test`` / ``api_test`` call ``reset(options={"options": 1})`` and
        expect it to work.
    """

    metadata = {  # noqa: RUF012 - PettingZoo reads it as a class attribute
        "name": f"uasep_formation_v{ENV_VERSION}",
        "render_modes": available_render_modes(("human", "rgb_array")),  # none without viz
        "is_parallelizable": True,
        "render_fps": 10,
    }

    def __init__(
        self,
        config: EnvConfig | dict | None = None,
        *,
        max_cycles: int | None = None,
        **kwargs: Any,
    ) -> None:
        self.config = _with_max_cycles(make_config(config, **kwargs), max_cycles, kwargs)
        self.render_mode = checked_render_mode(self.config.render_mode)
        self.core = EnvCore(self.config, n_envs=1)
        self.possible_agents = [f"uav_{i}" for i in range(self.config.n_uavs)]
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        self._no_clips = np.zeros(len(self.possible_agents), dtype=np.int64)
        self._no_clips.flags.writeable = False
        self._obs_space = gymnasium.spaces.Box(
            -self.config.observation.clip,
            self.config.observation.clip,
            (self.core.obs_dim,),
            np.float32,
        )
        self._act_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)
        # One space object shared by every agent (PettingZoo's ParallelEnv declares these).
        self.observation_spaces = dict.fromkeys(self.possible_agents, self._obs_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, self._act_space)
        self.state_space = gymnasium.spaces.Box(
            -self.config.observation.clip,
            self.config.observation.clip,
            (state_dim(self.config),),
            np.float32,
        )
        self._renderer: Any = None
        self._last: StepResult | None = None

    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        """The observation space of ``agent`` (the same object on every call)."""
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str) -> gymnasium.spaces.Box:
        """The action space of ``agent`` (the same object on every call)."""
        self._check_agent(agent)
        return self._act_space

    def _check_agent(self, agent: str) -> None:
        if agent not in self._index:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")

    @property
    def layout(self) -> Any:
        """The :class:`~uasep_env.interface.observation.ObservationLayout` of the observations."""
        return self.core.layout

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """Start an episode.

        Args:
            seed: Seeds the episode's generator (all randomness flows from it).
            options: ``None`` or a dict; ``{"config": {...}}`` changes config fields for this
                and later episodes (not those that change the spaces). Other keys are
                ignored with a ``UserWarning`` (PettingZoo's API test passes one).

        Returns:
            ``(observations, infos)`` keyed by agent.

        Raises:
            TypeError: ``seed`` is not None or an int, ``options`` is not a dict, or an
                unknown config key.
            ValueError: A negative seed or an invalid config value.
        """
        self.check_open("reset")
        check_seed(seed)
        if options is not None:
            check_options(options, None)  # a dict; keys other than "config" are ignored
            unknown = [k for k in options if k != "config"]
            if unknown:
                warnings.warn(
                    f"reset option(s) {unknown} ignored; the only option is 'config'",
                    UserWarning,
                    stacklevel=2,
                )
        changes = options.get("config") if options else None
        if changes is not None and not (isinstance(changes, dict) and not changes):
            self._reconfigure(changes)
        obs = self.core.reset(seed=seed)
        self.agents = list(self.possible_agents)
        self._last = None
        observations = {a: obs[0, i] for a, i in self._index.items()}
        infos: dict[str, dict] = {a: {} for a in self.agents}
        if self.render_mode == "human":
            self.render()
        return observations, infos

    def _reconfigure(self, changes: dict) -> None:
        if not isinstance(changes, dict):
            raise TypeError(f"options['config'] must be a dict, got {changes!r}")
        fixed = [k for k in changes if k in _SPACE_KEYS]
        if fixed:
            raise ValueError(
                f"config key(s) {fixed} change the spaces and cannot be set at reset; "
                "create a new environment instead"
            )
        config = make_config(self.config, **changes)
        # Spaces are fixed for an environment's life (what Gymnasium/PettingZoo code, wrappers
        # and vectorisers assume): a change that would alter them is refused.
        new_dim, new_state = ObservationLayout.from_config(config).dim, state_dim(config)
        if new_dim != self._obs_space.shape[0] or new_state != self.state_space.shape[0]:
            raise ValueError(
                f"options['config'] {_short(changes)} changes the observation width from "
                f"{self._obs_space.shape[0]} to {new_dim} (state {self.state_space.shape[0]} "
                f"to {new_state}); spaces are fixed for an environment's life: create a new "
                "environment instead"
            )
        seed_state = self.core.world._noise.rngs  # keep each environment's random stream going
        self.config = config
        self.render_mode = checked_render_mode(config.render_mode)
        self.core = EnvCore(config, n_envs=1)
        self.core.world._noise.rngs = seed_state

    def step(
        self, actions: dict[str, np.ndarray]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict],
    ]:
        """Advance one step with every live agent's action.

        Raises:
            ValueError: Missing or unknown agents, or a bad action (named).
            RuntimeError: Stepping a finished episode without reset.
        """
        self.check_open("step")
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict keyed by agent, got {type(actions).__name__}")
        if actions.keys() != self._index.keys():  # every agent lives until the episode ends
            unknown = sorted(set(actions) - set(self.agents))
            missing = sorted(set(self.agents) - set(actions))
            raise ValueError(f"bad action keys: missing {missing}, unknown {unknown}")
        joint, clipped = self._joint_action(actions)
        res = self.core.step(joint, validate=False)
        self._last = res
        done_term = bool(res.terminated[0])
        done_trunc = bool(res.truncated[0])
        # Agent order is row order (_index); rows of res.obs[0] are views, as before.
        observations = dict(zip(self._index, res.obs[0], strict=True))
        rewards = dict(zip(self._index, res.rewards[0].tolist(), strict=True))
        terminations = dict.fromkeys(self.agents, done_term)
        truncations = dict.fromkeys(self.agents, done_trunc)
        infos = dict(zip(self._index, self.core.env_infos(res, 0), strict=True))
        for info, count in zip(infos.values(), clipped.tolist(), strict=True):
            info["clipped_actions"] = count
        if done_term or done_trunc:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _joint_action(self, actions: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The agents' actions as one checked ``(1, N, 3)`` array, clipped to the box.

        Returns the array and each agent's number of clipped components. Checked as a whole
        (one pass); only a bad joint action is checked agent by agent, so that the error
        names the agent.
        """
        strict = self.config.action.strict
        joint = np.empty((1, len(self.possible_agents), 3))
        for i, agent in enumerate(self._index):
            a = actions[agent]
            if not (isinstance(a, np.ndarray) and a.shape == (3,) and a.dtype.kind in "fiu"):
                # lists, wrong shapes, wrong types: named by agent
                a = action_array(a, (3,), f"action of {agent}")
            joint[0, i] = a
        # The usual case (NaN compares false): nothing to clip or name. A few values: Python
        # compares them sooner than numpy's reductions start.
        if all(-1.0 <= x <= 1.0 for x in joint.ravel().tolist()):
            return joint, self._no_clips
        try:
            out, outside = prepare_actions(joint, joint.shape, "actions", strict)
        except ValueError:
            for agent in self._index:  # the same check per agent, to name the agent
                prepare_actions(actions[agent], (3,), f"action of {agent}", strict)
            raise
        counts = np.zeros(len(self.possible_agents), dtype=np.int64)
        if outside is not None:
            counts = outside[0].sum(axis=-1)
        return out, counts

    def state(self) -> np.ndarray:
        """The global true state (normalised), shape ``state_space.shape``."""
        return self.core.state()[0]


def _with_max_cycles(config: EnvConfig, max_cycles: Any, kwargs: dict) -> EnvConfig:
    """``config`` with ``episode_duration = max_cycles * step_duration`` when given."""
    if max_cycles is None:
        return config
    duration = check_positive_int("max_cycles", max_cycles) * config.step_duration
    given = kwargs.get("episode_duration")
    if given is not None and not math.isclose(float(given), duration, rel_tol=1e-9):
        raise ValueError(
            f"max_cycles={max_cycles!r} and episode_duration={kwargs['episode_duration']!r} "
            f"disagree (max_cycles means episode_duration={duration!r}); give one of them"
        )
    return make_config(config, episode_duration=duration)


def parallel_env(
    config: EnvConfig | dict | None = None, *, max_cycles: int | None = None, **kwargs: Any
) -> UAVSeparationParallelEnv:
    """Create the PettingZoo parallel environment (see :class:`UAVSeparationParallelEnv`).

    Args:
        config: A config or a (nested) dict of overrides (:func:`~uasep_env.config.make_config`).
        max_cycles: Episode length in steps (PettingZoo's convention); None: the config's.
        **kwargs: Config overrides, each a validated field of
            :class:`~uasep_env.config.EnvConfig`.

    Returns:
        The environment (reset it with a seed before stepping).

    Examples:
        >>> import uasep_env
        >>> env = uasep_env.parallel_env(scenario="paper", n_uavs=3, n_obstacles=1)
        >>> observations, infos = env.reset(seed=0)
        >>> env.agents
        ['uav_0', 'uav_1', 'uav_2']
        >>> observations["uav_0"].shape, observations["uav_0"].dtype
        ((58,), dtype('float32'))
        >>> env.action_space("uav_0")
        Box(-1.0, 1.0, (3,), float32)
    """
    return UAVSeparationParallelEnv(config, max_cycles=max_cycles, **kwargs)


def env(
    config: EnvConfig | dict | None = None, *, max_cycles: int | None = None, **kwargs: Any
) -> Any:
    """The AEC (turn-based) view of :func:`parallel_env` (PettingZoo's ``parallel_to_aec``).

    Agents act in turn; the joint action is stepped once every agent has acted. After
    ``close()`` every ``reset``/``step`` raises ``gymnasium.error.ClosedEnvironmentError``
    (not only the step that completes a joint action).
    """
    from pettingzoo.utils.conversions import parallel_to_aec
    from pettingzoo.utils.wrappers import BaseWrapper

    class ClosedCheck(BaseWrapper):
        """Refuses every call after close (the AEC view buffers actions between steps)."""

        def reset(self, seed: int | None = None, options: dict | None = None) -> None:
            par.check_open("reset")
            super().reset(seed=seed, options=options)

        def step(self, action: Any) -> None:
            par.check_open("step")
            super().step(action)

    par = parallel_env(config, max_cycles=max_cycles, **kwargs)
    return ClosedCheck(parallel_to_aec(par))
