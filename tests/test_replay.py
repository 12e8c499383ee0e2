"""Recorded tracks as obstacles: the replay model and the ``real_traffic`` family (issue 20)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT

import uasep_env
from uasep_env import make_config, real_traffic
from uasep_env.scenarios import RANDOM_MIX, REAL_TRAFFIC_TEST_SEEDS, sample_scenario
from uasep_env.scenarios.real_traffic import (
    MEET_TOLERANCE_S,
    MISS_DISTANCE_RANGE_M,
    REAL_TRAFFIC_BANK,
    ReplaySpec,
)
from uasep_env.sim.replay import track_velocities
from uasep_env.sim.world import World

REPLAY = {"scenario": "real_traffic", "obstacle": {"model": "replay"}}


def _cfg(**kw):
    return make_config({**REPLAY, **kw})


def _spec(seed, cfg):
    return sample_scenario(np.random.default_rng(seed), cfg)


def test_the_replayed_obstacle_flies_its_placed_track_exactly():
    cfg = _cfg(episode_duration=30.0, n_obstacles=2)
    seeds = [11, 12, 13]
    w = World(cfg, n_envs=3)
    w.reset(seed=seeds)
    specs = [_spec(s, cfg) for s in seeds]
    vel_err = 0.0
    for k in range(1, 151):
        w.step(np.zeros((3, 3, 3)))
        for i, s in enumerate(specs):
            np.testing.assert_array_equal(w.obstacles.pos[i], s.obstacle_track[:, k])
            if k < 150:
                central = (s.obstacle_track[:, k + 1] - s.obstacle_track[:, k - 1]) / (2 * cfg.dt)
                vel_err = max(vel_err, np.abs(w.obstacle_velocities()[i] - central).max())
    assert vel_err < 1e-9  # the sensed velocity is the track's (heading/speed/climb written)


def test_the_placed_track_is_the_recorded_one_interpolated_rotated_and_translated():
    cfg = _cfg(episode_duration=40.0, obstacle={"model": "replay", "replay_speed_scale": 0.5})
    tracks = real_traffic.load().tracks
    for seed in range(5):
        spec = _spec(seed, cfg)
        assert isinstance(spec, ReplaySpec)
        tr = tracks[int(spec.obstacle_track_index[0])]
        t = spec.obstacle_track_start[0] + cfg.dt * np.arange(spec.obstacle_track.shape[1])
        rec = np.stack([np.interp(t, tr.times, tr.positions[:, ax]) for ax in range(3)], -1)
        rec = (rec - rec[0]) * 0.5
        th = spec.obstacle_rotation[0]
        c, s = np.cos(th), np.sin(th)
        x, y = rec[:, 0], rec[:, 1]
        rot = np.stack([c * x - s * y, s * x + c * y, rec[:, 2]], -1)
        placed = spec.obstacle_track[0] - spec.obstacle_track[0, 0]
        np.testing.assert_allclose(placed, rot, atol=1e-6)
        np.testing.assert_array_equal(spec.obstacle_pos[0], spec.obstacle_track[0, 0])


@pytest.mark.parametrize("scale", [1.0, 0.2])
def test_closest_approach_to_the_target_plan_is_at_the_drawn_time_and_distance(scale):
    cfg = _cfg(episode_duration=150.0, noise=False,
               obstacle={"model": "replay", "replay_speed_scale": scale})  # fmt: skip
    seeds = [21, 22, 23, 24]
    w = World(cfg, n_envs=len(seeds))
    w.reset(seed=seeds)
    specs = [_spec(s, cfg) for s in seeds]
    rows = np.arange(len(seeds))
    who = np.array([s.obstacle_target[0] for s in specs])
    dist, times = [], []
    for _ in range(cfg.max_steps):
        w.step(np.zeros((len(seeds), 3, 3)))
        dist.append(np.linalg.norm(w.obstacles.pos[:, 0] - w.plan_pos[rows, who], axis=-1))
        times.append(w.time.copy())
    dist, times = np.array(dist), np.array(times)
    for i, s in enumerate(specs):
        meet, miss = s.obstacle_meet_time[0], s.obstacle_miss_distance[0]
        assert MISS_DISTANCE_RANGE_M[0] <= miss <= MISS_DISTANCE_RANGE_M[1]
        if meet > times[-1, i]:
            continue
        j = int(np.argmin(dist[:, i]))
        assert abs(times[j, i] - meet) <= MEET_TOLERANCE_S
        assert miss - 0.5 <= dist[j, i] <= miss + 1e-6
        at = int(np.argmin(np.abs(times[:, i] - meet)))
        assert dist[at, i] == pytest.approx(miss, abs=1e-6)


def _run(env_factory, seed, steps=30):
    env = env_factory()
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        if isinstance(obs, dict):  # PettingZoo: one action per agent
            act = {a: np.zeros(env.action_space(a).shape) for a in env.agents}
        else:
            act = np.zeros(env.action_space.shape)
        obs, *_ = env.step(act)
        out.append(obs)
    return out


def _same(a, b):
    for x, y in zip(a, b, strict=True):
        if isinstance(x, dict):
            assert x.keys() == y.keys()
            for k in x:
                np.testing.assert_array_equal(x[k], y[k])
        else:
            np.testing.assert_array_equal(x, y)


def test_same_seed_same_episode_in_the_pettingzoo_and_vector_views():
    pz = lambda: uasep_env.parallel_env(**REPLAY, episode_duration=20.0)  # noqa: E731
    _same(_run(pz, 5), _run(pz, 5))
    from uasep_env.envs.vector import FormationVectorEnv

    vec = lambda: FormationVectorEnv(2, {**REPLAY, "episode_duration": 20.0})  # noqa: E731
    a, b = _run(vec, 5), _run(vec, 5)
    _same(a, b)
    # Environment 1 of the vector env seeded 5 is the single env seeded 6: the same world.
    w1, w2 = World(_cfg(), n_envs=2), World(_cfg(), n_envs=1)
    w1.reset(seed=5)
    w2.reset(seed=6)
    for _ in range(20):
        w1.step(np.zeros((2, 3, 3)))
        w2.step(np.zeros((1, 3, 3)))
    np.testing.assert_array_equal(w1.obstacles.pos[1], w2.obstacles.pos[0])
    np.testing.assert_array_equal(w1.obstacle_est_pos[1], w2.obstacle_est_pos[0])
    assert not np.array_equal(_run(pz, 6)[5]["uav_0"], _run(pz, 5)[5]["uav_0"])


def test_per_env_reset_by_mask_and_frozen_envs():
    cfg = _cfg(episode_duration=30.0)
    w = World(cfg, n_envs=3)
    ref = World(cfg, n_envs=3)
    w.reset(seed=[1, 2, 3])
    ref.reset(seed=[1, 2, 3])
    zeros = np.zeros((3, 3, 3))
    for _ in range(10):
        w.step(zeros)
        ref.step(zeros)
    w.reset(seed=[None, 40, None], mask=np.array([False, True, False]))
    fresh = World(cfg, n_envs=1)
    fresh.reset(seed=40)
    for _ in range(10):
        w.step(zeros)
        ref.step(zeros)
        fresh.step(np.zeros((1, 3, 3)))
    np.testing.assert_array_equal(w.obstacles.pos[[0, 2]], ref.obstacles.pos[[0, 2]])
    np.testing.assert_array_equal(w.obstacles.pos[1], fresh.obstacles.pos[0])
    np.testing.assert_array_equal(w.obstacle_est_vel[1], fresh.obstacle_est_vel[0])
    # A frozen environment (inactive) keeps its replayed obstacle where it was.
    before = w.obstacles.pos.copy()
    w.step(zeros, active=np.array([True, False, True]))
    np.testing.assert_array_equal(w.obstacles.pos[1], before[1])
    w.step(zeros)
    fresh.step(np.zeros((1, 3, 3)))
    np.testing.assert_array_equal(w.obstacles.pos[1], fresh.obstacles.pos[0])


def test_replayed_tracks_stay_in_the_sky():
    for ground in (0.0, 60.0):
        cfg = _cfg(airspace={"ground_altitude": ground}, n_obstacles=2)
        floor = ground + cfg.airspace.obstacle_margin
        for seed in range(20):
            alt = -_spec(seed, cfg).obstacle_track[..., 2]
            assert alt.min() >= floor and alt.max() <= cfg.airspace.ceiling_altitude
    # Past the recorded 200 s (a longer episode): level flight at the last horizontal velocity.
    cfg = _cfg(episode_duration=210.0)
    w = World(cfg, n_envs=1)
    w.reset(seed=3)
    last = _spec(3, cfg).obstacle_track[0, -1]
    for _ in range(cfg.max_steps):
        w.step(np.zeros((1, 3, 3)))
    v = track_velocities(w.replay.pos[0, 0], cfg.dt)[-1]
    np.testing.assert_allclose(w.obstacles.pos[0, 0], last + np.array([v[0], v[1], 0.0]) * 10)
    assert w.obstacle_velocities()[0, 0, 2] == pytest.approx(0.0, abs=1e-12)


def test_training_draws_only_training_flights_and_the_splits_never_meet():
    tracks = real_traffic.load().tracks
    seen = {}
    for split in ("train", "validation", "test"):
        cfg = _cfg(n_obstacles=2, obstacle={"model": "replay", "replay_split": split})
        idx = {int(i) for s in range(40) for i in _spec(s, cfg).obstacle_track_index}
        assert {tracks[i].split for i in idx} == {split}
        seen[split] = {tracks[i].flight for i in idx}
    assert not (seen["train"] & seen["test"]) and not (seen["train"] & seen["validation"])
    assert make_config(REPLAY).obstacle.replay_split == "train"  # the default


def test_the_real_traffic_bank_is_test_flights_and_pinned():
    cfg = make_config(REAL_TRAFFIC_BANK)
    tracks = real_traffic.load().tracks
    assert len(REAL_TRAFFIC_TEST_SEEDS) >= 300
    for seed in list(REAL_TRAFFIC_TEST_SEEDS)[::10]:
        spec = _spec(seed, cfg)
        assert tracks[int(spec.obstacle_track_index[0])].split == "test"
    banks = json.loads((ROOT / "tests" / "data" / "banks.json").read_text())["banks"]
    bank = banks["real_traffic_test"]
    assert {**bank["config"], "scenario": bank["scenario"]} == REAL_TRAFFIC_BANK
    assert bank["seeds"] == [REAL_TRAFFIC_TEST_SEEDS.start, REAL_TRAFFIC_TEST_SEEDS.stop]
    assert len(bank["entries"]) == len(REAL_TRAFFIC_TEST_SEEDS)
    assert "real_traffic" not in RANDOM_MIX.names  # the pinned random banks stay as they were


def test_bad_input_names_the_field_and_value():
    with pytest.raises(ValueError, match=r"obstacle\.replay_speed_scale=3\.0"):
        _cfg(obstacle={"model": "replay", "replay_speed_scale": 3.0})
    with pytest.raises(ValueError, match=r"obstacle\.replay_speed_scale=0\.0"):
        _cfg(obstacle={"model": "replay", "replay_speed_scale": 0.0})
    with pytest.raises(ValueError, match=r"obstacle\.replay_speed_scale=nan"):
        _cfg(obstacle={"model": "replay", "replay_speed_scale": float("nan")})
    with pytest.raises(ValueError, match=r"obstacle\.model='kinematic'"):
        make_config(obstacle={"model": "kinematic"})
    with pytest.raises(ValueError, match=r"obstacle\.replay_split='tests'"):
        _cfg(obstacle={"model": "replay", "replay_split": "tests"})
    with pytest.raises(ValueError, match=r"obstacle\.replay_max_gap=0"):
        _cfg(obstacle={"model": "replay", "replay_max_gap": 0})
    with pytest.raises(ValueError, match=r"obstacle\.model='dubins'.*real_traffic.*'replay'"):
        make_config(scenario="real_traffic", obstacle={"model": "dubins"})
    with pytest.raises(ValueError, match=r"obstacle\.model='replay'.*crossing"):
        make_config(scenario="crossing", obstacle={"model": "replay"})
    # More distinct tracks than the split holds: named at construction, with the count.
    cfg = _cfg(n_obstacles=8, obstacle={"model": "replay", "replay_split": "validation"})
    with pytest.raises(ValueError, match=r"n_obstacles=8.*replay_split='validation' holds \d"):
        World(cfg)
    with pytest.raises(ValueError, match=r"n_obstacles=8"):
        uasep_env.parallel_env(cfg)
    # An airspace no recorded track fits in: a clear error, not an endless loop.
    narrow = _cfg(airspace={"ground_altitude": 75.0, "obstacle_margin": 20.0,
                            "ceiling_altitude": 101.0})  # fmt: skip
    with pytest.raises(ValueError, match=r"airspace\.ceiling_altitude"):
        _spec(0, narrow)


def test_the_obstacle_model_follows_the_scenario_unless_given():
    assert make_config().obstacle.model == "dubins"
    cfg = make_config(scenario="real_traffic")
    assert cfg.obstacle.model == "replay"
    assert cfg.replace(scenario="crossing").obstacle.model == "dubins"
    assert cfg.replace(obstacle={"replay_speed_scale": 0.5}).obstacle.model == "replay"
    assert make_config(cfg.to_dict()) == cfg  # the written config reads back


def test_the_gym_id():
    import gymnasium

    env = gymnasium.make(f"uasep/RealTraffic-v{uasep_env.registration.ENV_VERSION}",
                         episode_duration=10.0)  # fmt: skip
    env.reset(seed=0)
    assert env.unwrapped.config.obstacle.model == "replay"
    env.step(env.action_space.sample())


def test_replay_velocities_are_np_gradient_bit_for_bit():
    # Taken from the positions when needed (not stored): the same floats as np.gradient.
    from uasep_env.sim.replay import ReplayTracks

    rng = np.random.default_rng(3)
    tracks = ReplayTracks(n_envs=2, n_obstacles=3, n_samples=7, dt=0.1)
    tracks.pos[:] = rng.normal(0.0, 300.0, tracks.pos.shape)
    want = track_velocities(tracks.pos, tracks.dt)
    envs, slots = np.arange(2)[:, None], np.arange(3)[None, :]
    for k in range(7):
        got = tracks.velocity(envs, slots, np.full(2, k))
        assert np.array_equal(got, want[:, :, k]), k
    assert not hasattr(tracks, "vel")  # one (E, M, K, 3) array per batch, not two
