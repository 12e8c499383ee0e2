"""Gymnasium registration of the ``uasep`` ids (idempotent; runs on ``import uasep_env``).

The ids come from the scenario registry: every family with a ``gym_name`` registers
``uasep/<gym_name>-v<ENV_VERSION>`` (:data:`ENV_IDS`), and, for the earlier versions whose
episodes today's code reproduces (:data:`uasep_env.config.VERSION_DEFAULTS`), the same id at
that version with that version's defaults as overrides: ``uasep/Formation-v2`` plays the
``-v2`` episodes bit for bit.
"""

from __future__ import annotations

import gymnasium

from uasep_env.config.env import VERSION_DEFAULTS
from uasep_env.scenarios import FAMILIES

__all__ = [
    "EARLIER_IDS",
    "ENV_IDS",
    "ENV_VERSION",
    "ENV_VERSIONS",
    "FIRST_VERSION",
    "ID_VERSIONS",
    "register_envs",
]

#: The env ids' version: bumped whenever episodes or rewards change (see CHANGELOG.md), by
#: adding the new version's row to :data:`~uasep_env.config.VERSION_DEFAULTS` (one source).
ENV_VERSION = max(VERSION_DEFAULTS)

#: Each env version, newest first: ``(version, package release, what changed)``. Bumping
#: :data:`ENV_VERSION` needs a row here (tested); the env cards' version history is this
#: table (``docs/envs/``, ``tools/build_env_cards.py``), CHANGELOG.md has the detail.
ENV_VERSIONS: tuple[tuple[int, str, str], ...] = (
    (
        3,
        "0.4.0",
        "The obstacles' predicted region is the calibrated one by default "
        '(`prediction.fit="calibrated"`: it held recorded aircraft\'s next 10 s in >= 95 % '
        "of test windows, the enclosing Dubins region of `-v2` in 22 %), and every "
        "controller's default margin is the knee of its own front on a `-v3` validation "
        "bank. The `-v2` ids stay registered and reproduce their episodes.",
    ),
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


def _merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` on top, nested dicts merged."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _ids(version: int) -> dict[str, dict]:
    """Every family's id at ``version``, with that version's defaults as overrides."""
    return {
        f"uasep/{f.gym_name}-v{version}": _merge(
            {"scenario": f.name, **f.defaults}, VERSION_DEFAULTS[version]
        )
        for f in FAMILIES.values()
        if f.gym_name is not None and FIRST_VERSION.get(f.gym_name, 0) <= version
    }


#: id -> default config overrides, the current version's ids.
ENV_IDS: dict[str, dict] = _ids(ENV_VERSION)
#: The same for the earlier versions whose episodes today's code reproduces (registered
#: too; gymnasium warns that a newer version exists).
EARLIER_IDS: dict[str, dict] = {
    i: d
    for v in sorted(VERSION_DEFAULTS, reverse=True)
    if v < ENV_VERSION
    for i, d in _ids(v).items()
}

#: id -> its env version (every id of :data:`ENV_IDS`).
ID_VERSIONS: dict[str, int] = {i: int(i.rsplit("-v", 1)[1]) for i in (*ENV_IDS, *EARLIER_IDS)}


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` and :data:`EARLIER_IDS` not registered yet.

    Each id's ``max_episode_steps`` is its default episode length in steps (the env
    truncates there itself; ``gymnasium.make`` adds a ``TimeLimit`` at the same step and
    ``gymnasium.make_vec`` passes it to the vector env). The entry points are import
    strings, so processes started with ``spawn`` (e.g. ``AsyncVectorEnv``) import this
    package, and so register the ids, by themselves.
    """
    from uasep_env.config import make_config

    for env_id, defaults in {**ENV_IDS, **EARLIER_IDS}.items():
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
