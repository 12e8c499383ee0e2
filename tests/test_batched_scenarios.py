"""Batched scenarios (``uasep_env.scenarios.batched``): the generator's episodes, bit for bit."""

import itertools

import numpy as np
import pytest

from uasep_env import World
from uasep_env.config import make_config
from uasep_env.scenarios import FAMILIES, RANDOM_MIX, batched, sample_scenario
from uasep_env.scenarios.batched import sample_batch
from uasep_env.scenarios.spec import ScenarioBatch

BATCHED = [name for name, f in FAMILIES.items() if f.draws is not None]
# The formation's size and the obstacle slots, a long episode (the plan flies on past the
# 200 s timeline) and a narrow airspace (obstacle starts and climbs clamped).
N_UAVS = (2, 3, 8)
N_OBSTACLES = (0, 1, 3)
SHAPES = {
    "default": {},
    "long": {"episode_duration": 450.0},
    "narrow": {"airspace": {"obstacle_margin": 85.0, "ceiling_altitude": 112.0}},
}
SEEDS_PER_CONFIG = 12  # 27 configs: over 300 seeds per family


def _reference(seeds: range, cfg: object) -> tuple[ScenarioBatch, list]:
    rngs = [np.random.default_rng(s) for s in seeds]
    batch = ScenarioBatch.from_specs([sample_scenario(rng, cfg) for rng in rngs])
    return batch, [rng.bit_generator.state for rng in rngs]


def _assert_same_batch(ref: ScenarioBatch, got: ScenarioBatch, what: str) -> None:
    assert got.families == ref.families, what
    for name, value in vars(ref).items():
        if name in ("families", "specs", "plan", "plan_offsets"):  # (the world checks these)
            continue
        np.testing.assert_array_equal(
            getattr(got, name), value, err_msg=f"{what}: {name}", strict=True
        )


def test_the_drawn_families_have_a_batched_form():
    assert {"random", *RANDOM_MIX.names, "large_formation"} <= set(BATCHED)
    for name in RANDOM_MIX.names:  # random's batched form delegates to its members'
        assert FAMILIES[name].draws is not None, name


@pytest.mark.parametrize("family", BATCHED)
def test_batched_scenarios_equal_the_generator_bit_for_bit(family):
    _assert_batched_equal_the_generator(family)


@pytest.mark.parametrize("family", ["random", "large_formation"])
def test_the_slow_uniform_path_equals_the_generator_too(family, monkeypatch):
    """A numpy whose uniform rounds ``low + span * x`` fused draws with ``rng.uniform``."""
    monkeypatch.setattr(batched, "_uniforms", batched._uniforms_by_call)
    _assert_batched_equal_the_generator(family)


def test_the_uniform_formula_check_sees_a_rounding_difference(monkeypatch):
    if not batched._formula_is_exact():
        pytest.skip("this numpy's uniform rounds otherwise: the slow path is in use")
    nudged = batched._uniforms_by_formula

    def fused_like(rng, low, high, span):  # what a fused multiply-add changes: the last bit
        x = nudged(rng, low, high, span)
        return np.where(np.arange(len(x)) % 3 == 0, np.nextafter(x, np.inf), x)

    monkeypatch.setattr(batched, "_uniforms_by_formula", fused_like)
    assert not batched._formula_is_exact()


def _assert_batched_equal_the_generator(family: str) -> None:
    for i, (n, m, shape) in enumerate(itertools.product(N_UAVS, N_OBSTACLES, SHAPES)):
        cfg = make_config(scenario=family, n_uavs=n, n_obstacles=m, **SHAPES[shape])
        seeds = range(1000 * i, 1000 * i + SEEDS_PER_CONFIG)
        ref, states = _reference(seeds, cfg)
        rngs = [np.random.default_rng(s) for s in seeds]
        got = sample_batch(rngs, cfg)
        what = f"{family} n_uavs={n} n_obstacles={m} {shape}"
        _assert_same_batch(ref, got, what)
        # Each generator is left where the per-episode generator leaves it.
        assert [rng.bit_generator.state for rng in rngs] == states, what


def test_the_narrow_airspace_clamps_the_obstacle_starts():
    """The narrow config above does exercise the clamps (else it would test nothing)."""
    narrow = make_config(scenario="climbing", n_obstacles=3, **SHAPES["narrow"])
    wide = make_config(scenario="climbing", n_obstacles=3)
    a, _ = _reference(range(50), narrow)
    b, _ = _reference(range(50), wide)
    floor, ceiling = 85.0, 112.0
    alts = -a.obstacle_pos[..., 2]
    assert np.any(alts == floor) or np.any(alts == ceiling)
    assert not np.array_equal(a.obstacle_climb_rate, b.obstacle_climb_rate)


@pytest.mark.parametrize("family", ["paper", "collision_head_on", "real_traffic"])
def test_families_without_a_batched_form_are_drawn_one_at_a_time(family):
    cfg = make_config(scenario=family)
    ref, states = _reference(range(5), cfg)
    rngs = [np.random.default_rng(s) for s in range(5)]
    got = sample_batch(rngs, cfg)
    _assert_same_batch(ref, got, family)
    assert [rng.bit_generator.state for rng in rngs] == states
    assert got.specs is not None  # kept: a replayed track travels on its spec


def _per_episode_batches(rngs: list, config: object) -> ScenarioBatch:
    return ScenarioBatch.from_specs([sample_scenario(rng, config) for rng in rngs])


def test_vector_env_episodes_with_batched_resets_equal_per_episode_resets(monkeypatch):
    """Random actions end many episodes; the batched resets give the same episodes."""
    import uasep_env.sim.world as world_module
    from uasep_env.envs.vector import FormationVectorEnv

    def run() -> list:
        # UAVs lost 30 m off the plan: random actions end a few episodes a step.
        vec = FormationVectorEnv(64, scenario="random", n_obstacles=2, uav={"lost_distance": 30.0})
        rng = np.random.default_rng(5)
        out = [vec.reset(seed=11)[0]]
        ends = 0
        for _ in range(70):
            act = rng.uniform(-1.0, 1.0, vec.action_space.shape).astype(np.float32)
            obs, rew, term, trunc, _ = vec.step(act)
            ends += int((term | trunc).sum())
            out += [obs, rew, term, trunc]
        w = vec.core.world
        out += [w.uav_pos, w.obstacles.pos, w.pred_axes, w.pred_center, list(w.families)]
        out += [w.plan.waypoints, w.plan.cum, w.plan.length, w.plan.direction]
        out += [w.plan.cruise_speed, w._plan_offsets, w.plan_pos, w.plan_vel]
        assert len(set(w.families)) >= 4, w.families  # the random mix: rows of each family
        assert ends > 40, ends  # many resets, several rows at once
        return out

    batched = run()
    monkeypatch.setattr(world_module, "sample_batch", _per_episode_batches)
    reference = run()
    for k, (a, b) in enumerate(zip(batched, reference, strict=True)):
        if isinstance(a, list):
            assert a == b
        else:
            np.testing.assert_array_equal(a, b, err_msg=str(k), strict=True)


def test_world_partial_reset_with_seeds_equals_per_episode_scenarios():
    cfg = make_config(scenario="random", n_obstacles=3, n_uavs=4)
    world = World(cfg, 40, noise_block=8)
    world.reset(seed=7)
    mask = np.zeros(40, dtype=bool)
    mask[[1, 2, 3, 17, 30, 39]] = True
    world.reset(seed=[500 + i if m else None for i, m in enumerate(mask)], mask=mask)
    for i in np.flatnonzero(mask):
        s = sample_scenario(np.random.default_rng(500 + int(i)), cfg)
        assert world.families[i] == s.family
        np.testing.assert_array_equal(world.uav_pos[i], s.uav_pos)
        np.testing.assert_array_equal(world.obstacles.pos[i], s.obstacle_pos)
        np.testing.assert_array_equal(world.obstacles.hold_until[i], s.obstacle_hold_until)
        np.testing.assert_array_equal(world.plan.waypoints[i], s.waypoints)
