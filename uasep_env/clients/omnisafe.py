"""OmniSafe over the Gymnasium view: PPOLag (and OmniSafe's other on-policy algorithms).

Importing this module imports OmniSafe and registers :class:`UasepCMDP` with OmniSafe's
``env_register`` for every ``uasep/`` id (:data:`~uasep_env.registration.ENV_IDS`), so that
::

    import omnisafe
    import uasep_env.clients.omnisafe  # registers the uasep/ ids with OmniSafe

    agent = omnisafe.Agent("PPOLag", "uasep/Formation-v3", custom_cfgs={...})
    agent.learn()

trains on the formation, the cost being the Gymnasium view's ``info["cost"]``
(:mod:`uasep_env.interface.costs`). ``custom_cfgs["env_cfgs"]`` are ``gymnasium.make``
keywords (any :class:`~uasep_env.config.EnvConfig` field); ``train_cfgs.vector_env_nums``
above 1 steps the native vector env (:class:`~uasep_env.envs.vector.FormationVectorEnv`).

OmniSafe 0.5.0 imports ``safety_gymnasium`` when it is imported (for its own
Safety-Gymnasium tasks), and Safety-Gymnasium 1.0.0 does not import under Gymnasium 1.x
(``gymnasium.wrappers.compatibility`` is gone) nor install beside it (it pins gymnasium
0.28.1, mujoco 2.3.3 and pygame 2.1.0, which does not build on Python 3.11). Where
``safety_gymnasium`` does not import, this module puts a stand-in in ``sys.modules`` before
importing OmniSafe: its ``make`` raises ``ImportError`` saying why, and no uasep path calls
it. The install that works is in ``docs/clients.md`` (OmniSafe, safe RL).
"""

from __future__ import annotations

import importlib.util
import sys
import types
from typing import Any, ClassVar, NoReturn

import gymnasium
import numpy as np

from uasep_env.envs.safe import SafeEnv
from uasep_env.registration import ENV_IDS

__all__ = ["UasepCMDP"]


def _safety_gymnasium_stand_in(reason: str) -> types.ModuleType:
    """A ``safety_gymnasium`` module whose ``make`` and ``vector.make`` raise ``reason``."""

    def make(*args: Any, **kwargs: Any) -> NoReturn:
        raise ImportError(f"safety_gymnasium is a stand-in here (uasep_env): {reason}")

    module = types.ModuleType("safety_gymnasium", "Stand-in: Safety-Gymnasium does not import.")
    module.make = make  # type: ignore[attr-defined]
    module.vector = types.SimpleNamespace(make=make)  # type: ignore[attr-defined]
    module.UASEP_STAND_IN = True  # type: ignore[attr-defined]
    return module


# Missing OmniSafe is said before anything changes (no stand-in left behind).
if importlib.util.find_spec("omnisafe") is None:
    raise ModuleNotFoundError(
        "uasep_env.clients.omnisafe needs OmniSafe: see docs/clients.md, OmniSafe (safe RL)",
        name="omnisafe",
    )

# OmniSafe imports safety_gymnasium at its own import; only the uasep ids are used here.
try:
    import safety_gymnasium  # noqa: F401
except ImportError as exc:  # absent, or 1.0.0 under gymnasium 1.x
    sys.modules["safety_gymnasium"] = _safety_gymnasium_stand_in(f"{type(exc).__name__}: {exc}")

import torch  # noqa: E402  (OmniSafe's dependency, after the stand-in as OmniSafe is)
from omnisafe.envs.core import CMDP, env_register  # noqa: E402


def _vector_cost(info: dict[str, Any], num_envs: int) -> np.ndarray:
    """Each environment's cost of the step from the vector env's same-step infos.

    An environment that ended in the step has its reset's (empty) info, masked out; the step's
    cost is then in ``info["final_info"]``.
    """
    cost = np.zeros(num_envs)
    for block in (info, info.get("final_info", {})):
        if "cost" in block:
            cost = np.where(block["_cost"], block["cost"], cost)
    return cost


class UasepCMDP(CMDP):
    """A ``uasep/`` Gymnasium id as an OmniSafe ``CMDP``.

    One env (``num_envs == 1``): ``gymnasium.make(env_id, **kwargs)`` in Safety-Gymnasium's
    step form (:class:`~uasep_env.envs.safe.SafeEnv`), reset by OmniSafe's ``AutoReset``
    (which keeps the final observation). The env truncates at its own episode length, so
    OmniSafe's ``TimeLimit`` is not used (it would truncate at ``max_episode_steps`` only).
    Several (``num_envs > 1``): ``gymnasium.make_vec`` (the native vector env), resetting in
    the same step, its final observations in ``info["final_observation"]`` as OmniSafe's
    Safety-Gymnasium env gives them.

    Args:
        env_id: A ``uasep/`` id.
        num_envs: Number of environments.
        device: Torch device of the tensors returned.
        **kwargs: ``gymnasium.make`` keywords (OmniSafe's ``env_cfgs``).
    """

    need_auto_reset_wrapper: bool = False
    need_time_limit_wrapper: bool = False
    _support_envs: ClassVar[list[str]] = list(ENV_IDS)

    def __init__(
        self,
        env_id: str,
        num_envs: int = 1,
        device: torch.device | str = "cpu",
        **kwargs: Any,
    ) -> None:
        super().__init__(env_id)
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        self._num_envs = num_envs
        self._device = torch.device(device)
        self._env: Any
        if num_envs == 1:
            self.need_auto_reset_wrapper = True
            self._env = SafeEnv(gymnasium.make(env_id, **kwargs))
            self._action_space = self._env.action_space
            self._observation_space = self._env.observation_space
            steps = self._env.spec.max_episode_steps
        else:
            self._env = gymnasium.make_vec(
                env_id, num_envs=num_envs, autoreset_mode="SameStep", **kwargs
            )
            self._action_space = self._env.single_action_space
            self._observation_space = self._env.single_observation_space
            steps = self._env.spec.max_episode_steps
        self._max_episode_steps = min(steps, self._env.unwrapped.config.max_steps)
        self._metadata = dict(self._env.metadata)

    def _tensor(self, x: Any) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x), dtype=torch.float32, device=self._device)

    def step(
        self, action: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict]:
        """One step: ``(obs, reward, cost, terminated, truncated, info)``, float32 tensors."""
        act = action.detach().cpu().numpy()
        if self._num_envs == 1:
            obs, reward, cost, terminated, truncated, info = self._env.step(act)
        else:
            obs, reward, terminated, truncated, info = self._env.step(act)
            cost = _vector_cost(info, self._num_envs)
            if "final_obs" in info:
                # OmniSafe bootstraps a truncated episode's value from its final observation.
                final = [
                    o if o is not None else np.zeros(obs.shape[-1], np.float32)
                    for o in info["final_obs"]
                ]
                info["final_observation"] = self._tensor(np.stack(final))
                info["_final_observation"] = torch.as_tensor(info["_final_obs"])
        return (
            self._tensor(obs),
            self._tensor(reward),
            self._tensor(cost),
            self._tensor(terminated),
            self._tensor(truncated),
            info,
        )

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[torch.Tensor, dict]:
        """Start an episode (each environment's); ``seed`` fixes it."""
        obs, info = self._env.reset(seed=seed, options=options)
        return self._tensor(obs), info

    @property
    def max_episode_steps(self) -> int:
        """Steps in an episode (the env truncates there)."""
        return self._max_episode_steps

    def set_seed(self, seed: int) -> None:
        """Seed the env (a reset with ``seed``, as OmniSafe's Safety-Gymnasium env does)."""
        self.reset(seed=seed)

    def render(self) -> Any:
        """The env's frame (``render_mode`` in ``env_cfgs``)."""
        return self._env.render()

    def close(self) -> None:
        """Close the env."""
        self._env.close()


env_register(UasepCMDP)  # OmniSafe's make() and Agent() find the uasep/ ids from here on
