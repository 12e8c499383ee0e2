"""Scenarios: the encounter geometry does not depend on the episode's length (issue 12)."""

import numpy as np
import pytest

from uasep_env.config import make_config
from uasep_env.envs.vector import FormationVectorEnv
from uasep_env.scenarios import RANDOM_FAMILIES, sample_scenario

FAMILIES = ["paper", *RANDOM_FAMILIES, "random", "large_formation"]


@pytest.mark.parametrize("family", FAMILIES)
def test_no_scenario_starts_inside_the_separation_distance(family):
    extra = {"n_uavs": 8} if family == "large_formation" else {}
    for duration in (0.2, 0.6, 2.0, 7.0, 45.0, 200.0, 650.0):
        cfg = make_config(scenario=family, episode_duration=duration, n_obstacles=3, **extra)
        for seed in range(60):
            s = sample_scenario(np.random.default_rng(seed), cfg)
            d = np.linalg.norm(s.uav_pos[:, None] - s.uav_pos[None], axis=-1)
            d[np.diag_indices(len(d))] = np.inf
            assert d.min() >= cfg.uav.separation_distance, (family, duration, seed)
            do = np.linalg.norm(s.uav_pos[:, None] - s.obs_pos[None], axis=-1)
            assert do.min() >= cfg.uav.obstacle_separation, (family, duration, seed)


@pytest.mark.parametrize("family", ["paper", "random"])
def test_short_episodes_are_the_start_of_the_same_encounter(family):
    long = make_config(scenario=family)
    for duration in (2.0, 50.0):
        short = make_config(scenario=family, episode_duration=duration)
        for seed in range(20):
            a = sample_scenario(np.random.default_rng(seed), long)
            b = sample_scenario(np.random.default_rng(seed), short)
            for name, value in vars(a).items():
                np.testing.assert_array_equal(value, getattr(b, name), err_msg=name)


def test_short_zero_action_episodes_do_not_collide():
    env = FormationVectorEnv(100, episode_duration=2.0)
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, np.float32)
    for _ in range(env.config.max_steps):
        _, _, term, trunc, _ = env.step(zero)
        assert not term.any()
    assert trunc.all()
