"""Safety-Gymnasium's step convention over the Gymnasium view: the cost in the step tuple.

Safe-RL trainers built on Safety-Gymnasium (OmniSafe, SafePO) step an env as
``obs, reward, cost, terminated, truncated, info = env.step(action)``. The Gymnasium view
(:class:`~uasep_env.envs.gym_env.FormationEnv`) keeps Gymnasium's five-tuple and reports the
cost in ``info["cost"]`` (:mod:`uasep_env.interface.costs`); :class:`SafeEnv` moves it into
the tuple, as Safety-Gymnasium's own ``Gymnasium2SafetyGymnasium`` wrapper does, without
needing Safety-Gymnasium (whose 1.0.0 release pins gymnasium 0.28.1). The info keeps
``"cost"`` too, so code reading either place sees the same number.
"""

from __future__ import annotations

from typing import Any

import gymnasium

__all__ = ["SafeEnv", "safe_make"]


class SafeEnv(gymnasium.Wrapper):
    """A Gymnasium env whose ``step`` returns ``(obs, reward, cost, terminated, truncated, info)``.

    Args:
        env: A Gymnasium env reporting its cost in ``info["cost"]`` (every ``uasep/`` id).
    """

    def step(self, action: Any) -> tuple[Any, float, float, bool, bool, dict[str, Any]]:
        """Advance one step; the cost is ``info["cost"]``, a float.

        Raises:
            ValueError: The wrapped env's info has no ``"cost"``.
        """
        obs, reward, terminated, truncated, info = self.env.step(action)
        if "cost" not in info:
            raise ValueError(
                f"SafeEnv needs info['cost'] from the wrapped env; {self.env} gave none"
            )
        return obs, reward, float(info["cost"]), terminated, truncated, info


def safe_make(env_id: str = "uasep/Formation-v3", **kwargs: Any) -> SafeEnv:
    """``SafeEnv(gymnasium.make(env_id, **kwargs))``: a ``uasep/`` id in Safety-Gymnasium's form.

    Args:
        env_id: A registered Gymnasium id.
        **kwargs: ``gymnasium.make`` keywords (any :class:`~uasep_env.config.EnvConfig` field).
    """
    return SafeEnv(gymnasium.make(env_id, **kwargs))
