"""Scenarios: the paper's encounter and seeded families of random encounters.

A scenario turns a :class:`numpy.random.Generator` and the config into one episode's
initial conditions (:class:`ScenarioSpec`): the planned trajectory, the UAVs' initial
states, and every obstacle's initial state and performance. All randomness comes from the
generator passed in, so a seed fixes the episode.

Each family (``EnvConfig.scenario``) is one :class:`ScenarioFamily` in the registry
(:data:`FAMILIES`), declared with its documentation in :mod:`uasep_env.scenarios.families`;
the README's table of families is generated from it (``tools/sync_readme.py``). The
``random`` family draws another family per episode from a weighted mix declared once there
(:data:`RANDOM_MIX`).

In every family, obstacle slots beyond the first are background traffic aimed at the
formation at other times. Every obstacle holds its initial course until 10-40 s before its
encounter (drawn per obstacle; 25 s in ``paper``) and then manoeuvres at random, so that
encounters happen and their outcome is uncertain. Every obstacle starts between the ground
plus ``airspace.obstacle_margin`` and ``airspace.ceiling_altitude``.

A partial reset draws many episodes at once (:func:`uasep_env.scenarios.batched.sample_batch`):
the families that declare a batched form (:attr:`ScenarioFamily.draws`) draw per episode,
from its generator in its order, and build the geometry once over the batch (compiled,
``scenario_geometry``); ``random`` and its members declare their draws as tables too
(:attr:`ScenarioFamily.draw_tables`), which a compiled kernel draws from every episode's
generator at once. The same episodes as :func:`sample_scenario`, bit for bit.

The encounters' timing does not depend on ``episode_duration``: they are laid out on the
default 200 s timeline (meetings at 60-140 s, the paper's at 115 s), so a shorter episode is
the start of the same encounter and a longer one flies on along the plan's last leg. No
scenario starts with two UAVs within ``uav.separation_distance`` (the start scatter is shrunk
towards the formation slots when a draw would) or an obstacle near a UAV (obstacles start
at least a minute's flight from their encounter).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from uasep_env.scenarios.families import RANDOM_MIX, TRAFFIC_MIX
from uasep_env.scenarios.registry import (
    FAMILIES,
    Mix,
    ScenarioFamily,
    get_family,
    register,
    scenario_defaults,
    scenario_names,
)
from uasep_env.scenarios.seeds import (
    HELD_OUT_PAPER_SEEDS,
    HELD_OUT_SEEDS,
    REAL_TRAFFIC_TEST_SEEDS,
    SCALING_SEEDS,
    SEED_RANGES,
    TRAINING_SEEDS,
    VALIDATION_SEEDS,
    check_training_seeds,
)
from uasep_env.scenarios.spec import N_WAYPOINTS, ScenarioSpec, place_obstacles

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = [
    "FAMILIES",
    "HELD_OUT_PAPER_SEEDS",
    "HELD_OUT_SEEDS",
    "N_WAYPOINTS",
    "RANDOM_FAMILIES",
    "RANDOM_MIX",
    "REAL_TRAFFIC_TEST_SEEDS",
    "SCALING_SEEDS",
    "SCENARIO_DEFAULTS",
    "SEED_RANGES",
    "TRAFFIC_MIX",
    "TRAINING_SEEDS",
    "VALIDATION_SEEDS",
    "Mix",
    "ScenarioFamily",
    "ScenarioSpec",
    "check_training_seeds",
    "get_family",
    "place_obstacles",
    "register",
    "sample_scenario",
    "scenario_defaults",
    "scenario_names",
]

#: Families drawn by the ``random`` scenario (its mix's names).
RANDOM_FAMILIES = RANDOM_MIX.names
#: Family -> the config it is meant to be flown with, applied where a scenario is chosen by
#: name (the gym ids, ``uasep-eval --scenario``) before overrides; from the registry.
SCENARIO_DEFAULTS: dict[str, dict] = {
    name: dict(f.defaults) for name, f in FAMILIES.items() if f.defaults
}


def sample_scenario(rng: np.random.Generator, config: EnvConfig) -> ScenarioSpec:
    """Draw one episode's initial conditions.

    Args:
        rng: The episode's generator (all randomness comes from it).
        config: The environment config (``config.scenario`` names the family).

    Returns:
        The scenario.
    """
    return get_family(config.scenario).generate(rng, config)
