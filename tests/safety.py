"""Encounters on a collision course, for every test that claims a controller keeps separation.

The paper's obstacle passes 10 m below the formation, so plan tracking alone keeps 10-14 m
there: a "keeps separation on the paper scenario" test cannot fail. The ``collision_*``
families aim a straight-flying obstacle at a UAV's planned position, at its altitude; a
controller without avoidance collides on every one of :data:`SEEDS` (checked by
``tests/test_policies.py``), so a controller that passes here avoids.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from uasep_env import make_config
from uasep_env.config import EnvConfig
from uasep_env.metrics import episode_metrics
from uasep_env.policies import APF, APFGains, Policy
from uasep_env.rollout import run_episodes

#: The collision-course families (a head-on and a crossing encounter).
COLLISION_COURSES = ("collision_head_on", "collision_crossing")
#: Seeds played per encounter (noise on).
SEEDS = tuple(range(6))
#: Long enough for the meeting (at 45-60 % of the episode) and the return to the plan.
EPISODE_S = 100.0


def collision_config(scenario: str, **overrides: object) -> EnvConfig:
    """The config of a collision-course encounter (noise on, one obstacle by default)."""
    return make_config(scenario=scenario, episode_duration=EPISODE_S, **overrides)


def no_avoidance(config: EnvConfig) -> Policy:
    """Plan tracking alone: the paper's APF with the obstacle repulsion switched off."""
    return APF(config, gains=APFGains(k_obstacle=0.0))


def separation_losses(
    make: Callable[[EnvConfig], Policy], scenario: str, seeds=SEEDS, **overrides: object
) -> dict[str, list]:
    """Per seed: collision, loss of separation, closest obstacle and UAV distance (m)."""
    cfg = collision_config(scenario, **overrides)
    eps = run_episodes(make(cfg), cfg, list(seeds))
    ms = [episode_metrics(ep.record).episode for ep in eps]
    return {
        "collision": [m.collision for m in ms],
        "lost": [bool(m.collision or m.loss_of_separation) for m in ms],
        "min_obstacle": [float(m.min_obstacle_distance) for m in ms],
        "min_uav": [float(m.min_uav_separation) for m in ms],
        "terminated": [bool(ep.terminated) for ep in eps],
        "distance": float(np.min([m.min_obstacle_distance for m in ms])),
    }
