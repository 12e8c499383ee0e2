"""The batched environment core shared by every environment view.

:class:`EnvCore` wraps a :class:`~uasep_env.world.World` and adds what an RL environment
needs on top of the physics: action validation and scaling, observations, named rewards,
termination (a collision), truncation (time limit / end of the plan) and the per-step
safety figures. The PettingZoo env, the Gymnasium env, the vector env and the SB3 adapter
are thin views of it; none of them steps the world another way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uasep_env.actions import ResidualAPF
from uasep_env.config import EnvConfig, make_config
from uasep_env.observation import ObservationLayout, build_observations, global_state
from uasep_env.rewards import REWARD_TERMS, collisions, compute_rewards
from uasep_env.world import World

__all__ = ["ACTION_TOLERANCE", "EnvCore", "StepResult", "validate_actions"]

#: Actions may exceed ``[-1, 1]`` by this much (rounding) before they are rejected.
ACTION_TOLERANCE = 1e-6


def validate_actions(
    actions: np.ndarray, shape: tuple[int, ...], where: str = "action"
) -> np.ndarray:
    """Check normalised actions: shape, finiteness and the ``[-1, 1]`` box.

    Args:
        actions: The actions.
        shape: Their expected shape.
        where: Name used in error messages.

    Returns:
        The actions as float64, clipped only by the rounding tolerance.

    Raises:
        ValueError: Naming a value that is not a number, the wrong shape, or the first
            non-finite or out-of-range value.
    """
    try:
        a = np.asarray(actions).astype(float, copy=False)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{where} must be numbers, got {actions!r}") from err
    if a.shape != shape:
        raise ValueError(f"{where} must have shape {shape}, got {a.shape}")
    # One pass in the usual case: NaN compares false, so it fails this test too.
    if not (np.abs(a) <= 1.0 + ACTION_TOLERANCE).all():
        finite = np.isfinite(a)
        if not finite.all():
            idx = tuple(int(i) for i in np.argwhere(~finite)[0])
            raise ValueError(f"{where} contains a non-finite value {float(a[idx])} at index {idx}")
        idx = tuple(int(i) for i in np.argwhere(np.abs(a) > 1.0 + ACTION_TOLERANCE)[0])
        raise ValueError(
            f"{where} value {float(a[idx])} at index {idx} is outside the action space [-1, 1]"
        )
    return np.minimum(np.maximum(a, -1.0), 1.0)  # np.clip, with less overhead


@dataclass
class StepResult:
    """What one batched step produced (arrays over ``(n_envs, n_uavs)``).

    Attributes:
        obs: ``(E, N, D)`` observations after the step.
        rewards: ``(E, N)`` rewards.
        terms: Unweighted reward terms, name -> ``(E, N)``.
        terminated: ``(E,)`` an episode ended by a collision.
        truncated: ``(E,)`` an episode ended by the time limit or the end of the plan.
        safety: Per-step safety figures, name -> ``(E, N)``.
    """

    obs: np.ndarray
    rewards: np.ndarray
    terms: dict[str, np.ndarray]
    terminated: np.ndarray
    truncated: np.ndarray
    safety: dict[str, np.ndarray]


class EnvCore:
    """Observations, rewards and episode ends over a batched :class:`World`.

    Args:
        config: The validated config (or a dict).
        n_envs: Number of environments in the batch.
    """

    def __init__(self, config: EnvConfig | dict | None = None, n_envs: int = 1) -> None:
        self.config = config if isinstance(config, EnvConfig) else make_config(config)
        self.world = World(self.config, n_envs)
        self.layout = ObservationLayout.from_config(self.config)
        self.n_envs = n_envs
        self.n_uavs = self.config.n_uavs
        self._obs = np.zeros((n_envs, self.n_uavs, self.layout.world_dim), dtype=np.float32)
        # residual_apf mode: the APF's command for the current observations (what the next
        # action corrects); None in direct mode.
        self.residual = ResidualAPF(self.config) if self.layout.base_action else None
        self._base = np.zeros((n_envs, self.n_uavs, 3), dtype=np.float32)

    @property
    def obs_dim(self) -> int:
        """Width of one agent's observation."""
        return self.layout.dim

    def _observe(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Rebuild the observations of all environments (or ``rows``); returns a copy."""
        if rows is None:
            obs = build_observations(self.world, self.layout, self._obs)
        else:
            obs = build_observations(self.world, self.layout, rows=rows)
            self._obs[rows] = obs
        if self.residual is None:
            return obs.copy() if rows is None else obs
        base = self.residual.base(obs)
        if rows is None:
            self._base[...] = base
        else:
            self._base[rows] = base
        return self.residual.observe(obs, base)

    def reset(
        self, seed: int | Sequence[int | None] | None = None, mask: np.ndarray | None = None
    ) -> np.ndarray:
        """Reset the environments in ``mask`` (all by default); returns all observations."""
        self.world.reset(seed=seed, mask=mask)
        return self._observe()

    def reset_some(self, mask: np.ndarray) -> np.ndarray:
        """Reset the environments in ``mask``; returns their observations only.

        For the same-step autoresets of the vector views: the other environments'
        observations are not rebuilt.

        Returns:
            ``(mask.sum(), N, D)`` observations, in environment order.
        """
        self.world.reset(mask=mask)
        return self._observe(rows=np.flatnonzero(mask))

    def observations(self) -> np.ndarray:
        """Current observations ``(E, N, D)`` (a copy)."""
        return self._observe()

    def state(self) -> np.ndarray:
        """Global true state ``(E, state_dim)``."""
        return global_state(self.world)

    def step(
        self, actions: np.ndarray, validate: bool = True, active: np.ndarray | None = None
    ) -> StepResult:
        """Apply normalised actions ``(E, N, 3)`` in ``[-1, 1]`` and advance one step.

        Args:
            actions: Accelerations as fractions of ``uav.max_accel`` per axis, or in the
                ``residual_apf`` mode corrections to the APF's command (see
                :mod:`uasep_env.actions`).
            validate: Check the actions (shape, finite, in range) first.
            active: Optional ``(E,)`` mask of environments that move (see
                :meth:`World.step <uasep_env.world.World.step>`).

        Returns:
            The :class:`StepResult`. Episodes that ended are not reset here.
        """
        w = self.world
        if validate:
            actions = validate_actions(actions, (self.n_envs, self.n_uavs, 3), "actions")
        if self.residual is not None:
            actions = self.residual.command(self._base, actions)
        w.step(actions * self.config.uav.max_accel, active=active)
        region = w.region_distances()
        rewards, terms = compute_rewards(w, self.config.reward, region)
        collided = collisions(w)
        terminated = collided.any(axis=1)
        truncated = ((w.steps >= self.config.max_steps) | w.plan_finished()) & ~terminated
        u = self.config.uav
        d_region = region.min(axis=-1, initial=np.inf)
        safety = {
            "min_uav_distance": w.min_uav_dist.copy(),
            "min_obstacle_distance": w.min_obs_dist.copy(),
            "min_region_distance": d_region,
            "loss_of_separation_uav": w.min_uav_dist < u.separation_distance,
            "loss_of_separation_obstacle": w.min_obs_dist < u.obstacle_separation,
            "in_reachable_region": d_region < 0.0,
            "collision": collided,
        }
        obs = self._observe()
        return StepResult(obs, rewards, terms, terminated, truncated, safety)

    @staticmethod
    def env_infos(result: StepResult, env: int) -> list[dict]:
        """The ``info`` dicts of every agent of environment ``env``, in agent order.

        Reward terms as floats, safety figures as Python floats and bools.
        """
        terms = {k: result.terms[k][env].tolist() for k in REWARD_TERMS}
        safety = {k: v[env].tolist() for k, v in result.safety.items()}
        return [
            {
                "reward_terms": {k: v[i] for k, v in terms.items()},
                **{k: v[i] for k, v in safety.items()},
            }
            for i in range(result.rewards.shape[1])
        ]
