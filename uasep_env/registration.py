"""Gymnasium registration of the ``uasep`` ids (idempotent; runs on ``import uasep_env``)."""

from __future__ import annotations

import gymnasium

from uasep_env.scenarios import SCENARIO_DEFAULTS

__all__ = ["ENV_IDS", "register_envs"]

#: id -> default config overrides.
ENV_IDS: dict[str, dict] = {
    "uasep/Formation-v1": {"scenario": "random"},
    "uasep/PaperEncounter-v1": {"scenario": "paper"},
    "uasep/LargeFormation-v1": {
        "scenario": "large_formation",
        **SCENARIO_DEFAULTS["large_formation"],
    },
}


def register_envs() -> None:
    """Register every id in :data:`ENV_IDS` that is not registered yet.

    Each id's ``max_episode_steps`` is its default episode length in steps (the env
    truncates there itself; ``gymnasium.make`` adds a ``TimeLimit`` at the same step and
    ``gymnasium.make_vec`` passes it to the vector env). The entry points are import
    strings, so processes started with ``spawn`` (e.g. ``AsyncVectorEnv``) import this
    package, and so register the ids, by themselves.
    """
    from uasep_env.config import make_config

    for env_id, defaults in ENV_IDS.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point="uasep_env.envs.gym_env:FormationEnv",
            vector_entry_point="uasep_env.envs.vector:FormationVectorEnv",
            kwargs=dict(defaults),
            max_episode_steps=make_config(defaults).max_steps,
            disable_env_checker=False,
        )
