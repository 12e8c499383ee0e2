"""The batched environment core shared by every environment view.

:class:`EnvCore` wraps a :class:`~uasep_env.sim.world.World` and adds what an RL environment
needs on top of the physics: action validation and scaling, observations, named rewards,
termination (a collision, or a UAV lost: farther than ``uav.lost_distance`` from its
plan), truncation (time limit / end of the plan), the per-step safety figures and the
cost channel of constrained RL (:mod:`uasep_env.interface.costs`). The
PettingZoo env, the Gymnasium env, the vector env and the SB3 adapter are thin views of
it; none of them steps the world another way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uasep_env.config import EnvConfig, make_config
from uasep_env.config.checks import is_real
from uasep_env.envs._infos import row_dicts
from uasep_env.interface.actions import Residual
from uasep_env.interface.costs import COST_TERMS, SAFETY_FLAGS
from uasep_env.interface.observation import ObservationLayout, build_observations, global_state
from uasep_env.interface.outcome import compute_outcome
from uasep_env.interface.rewards import REWARD_TERMS, share_rewards
from uasep_env.runtime.capacity import check_count
from uasep_env.sim.world import World

__all__ = [
    "ACTION_TOLERANCE",
    "SAFETY_KEYS",
    "ActionTypeError",
    "EnvCore",
    "StepResult",
    "action_array",
    "check_options",
    "prepare_actions",
    "validate_actions",
]

#: The per-step safety figures of :attr:`StepResult.safety`, in order: the minimum
#: distances to another UAV, an obstacle and a region over the step (m), the safety flags
#: the cost terms read (:data:`uasep_env.interface.costs.SAFETY_FLAGS`: loss of separation
#: with a UAV, with an obstacle, inside a region), a collision, lost.
SAFETY_KEYS = (
    "min_uav_distance", "min_obstacle_distance", "min_region_distance",
    *SAFETY_FLAGS,
    "collision", "lost",
)  # fmt: skip
#: An agent's info dict from its columns: the reward terms, the safety figures, the cost
#: and the cost terms, the keys written out once (:func:`uasep_env.envs._infos.row_dicts`).
_agent_infos = row_dicts(
    (("reward_terms", REWARD_TERMS), *SAFETY_KEYS, "cost", ("cost_terms", COST_TERMS))
)


#: Actions may exceed ``[-1, 1]`` by this much (rounding) before strict checks reject them.
ACTION_TOLERANCE = 1e-6


class ActionTypeError(TypeError, ValueError):
    """An action that is not made of real numbers (strings, bools, complex, None, ...).

    A :class:`TypeError` (Python's convention for a value of the wrong type) that is also a
    :class:`ValueError`, which every other bad action raises.
    """


def _short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _real_array(actions: Any, where: str) -> np.ndarray:
    """``actions`` as an array of an integer or floating dtype; anything else is named."""
    if isinstance(actions, np.ndarray) and actions.dtype.kind in "fiu":
        return actions
    if isinstance(actions, np.ndarray) and actions.dtype.kind != "O":
        if actions.size == 0:
            raise ActionTypeError(f"{where} must be real numbers, got dtype {actions.dtype}")
        idx = np.unravel_index(0, actions.shape)
        raise ActionTypeError(
            f"{where} must be real numbers, got {_short(actions[idx])} (dtype {actions.dtype}) "
            f"at index {tuple(int(i) for i in idx)}"
        )
    # Lists, scalars and object arrays: look at each element's own type, so that bools,
    # strings or None inside a list are not converted.
    try:
        arr = actions if isinstance(actions, np.ndarray) else np.asarray(actions, dtype=object)
    except (TypeError, ValueError, OverflowError) as err:
        raise ActionTypeError(
            f"{where} must be a rectangular array of real numbers, got {_short(actions)}"
        ) from err
    flat = arr.ravel()
    for i, x in enumerate(flat):
        if not is_real(x, any_real=True):
            idx = tuple(int(j) for j in np.unravel_index(i, arr.shape))
            what = "a nested sequence (ragged)" if isinstance(x, (list, tuple, np.ndarray)) else ""
            raise ActionTypeError(
                f"{where} must be real numbers, got {what or _short(x)} at index {idx}"
                + (f": {_short(x)}" if what else "")
            )
    # Python ints beyond float range are finite: clamp them (they are clipped anyway).
    values = [max(-2, min(2, x)) if isinstance(x, int) else x for x in flat]
    return np.array([float(v) for v in values], dtype=float).reshape(arr.shape)


def action_array(actions: Any, shape: tuple[int, ...], where: str = "action") -> np.ndarray:
    """``actions`` as a float64 array of ``shape``, not range-checked.

    Raises:
        ActionTypeError: A value that is not a real number, named with its index.
        ValueError: The wrong shape.
    """
    a = _real_array(actions, where)
    if a.shape != tuple(shape):
        raise ValueError(f"{where} must have shape {tuple(shape)}, got {a.shape}")
    return a.astype(float, copy=False)


def prepare_actions(
    actions: Any, shape: tuple[int, ...], where: str = "action", strict: bool = False
) -> tuple[np.ndarray, np.ndarray | None]:
    """Check normalised actions and clip finite ones to the box ``[-1, 1]``.

    Only real numbers are actions: arrays of an integer or floating dtype, Python or numpy
    numbers, and (nested) lists of them. Finite values outside the box are clipped to it
    (the ecosystem's convention), unless ``strict``.

    Args:
        actions: The actions.
        shape: Their expected shape.
        where: Name used in error messages.
        strict: Raise for values outside the box (beyond the rounding tolerance
            :data:`ACTION_TOLERANCE`) instead of clipping them.

    Returns:
        ``(clipped, outside)``: the actions as float64 in ``[-1, 1]``, and a bool mask of
        ``shape`` marking the values that were outside the box (``None`` when none was).

    Raises:
        ActionTypeError: A value that is not a real number (a ``TypeError`` and a
            ``ValueError``), named with its index.
        ValueError: The wrong shape, or a non-finite value (named with its index), or, with
            ``strict``, a value outside the box.
    """
    a = action_array(actions, shape, where)
    # One pass in the usual case: NaN compares false, so it fails this test too.
    if (np.abs(a) <= 1.0).all():
        return np.array(a, dtype=float), None
    finite = np.isfinite(a)
    if not finite.all():
        idx = tuple(int(i) for i in np.argwhere(~finite)[0])
        raise ValueError(f"{where} contains a non-finite value {float(a[idx])} at index {idx}")
    if strict:
        beyond = np.abs(a) > 1.0 + ACTION_TOLERANCE
        if beyond.any():
            idx = tuple(int(i) for i in np.argwhere(beyond)[0])
            raise ValueError(
                f"{where} value {float(a[idx])} at index {idx} is outside the action space "
                "[-1, 1] (action.strict is set)"
            )
    return np.minimum(np.maximum(a, -1.0), 1.0), np.abs(a) > 1.0


def validate_actions(
    actions: np.ndarray, shape: tuple[int, ...], where: str = "action"
) -> np.ndarray:
    """Check normalised actions strictly: shape, real numbers, finite, in ``[-1, 1]``.

    :func:`prepare_actions` with ``strict=True``, for callers that own their actions (the
    rollouts of policies); the environments clip unless ``action.strict`` is set.

    Args:
        actions: The actions.
        shape: Their expected shape.
        where: Name used in error messages.

    Returns:
        The actions as float64, clipped only by the rounding tolerance.

    Raises:
        ValueError: Naming a value that is not a number (:class:`ActionTypeError`), the
            wrong shape, or the first non-finite or out-of-range value.
    """
    return prepare_actions(actions, shape, where, strict=True)[0]


def clipped_counts(outside: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    """Per-agent number of clipped action components: ``outside`` summed over its last axis.

    Args:
        outside: The mask of :func:`prepare_actions` (``None``: nothing was clipped).
        shape: The shape of the counts (the mask's shape without its last axis).
    """
    if outside is None:
        return np.zeros(shape, dtype=np.int64)
    return outside.reshape(*shape, -1).sum(axis=-1)


def check_options(options: Any, supported: Sequence[str] | None, where: str = "reset") -> dict:
    """Reset ``options``: ``None`` or a dict of the ``supported`` keys (unknown keys named).

    Args:
        options: The options.
        supported: The option keys understood (``None``: any key, the others ignored).
        where: Name used in error messages.

    Raises:
        TypeError: ``options`` is not a dict (or None).
        ValueError: An unknown option key.
    """
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"{where} options must be a dict or None, got {_short(options)}")
    unknown = [] if supported is None else [k for k in options if k not in supported]
    if unknown:
        names = ", ".join(_short(k) for k in unknown)
        raise ValueError(
            f"unknown {where} option(s) {names}; supported: {', '.join(supported or ()) or 'none'}"
        )
    return options


@dataclass
class StepResult:
    """What one batched step produced (arrays over ``(n_envs, n_uavs)``).

    Attributes:
        obs: ``(E, N, D)`` observations after the step.
        rewards: ``(E, N)`` rewards.
        terms: Unweighted reward terms, name -> ``(E, N)``.
        terminated: ``(E,)`` an episode ended by a collision or a lost UAV (farther than
            ``uav.lost_distance`` from its planned position).
        truncated: ``(E,)`` an episode ended by the time limit or the end of the plan.
        safety: Per-step safety figures, name -> ``(E, N)``.
        cost: ``(E, N)`` costs (>= 0; :mod:`uasep_env.interface.costs`), in no reward.
        cost_terms: Unweighted cost terms, name -> ``(E, N)``.
        terms_array: ``(T, E, N)`` the reward terms in ``REWARD_TERMS`` order, whose rows
            :attr:`terms` holds (``None`` where a caller built only the dict).
        cost_terms_array: ``(C, E, N)`` the cost terms in ``COST_TERMS`` order, whose rows
            :attr:`cost_terms` holds (or ``None``).
    """

    obs: np.ndarray
    rewards: np.ndarray
    terms: dict[str, np.ndarray]
    terminated: np.ndarray
    truncated: np.ndarray
    safety: dict[str, np.ndarray]
    cost: np.ndarray
    cost_terms: dict[str, np.ndarray]
    terms_array: np.ndarray | None = None
    cost_terms_array: np.ndarray | None = None


class EnvCore:
    """Observations, rewards and episode ends over a batched :class:`World`.

    Args:
        config: The validated config (or a dict).
        n_envs: Number of environments in the batch.
        count_name: The name ``n_envs`` has in the view that makes this core (``num_envs``),
            for the error when that many environments would not fit in memory.

    Raises:
        ValueError: ``n_envs`` is not a positive integer or would not fit in memory
            (:func:`uasep_env.runtime.capacity.check_count`).
    """

    def __init__(
        self, config: EnvConfig | dict | None = None, n_envs: int = 1, *, count_name: str = "n_envs"
    ) -> None:
        self.config = config if isinstance(config, EnvConfig) else make_config(config)
        check_count(count_name, n_envs, self.config)  # before anything is allocated
        self.world = World(self.config, n_envs)
        self.layout = ObservationLayout.from_config(self.config)
        self._max_steps = self.config.max_steps  # a property that computes it
        self.n_envs = n_envs
        self.n_uavs = self.config.n_uavs
        self._obs = np.zeros((n_envs, self.n_uavs, self.layout.world_dim), dtype=np.float32)
        # A residual mode: the base controller's command for the current observations (what
        # the next action corrects); None in direct mode.
        self.residual = Residual(self.config) if self.layout.base_action else None
        self._base = np.zeros((n_envs, self.n_uavs, 3), dtype=np.float32)

    def state_dict(self) -> dict[str, np.ndarray]:
        """The batch's state as arrays (copies), for :meth:`load_state_dict`.

        The world's (``world.*``, :meth:`World.state_dict
        <uasep_env.sim.world.World.state_dict>`) and the last observations and APF commands
        (``core.*``), which the next step's actions correct.
        """
        state = {f"world.{k}": v for k, v in self.world.state_dict().items()}
        state |= {f"core.{k}": v.copy() for k, v in self._state_arrays().items()}
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a :meth:`state_dict` of a core of the same config and size.

        Everything checked before anything is written (:meth:`World.load_state_dict
        <uasep_env.sim.world.World.load_state_dict>`).

        Raises:
            ValueError: One line naming the array.
        """
        from uasep_env.sim.snapshot import check_arrays, copy_arrays

        other = sorted(k for k in state if not k.startswith(("world.", "core.")))
        if other:
            raise ValueError(f"{other[0]!r:.60}: not part of the state")
        ours = {k[5:]: v for k, v in state.items() if k.startswith("core.")}
        live = self._state_arrays()
        check_arrays({f"core.{k}": v for k, v in ours.items()},
                     {f"core.{k}": v for k, v in live.items()})  # fmt: skip
        try:
            self.world.load_state_dict(
                {k[6:]: v for k, v in state.items() if k.startswith("world.")}
            )
        except ValueError as err:  # named as in this state
            raise ValueError(f"world.{err}") from None
        copy_arrays(ours, live)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {"obs": self._obs, "base": self._base}

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
        self,
        actions: np.ndarray,
        validate: bool = True,
        active: np.ndarray | None = None,
        reset: np.ndarray | None = None,
    ) -> StepResult:
        """Apply normalised actions ``(E, N, 3)`` in ``[-1, 1]`` and advance one step.

        Args:
            actions: Accelerations as fractions of ``uav.max_accel`` per axis, or in the
                ``residual_apf`` mode corrections to the APF's command (see
                :mod:`uasep_env.interface.actions`).
            validate: Check the actions (shape, finite, in range) first.
            active: Optional ``(E,)`` mask of environments that move (see
                :meth:`World.step <uasep_env.sim.world.World.step>`).
            reset: Optional ``(E,)`` mask of environments that start a new episode in this
                step instead of moving (the same; their actions are ignored).

        Returns:
            The :class:`StepResult`. Episodes that ended are not reset here.
        """
        w = self.world
        if validate:
            actions = validate_actions(actions, (self.n_envs, self.n_uavs, 3), "actions")
        if self.residual is not None:
            actions = self.residual.command(self._base, actions)
        w.step(actions * self.config.uav.max_accel, active=active, reset=reset)
        cfg = self.config
        out = compute_outcome(w, cfg, w.region_distances())
        terminated = (out.collided | out.lost).any(axis=1)
        truncated = ((w.steps >= self._max_steps) | w.plan_finished()) & ~terminated
        safety = dict(
            zip(
                SAFETY_KEYS,
                (w.min_uav_dist.copy(), w.min_obstacle_dist.copy(), out.d_region, *out.flags,
                 out.collided, out.lost),
                strict=True,
            )
        )  # fmt: skip
        rewards = share_rewards(out.own, cfg.reward)
        terms = dict(zip(REWARD_TERMS, out.terms, strict=True))
        cost_terms = dict(zip(COST_TERMS, out.cost_terms, strict=True))
        obs = self._observe()
        return StepResult(
            obs, rewards, terms, terminated, truncated, safety, out.cost, cost_terms,
            out.terms, out.cost_terms,
        )  # fmt: skip

    @staticmethod
    def env_infos(result: StepResult, env: int) -> list[dict]:
        """The ``info`` dicts of every agent of environment ``env``, in agent order.

        Reward terms as floats, safety figures as Python floats and bools, the ``cost`` and
        its ``cost_terms`` as floats.
        """
        return _agent_infos(
            *(result.terms[k][env].tolist() for k in REWARD_TERMS),
            *(result.safety[k][env].tolist() for k in SAFETY_KEYS),
            result.cost[env].tolist(),
            *(result.cost_terms[k][env].tolist() for k in COST_TERMS),
        )
