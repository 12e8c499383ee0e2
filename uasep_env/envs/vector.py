"""A native Gymnasium vector environment over the batched core.

``gymnasium.make_vec("uasep/Formation-v3", num_envs=4096)`` returns
:class:`FormationVectorEnv`: one :class:`~uasep_env.sim.world.World` of ``num_envs``
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
from uasep_env.config.checks import check_positive_int, check_seed
from uasep_env.envs._view import ViewMixin
from uasep_env.envs.core import EnvCore, check_options, clipped_counts, prepare_actions
from uasep_env.interface.costs import COST_TERMS
from uasep_env.interface.rewards import REWARD_TERMS, team_mean
from uasep_env.viz.requirements import (
    available_render_modes,
    checked_render_mode,
    require_matplotlib,
)

__all__ = ["FormationVectorEnv"]


def _limit_steps(config: EnvConfig, max_episode_steps: Any) -> EnvConfig:
    """``config`` truncated after at most ``max_episode_steps`` steps (``None``: as is)."""
    if max_episode_steps is None:
        return config
    steps = check_positive_int("max_episode_steps", max_episode_steps)
    if steps >= config.max_steps:
        return config
    return make_config(config, episode_duration=steps * config.step_duration)


def _with_masks(values: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, Any]:
    """``values`` with each key's mask ``"_" + key``, a copy of ``rows``.

    Each key has its own mask (as ``SyncVectorEnv``'s): the rows of one block, one
    allocation for all of them instead of one each (about 20 keys a step).
    """
    block = np.empty((len(values), len(rows)), dtype=bool)
    block[...] = rows
    out: dict[str, Any] = {}
    for (k, v), mask in zip(values.items(), block, strict=True):
        out[k], out["_" + k] = v, mask
    return out


def _masked(values: dict[str, np.ndarray], rows: np.ndarray | None) -> dict[str, Any]:
    """Gymnasium's vector infos of ``values`` for the environments in ``rows`` (all: None).

    The other rows are zero and masked out; no row: no keys (as ``SyncVectorEnv``).
    """
    if rows is None:
        return _with_masks(values, np.ones(len(next(iter(values.values()))), dtype=bool))
    if not rows.any():
        return {}
    kept = {}
    for k, v in values.items():
        keep = rows.reshape(-1, *([1] * (v.ndim - 1)))
        kept[k] = np.where(keep, v, np.zeros((), v.dtype))
    return _with_masks(kept, rows)


def _zero_rows(values: dict[str, np.ndarray], rows: np.ndarray, idx: np.ndarray) -> dict[str, Any]:
    """``_masked(values, ~rows)``, zeroing ``rows`` in place (the step's own, fresh arrays).

    A few rows reset in a step of a large batch: writing them costs a few rows, where
    ``np.where`` would copy every array. ``idx``: the indices of ``rows`` (a few indices:
    cheaper to write through than a mask). The terms' means (:data:`_TERM_KEYS`) were
    zeroed where they were made.
    """
    keep = ~rows
    if not keep.any():
        return {}
    for k, v in values.items():
        if k not in _TERM_KEYS:
            v[idx] = 0
    return _with_masks(values, keep)


def _add_term_means(
    values: dict[str, np.ndarray],
    prefix: str,
    names: tuple[str, ...],
    array: np.ndarray | None,
    rows: dict[str, np.ndarray],
    zeroed: np.ndarray | None,
) -> None:
    """Put each term's team mean in ``values`` as ``prefix + name``, zero in ``zeroed``.

    From the terms' own ``(K, E, N)`` array where the step gave it (a stack of its rows
    was a copy of a megabyte a step at 4096 environments), else from ``rows``.
    """
    if array is None:
        array = np.stack([rows[k] for k in names])
    means = team_mean(array)
    if zeroed is not None:
        means[:, zeroed] = 0
    for k, mean in zip(names, means, strict=True):
        values[prefix + k] = mean


#: The infos' keys of the reward and cost terms' team means (rows of one array each).
_TERM_KEYS = frozenset(["reward_" + k for k in REWARD_TERMS] + ["cost_" + k for k in COST_TERMS])


class FormationVectorEnv(ViewMixin, VectorEnv):
    """``num_envs`` centralised formation environments in one batched world.

    Args:
        num_envs: Number of environments.
        config: Base config (or dict); keyword arguments override it, validated.
        autoreset_mode: ``"NextStep"`` (Gymnasium's default: an environment that ended is
            reset on the following ``step``, whose action for it is ignored),
            ``"SameStep"`` (reset in the same step; the final observation and info are in
            ``infos["final_obs"]`` / ``infos["final_info"]``) or ``"Disabled"`` (reset
            ended environments with ``reset(options={"reset_mask": mask})``).
        max_episode_steps: Gymnasium's time limit (``gymnasium.make_vec`` passes the id's
            ``spec.max_episode_steps``): episodes are truncated after ``min(max_episode_steps,
            config.max_steps)`` steps, as ``gymnasium.make``'s ``TimeLimit`` does.
        **kwargs: :class:`~uasep_env.config.EnvConfig` fields.

    Infos are dicts of arrays with Gymnasium's ``_key`` masks: ``rewards`` (per UAV),
    ``reward_<term>`` (team mean of each term of :data:`~uasep_env.interface.rewards.REWARD_TERMS`),
    the safety figures per UAV, ``cost`` (the team mean of the agents' costs,
    :mod:`uasep_env.interface.costs`), ``costs`` (per UAV) and ``cost_<term>`` (team mean of each
    cost term), and ``clipped_actions`` (per UAV, the action components
    clipped to ``[-1, 1]``; with ``action={"strict": True}`` out-of-box actions raise
    ``ValueError`` instead). In every autoreset mode they are exactly what
    ``gymnasium.vector.SyncVectorEnv`` over :class:`~uasep_env.envs.gym_env.FormationEnv`
    gives (keys, masks, dtypes): an environment reset during the step has the reset's
    (empty) info, i.e. its entries are masked out and zero; in ``"SameStep"`` mode
    ``final_obs`` is an object array (``None`` where no episode ended) and ``final_info``
    holds the finished episodes' infos, masked to them.

    Stepping before the first :meth:`reset`, or (``"Disabled"`` mode) stepping an
    environment whose episode ended and was not reset, raises ``RuntimeError``.
    """

    def __init__(
        self,
        num_envs: int = 1,
        config: EnvConfig | dict | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        **kwargs: Any,
    ) -> None:
        self._renderers: list[Any] | None = None  # first: close() runs if __init__ raises
        check_positive_int("num_envs", num_envs)
        self.config = _limit_steps(make_config(config, **kwargs), max_episode_steps)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as err:
            raise ValueError(
                f"autoreset_mode {autoreset_mode!r} must be one of "
                f"{[m.value for m in AutoresetMode]}"
            ) from err
        self.metadata = {
            "render_modes": available_render_modes(("rgb_array",)),  # none without viz
            "render_fps": 10,
            "autoreset_mode": self.autoreset_mode,
        }
        self.render_mode = checked_render_mode(self.config.render_mode)
        self.num_envs = int(num_envs)
        self.core = EnvCore(self.config, n_envs=self.num_envs, count_name="num_envs")
        n, d = self.config.n_uavs, self.core.obs_dim
        clip = self.config.observation.clip
        self.single_observation_space = gymnasium.spaces.Box(-clip, clip, (n * d,), np.float32)
        self.single_action_space = gymnasium.spaces.Box(-1.0, 1.0, (n * 3,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._needs_reset = np.zeros(self.num_envs, dtype=bool)
        self._started = False

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
        self.check_open("reset")
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
        self.check_open("step")
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
        # Environments that ended last step start new episodes in this one (their action is
        # ignored), so one observation pass serves both.
        res = self.core.step(a, validate=False, reset=pending if some_pending else None)
        obs = res.obs.reshape(self.num_envs, -1)
        rewards = team_mean(res.rewards)
        terminated = res.terminated.copy()
        truncated = res.truncated.copy()
        held = np.flatnonzero(pending) if some_pending else None
        values = self._info_values(res, held)
        values["clipped_actions"] = clipped_counts(outside, (self.num_envs, n))
        done = terminated | truncated
        if some_pending:
            rewards[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
            done = terminated | truncated
            # Reset this step: the reset's (empty) info, as SyncVectorEnv gives.
            infos = _zero_rows(values, pending, held)
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = obs[i].copy()
            infos = {
                "final_obs": final_obs,
                "_final_obs": done.copy(),
                "final_info": _masked(values, done),
                "_final_info": done.copy(),
                **_masked(values, ~done),  # the ended ones have the reset's (empty) info
            }
            obs[done] = self.core.reset_some(done).reshape(int(done.sum()), -1)
        else:
            infos = _masked(values, None)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._needs_reset = done
        elif self.autoreset_mode == AutoresetMode.DISABLED:
            self._needs_reset = self._needs_reset | done
        return obs, rewards, terminated, truncated, infos

    @staticmethod
    def _info_values(res: Any, zeroed: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The infos' arrays; the terms' means already zero in the rows ``zeroed`` (indices).

        The terms' means are rows of one array each: zeroed there in one write, not one
        per key (:func:`_zero_rows` does the others).
        """
        # The step's arrays are its own (fresh each step): no copies needed.
        values: dict[str, np.ndarray] = {"rewards": res.rewards}
        _add_term_means(values, "reward_", REWARD_TERMS, res.terms_array, res.terms, zeroed)
        values.update(res.safety)
        values["cost"] = team_mean(res.cost)
        values["costs"] = res.cost
        _add_term_means(values, "cost_", COST_TERMS, res.cost_terms_array, res.cost_terms, zeroed)
        return values

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One RGB frame per environment (``render_mode="rgb_array"``; else ``None``).

        Gymnasium's vector convention (``SyncVectorEnv.render``), which its vector wrappers
        (``HumanRendering``, ``RecordVideo``) read. Each environment has its own renderer,
        so each keeps its own trails.

        Raises:
            ModuleNotFoundError: Without matplotlib, naming the ``viz`` extra.
        """
        if self.render_mode != "rgb_array":
            return None
        if self._renderers is None:
            require_matplotlib("render() (render_mode='rgb_array')")
            from uasep_env.viz.frames import Renderer

            self._renderers = [Renderer(mode="rgb_array") for _ in range(self.num_envs)]
        world = self.core.world
        return tuple(r.render(world, env=i) for i, r in enumerate(self._renderers))

    # The vector API's close (it calls close_extras and marks the env closed), not the view's.
    close = VectorEnv.close

    def close_extras(self, **kwargs: Any) -> None:
        """Close the renderers."""
        for renderer in self._renderers or ():
            renderer.close()
        self._renderers = None
