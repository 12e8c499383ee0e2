"""Scenarios: the encounter geometry does not depend on the episode's length (issue 12)."""

import numpy as np
import pytest
from conftest import given, settings, st

from uasep_env.config import make_config
from uasep_env.envs.vector import FormationVectorEnv
from uasep_env.scenarios import sample_scenario, scenario_names

FAMILIES = list(scenario_names())  # every registered family


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
            do = np.linalg.norm(s.uav_pos[:, None] - s.obstacle_pos[None], axis=-1)
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


# ---- The registry ------------------------------------------------------------------------------
def test_every_list_of_families_reads_the_registry():
    import uasep_env.config as config_pkg
    from uasep_env.evaluation.cli import build_parser
    from uasep_env.registration import ENV_IDS, ENV_VERSION
    from uasep_env.scenarios import FAMILIES, RANDOM_MIX, TRAFFIC_MIX, scenario_names

    assert config_pkg.SCENARIOS == scenario_names() == tuple(FAMILIES)
    choices = next(a.choices for a in build_parser()._actions if a.dest == "scenario")
    assert tuple(choices) == scenario_names()
    ids = {f"uasep/{f.gym_name}-v{ENV_VERSION}" for f in FAMILIES.values() if f.gym_name}
    assert set(ENV_IDS) == ids
    assert all(n in FAMILIES for n in RANDOM_MIX.names)
    assert all(n in FAMILIES for n in TRAFFIC_MIX.names)
    for f in FAMILIES.values():
        assert f.summary and f.parameters and "\n" not in f.summary, f.name


def test_a_mix_of_equal_weights_draws_as_integers_did():
    from uasep_env.scenarios import Mix

    names = ("a", "b", "c", "d", "e")
    mix = Mix(weights=dict.fromkeys(names, 1))
    r1, r2 = np.random.default_rng(7), np.random.default_rng(7)
    assert [mix.draw(r1) for _ in range(200)] == [names[int(r2.integers(5))] for _ in range(200)]
    weighted = Mix(weights={"x": 3, "y": 1})
    draws = [weighted.draw(np.random.default_rng(s)) for s in range(4000)]
    assert 0.7 < draws.count("x") / len(draws) < 0.8
    with pytest.raises(ValueError, match="positive integer weights"):
        Mix(weights={"x": 0})


def test_unknown_or_taken_family_names_are_refused():
    from uasep_env.scenarios import FAMILIES, ScenarioFamily, get_family, register

    with pytest.raises(ValueError, match="scenario='moon'"):
        get_family("moon")
    with pytest.raises(ValueError, match="taken"):
        register(
            ScenarioFamily(
                name="paper", summary="x", parameters="y", generate=FAMILIES["paper"].generate
            )
        )


# ---- Obstacles stay in the sky -----------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(
    family=st.sampled_from(FAMILIES),
    seed=st.integers(0, 2**32 - 1),
    n_obstacles=st.integers(0, 4),
    ground=st.floats(-200.0, 60.0),
    margin=st.floats(0.0, 30.0),
    ceiling=st.floats(110.0, 1000.0),
)
def test_every_family_starts_obstacles_in_the_airspace(
    family, seed, n_obstacles, ground, margin, ceiling
):
    margin = min(margin, 99.0 - ground)
    extra = {"n_uavs": 8} if family == "large_formation" else {}
    cfg = make_config(
        scenario=family,
        n_obstacles=n_obstacles,
        airspace={
            "ground_altitude": ground,
            "obstacle_margin": margin,
            "ceiling_altitude": ceiling,
        },
        **extra,
    )
    try:
        s = sample_scenario(np.random.default_rng(seed), cfg)
    except ValueError as err:  # a family may refuse an airspace it cannot fill (real tracks)
        assert "airspace.ceiling_altitude" in str(err) or "airspace.ground" in str(err), err
        return
    alt = -s.obstacle_pos[:, 2]
    assert np.all(alt >= ground + margin - 1e-9) and np.all(alt <= ceiling + 1e-9)
    band = s.obstacle_alt_band
    assert np.all(band[:, 0] <= alt + 1e-9) and np.all(alt <= band[:, 1] + 1e-9)
    assert np.all(band[:, 0] >= ground + margin - 1e-9) and np.all(band[:, 1] <= ceiling + 1e-9)


@pytest.mark.parametrize("family", ["climbing", "random", "multi_obstacle"])
def test_obstacles_stay_above_the_ground_through_episodes(family):
    """Issue 19: `climbing` started obstacles up to 152 m underground; none is, nor goes, now."""
    from uasep_env import World

    w = World(make_config(scenario=family, n_obstacles=3), n_envs=12)
    w.reset(seed=0)
    floor = w.config.airspace.ground_altitude + w.config.airspace.obstacle_margin
    assert np.all(-w.obstacles.pos[..., 2] >= floor - 1e-9)
    lowest = np.inf
    for _ in range(w.config.max_steps):
        w.step(np.zeros((12, 3, 3)))
        lowest = min(lowest, float(np.min(-w.obstacles.pos[..., 2])))
    assert lowest >= w.config.airspace.ground_altitude


def test_climbers_that_would_start_underground_climb_more_slowly():
    cfg = make_config(scenario="climbing")
    slowed = 0
    for seed in range(200):
        s = sample_scenario(np.random.default_rng(seed), cfg)
        c, vz = s.obstacle_climb_rate[0], s.obstacle_max_climb_rate[0]
        assert abs(c) <= vz + 1e-12
        slowed += abs(c) < vz - 1e-12
    assert slowed > 20  # 68 of these 200 seeds started below 20 m before the fix


def test_airspace_is_validated():
    with pytest.raises(ValueError, match=r"airspace\.ground_altitude"):
        make_config(airspace={"ground_altitude": 90.0})
    with pytest.raises(ValueError, match=r"airspace\.ceiling_altitude"):
        make_config(airspace={"ceiling_altitude": 80.0})
    with pytest.raises(ValueError, match=r"airspace\.obstacle_margin"):
        make_config(airspace={"obstacle_margin": -1.0})
    with pytest.raises(TypeError, match=r"airspace\.ground"):
        make_config(airspace={"ground": 0.0})


def test_deprecated_obs_names_still_read():
    s = sample_scenario(np.random.default_rng(0), make_config())
    with pytest.warns(DeprecationWarning, match="obstacle_pos"):
        np.testing.assert_array_equal(s.obs_pos, s.obstacle_pos)
