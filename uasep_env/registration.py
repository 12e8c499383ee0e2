"""Gymnasium registration of the ``uasep`` ids (idempotent; runs on ``import uasep_env``).

The ids come from the scenario registry: every family with a ``gym_name`` registers
``uasep/<gym_name>-v<ENV_VERSION>`` (:data:`ENV_IDS`).
"""

from __future__ import annotations

import gymnasium

from uasep_env.scenarios import FAMILIES

__all__ = ["ENV_IDS", "ENV_VERSION", "ENV_VERSIONS", "FIRST_VERSION", "register_envs"]

#: The env ids' version: bumped whenever episodes or rewards change (see CHANGELOG.md).
ENV_VERSION = 2

#: Each env version, newest first: ``(version, package release, what changed)``. Bumping
#: :data:`ENV_VERSION` needs a row here (tested); the env cards' version history is this
#: table (``docs/envs/``, ``tools/build_env_cards.py``), CHANGELOG.md has the detail.
ENV_VERSIONS: tuple[tuple[int, str, str], ...] = (
    (
        2,
        "0.3.0",
        "Obstacles stay in the sky (the `airspace` group): climbing obstacles no longer "
        "start underground and no obstacle flies below the ground; only episodes with a "
        "climbing obstacle changed. `uasep/RealTraffic-v2` (recorded aircraft) added.",
    ),
    (
        1,
        "0.2.0",
        "The reward made learnable (+1 a step alive, penalties summing to at most 1, a "
        "collision costs the whole episode to every UAV); a UAV farther than "
        "`uav.lost_distance` from its plan ends the episode; `observation.clip` 12; encounter "
        "timing independent of `episode_duration`; `spec.max_episode_steps` declared.",
    ),
    (0, "0.1.0", "The first ids."),
)

#: The first env version of ids added after ``-v0``, by the family's ``gym_name``.
FIRST_VERSION: dict[str, int] = {"RealTraffic": 2}

#: id -> default config overrides.
ENV_IDS: dict[str, dict] = {
    f"uasep/{f.gym_name}-v{ENV_VERSION}": {"scenario": f.name, **f.defaults}
    for f in FAMILIES.values()
    if f.gym_name is not None
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
