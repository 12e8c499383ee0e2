"""The batched world: determinism, batch invariance, per-env reset, bounds, extremes."""

import operator

import numpy as np
import pytest
from conftest import HANG_GUARD_S

from uasep_env import World, make_config
from uasep_env.config import SCENARIOS

STATE = ("uav_pos", "uav_vel", "est_pos", "est_vel", "obstacle_est_pos", "pred_center", "time")


def _actions(rng, e, n, scale=2.0):
    return rng.uniform(-scale, scale, size=(e, n, 3))


def _run(world, steps, seed_actions=0):
    rng = np.random.default_rng(seed_actions)
    traj = []
    for _ in range(steps):
        world.step(_actions(rng, world.n_envs, world.n_uavs))
        traj.append({k: getattr(world, k).copy() for k in STATE})
        traj[-1]["obs_pos"] = world.obstacles.pos.copy()
    return traj


@pytest.mark.parametrize("scenario", ["paper", "random", "multi_obstacle"])
def test_same_seed_bit_identical(scenario):
    cfg = make_config(scenario=scenario, n_obstacles=2)
    a, b = World(cfg, 3), World(cfg, 3)
    a.reset(seed=7)
    b.reset(seed=7)
    for sa, sb in zip(_run(a, 300), _run(b, 300), strict=True):
        for k in sa:
            assert np.array_equal(sa[k], sb[k]), k


def test_different_seed_differs():
    cfg = make_config(scenario="random")
    a, b = World(cfg, 1), World(cfg, 1)
    a.reset(seed=1)
    b.reset(seed=2)
    assert not np.array_equal(a.uav_pos, b.uav_pos)


def test_batch_gives_same_per_env_result_as_alone():
    cfg = make_config(scenario="random", n_obstacles=2, decision_interval=2)
    e = 5
    batch = World(cfg, e)
    batch.reset(seed=100)
    rng = np.random.default_rng(3)
    acts = [_actions(rng, e, cfg.n_uavs) for _ in range(150)]
    hist = []
    for a in acts:
        batch.step(a)
        hist.append({k: getattr(batch, k).copy() for k in STATE})
    for i in range(e):
        alone = World(cfg, 1)
        alone.reset(seed=100 + i)
        for a, h in zip(acts, hist, strict=True):
            alone.step(a[i : i + 1])
            for k in STATE:
                assert np.array_equal(getattr(alone, k)[0], h[k][i]), (i, k)


def test_masked_reset_leaves_other_envs_untouched_and_matches_fresh_env():
    cfg = make_config(scenario="crossing")
    w = World(cfg, 3)
    w.reset(seed=[10, 11, 12])
    rng = np.random.default_rng(0)
    for _ in range(20):
        w.step(_actions(rng, 3, cfg.n_uavs))
    before = w.uav_pos.copy()
    w.reset(seed=[None, 99, None], mask=np.array([False, True, False]))
    np.testing.assert_array_equal(w.uav_pos[[0, 2]], before[[0, 2]])
    fresh = World(cfg, 1)
    fresh.reset(seed=99)
    np.testing.assert_array_equal(w.uav_pos[1], fresh.uav_pos[0])
    np.testing.assert_array_equal(w.est_pos[1], fresh.est_pos[0])
    assert w.time[1] == 0.0 and w.time[0] > 0.0


def test_inactive_envs_do_not_move_or_consume_randomness():
    cfg = make_config(scenario="random")
    w, ref = World(cfg, 2), World(cfg, 2)
    w.reset(seed=5)
    ref.reset(seed=5)
    zero = np.zeros((2, cfg.n_uavs, 3))
    frozen_pos = None
    for k in range(10):
        w.step(zero, active=np.array([True, k >= 5]))
        if k == 4:
            frozen_pos = w.uav_pos[1].copy()
    assert frozen_pos is not None
    for _ in range(5):
        ref.step(zero)
    # Env 1 moved only 5 steps, exactly like 5 unmasked steps of a fresh copy.
    np.testing.assert_array_equal(w.uav_pos[1], ref.uav_pos[1])
    assert w.steps[1] == 5 and w.steps[0] == 10


def test_speed_limit_holds_in_world_under_extreme_actions():
    cfg = make_config(scenario="random", uav={"max_speed": 7.0, "max_accel": 50.0})
    w = World(cfg, 4)
    w.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(200):
        w.step(rng.choice([-1e6, 1e6], size=(4, cfg.n_uavs, 3)))
        assert np.all(np.linalg.norm(w.uav_vel, axis=-1) <= 7.0 * (1 + 1e-12))
        assert np.all(np.isfinite(w.uav_pos)) and np.all(np.isfinite(w.est_pos))


def test_zero_noise_estimates_are_exact():
    cfg = make_config(noise=False)
    w = World(cfg, 2)
    w.reset(seed=0)
    _run(w, 50)
    np.testing.assert_allclose(w.est_pos, w.uav_pos, atol=1e-9)
    np.testing.assert_allclose(w.obstacle_est_pos, w.obstacles.pos, atol=1e-9)


def test_noise_makes_estimates_differ_and_kalman_helps():
    cfg = make_config(noise={"position_std": 2.0, "velocity_std": 0.3})
    raw = make_config(cfg, prediction={"kalman": False})
    errs = {}
    for name, c in (("kf", cfg), ("raw", raw)):
        w = World(c, 8)
        w.reset(seed=3)
        e = []
        rng = np.random.default_rng(0)
        for _ in range(200):
            w.step(_actions(rng, 8, c.n_uavs, 0.5))
            e.append(np.linalg.norm(w.est_pos - w.uav_pos, axis=-1).mean())
        errs[name] = np.mean(e[20:])
    assert errs["kf"] < 0.7 * errs["raw"], errs


def test_true_obstacle_inside_predicted_ellipsoid_noise_free():
    # The prediction is made from the estimate; with no noise the obstacle's position over
    # the horizon must stay inside the ellipsoid predicted at the start (swept set).
    cfg = make_config(scenario="random", noise=False, n_obstacles=3)
    w = World(cfg, 16)
    w.reset(seed=11)
    zero = np.zeros((16, cfg.n_uavs, 3))
    for _ in range(5):
        w.step(zero)
    centers, axes, heading = w.pred_center.copy(), w.pred_axes.copy(), w.pred_heading.copy()
    from uasep_env.reachable import distance_to_ellipsoid

    horizon_steps = int(cfg.prediction.horizon / cfg.step_duration)
    for _ in range(horizon_steps):
        w.step(zero)
        d = distance_to_ellipsoid(w.obstacles.pos, centers, axes, heading)
        assert np.all(d <= 1e-6), d.max()


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_every_scenario_runs_and_stays_finite(scenario):
    n = 8 if scenario == "large_formation" else 3
    cfg = make_config(scenario=scenario, n_uavs=n, n_obstacles=2)
    w = World(cfg, 2)
    w.reset(seed=1)
    _run(w, 30)
    assert np.all(np.isfinite(w.uav_pos)) and np.all(np.isfinite(w.pred_center))
    assert np.all(w.pred_axes > 0)


def test_step_validation_errors():
    w = World(make_config(), 2)
    with pytest.raises(RuntimeError, match="before"):
        w.step(np.zeros((2, 3, 3)))
    w.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 3, 3\)"):
        w.step(np.zeros((2, 3)))
    bad = np.zeros((2, 3, 3))
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match=r"\[\[1, 2, 0\]\]"):
        w.step(bad)
    with pytest.raises(ValueError, match="mask"):
        w.reset(mask=np.array([True]))
    with pytest.raises(ValueError, match="expected 2 seeds"):
        w.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="n_envs"):
        World(make_config(), 0)


def test_envs_out_of_noise_lockstep_still_match_fresh_envs():
    """After a masked reset the envs read their noise blocks at different offsets."""
    cfg = make_config(scenario="random")
    w = World(cfg, 3, noise_block=16)
    w.reset(seed=[1, 2, 3])
    rng = np.random.default_rng(0)
    for _ in range(5):
        w.step(_actions(rng, 3, cfg.n_uavs))
    w.reset(seed=[None, 42, None], mask=np.array([False, True, False]))
    fresh = World(cfg, 1, noise_block=16)
    fresh.reset(seed=42)
    assert len(set(w._noise.buf_pos.tolist())) > 1  # the gather path of NoiseStreams.draw
    for _ in range(40):  # crosses several block refills
        a = _actions(rng, 3, cfg.n_uavs)
        w.step(a)
        fresh.step(a[1:2])
        for k in STATE:
            np.testing.assert_array_equal(getattr(w, k)[1], getattr(fresh, k)[0], err_msg=k)


def test_planned_state_follows_time_and_is_read_only():
    cfg = make_config(scenario="random")
    w = World(cfg, 4)
    w.reset(seed=0)
    rng = np.random.default_rng(1)
    for k in range(30):
        w.step(_actions(rng, 4, cfg.n_uavs), active=np.array([True, True, k < 10, True]))
        if k == 20:
            w.reset(mask=np.array([False, True, False, False]))
        pos, vel = w.plan.uav_positions(w.time, w.slots)
        np.testing.assert_array_equal(w.planned()[0], pos)
        np.testing.assert_array_equal(w.planned()[1], vel)
        np.testing.assert_array_equal(w.plan_center, w.plan.center(w.time)[0])
    kept = w.planned()[0]
    snapshot = kept.copy()
    with pytest.raises(ValueError, match="read-only"):
        kept[0, 0, 0] = 1.0
    w.step(_actions(rng, 4, cfg.n_uavs))
    np.testing.assert_array_equal(kept, snapshot)  # a later step does not rewrite it


def test_kernel_input_views_stay_read_only_views_of_the_state():
    """The views made once (World.frozen_inputs, PlannedTrajectory.frozen) show the state.

    They hold only while the state arrays are written in place: a step, a full reset or a
    partial one that put a new array in an attribute would leave a view of the old one.
    """
    cfg = make_config(scenario="random", n_obstacles=2)
    w = World(cfg, 4)
    w.reset(seed=0)
    views, plan = w.frozen_inputs(), w.plan.frozen()
    rng = np.random.default_rng(2)
    for k in range(6):
        w.step(_actions(rng, 4, cfg.n_uavs))
        if k % 2:
            w.reset(mask=np.array([k == 1, True, False, k == 5]))
        if k == 4:
            w.reset(seed=9)
        assert w.frozen_inputs() is views and w.plan.frozen() is plan
        pairs = [(getattr(plan, n), getattr(w.plan, n), n) for n in plan._ARRAYS]
        pairs += [(view, operator.attrgetter(n)(w), n) for n, view in views.items()]
        for view, state, name in pairs:
            assert not view.flags.writeable, name
            assert np.shares_memory(view, state) and view.shape == state.shape, name


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_env_steps_as_the_original(how):
    """A copy makes its own kernel views: copied ones would be arrays of their own, stale."""
    import copy
    import pickle

    import uasep_env

    env = uasep_env.parallel_env(scenario="random")
    env.reset(seed=0)
    acts = {a: np.full(3, 0.3, np.float32) for a in env.agents}
    for _ in range(5):
        env.step(acts)
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    for k in range(40):
        if k == 20:  # a new plan, written into the plan's arrays
            env.reset(seed=1)
            twin.reset(seed=1)
        obs, rewards, *_ = env.step(acts)
        twin_obs, twin_rewards, *_ = twin.step(acts)
        assert rewards == twin_rewards
        for agent, o in obs.items():
            np.testing.assert_array_equal(twin_obs[agent], o)


def test_noise_drawn_on_several_threads_is_bit_identical(monkeypatch):
    """Large batches refill their noise on a thread pool: the same numbers as one thread."""
    import uasep_env.sim.noise as noise_mod

    def run(chunk):
        monkeypatch.setattr(noise_mod, "REFILL_CHUNK", chunk)
        w = World(make_config(scenario="random", n_obstacles=2), 9, noise_block=8)
        w.reset(seed=4)
        return _run(w, 30)

    calls = []
    real = noise_mod._run_chunked

    def spy(fn, envs):
        calls.append(len(envs))
        real(fn, envs)

    monkeypatch.setattr(noise_mod, "_run_chunked", spy)
    serial = run(10**9)
    threaded = run(2)
    assert max(calls) == 9 and len(calls) >= 4  # several refills of the whole batch
    for s, t in zip(serial, threaded, strict=True):
        for k in s:
            np.testing.assert_array_equal(s[k], t[k], err_msg=k)


def _threaded_rollout(_: int = 0) -> np.ndarray:
    w = World(make_config(scenario="random"), 8, noise_block=4)
    w.reset(seed=6)
    return np.stack([t["est_pos"] for t in _run(w, 10)])


def test_noise_threads_work_in_a_forked_child(monkeypatch):
    """A child forked after the parent used the noise thread pool makes its own pool."""
    import multiprocessing

    import uasep_env.sim.noise as noise_mod

    monkeypatch.setattr(noise_mod, "REFILL_CHUNK", 2)
    if (multiprocessing.cpu_count() or 1) < 2:
        pytest.skip("one core: the noise is drawn on one thread")
    parent = _threaded_rollout()
    assert noise_mod._pool  # the parent's pool exists when the child is forked
    with multiprocessing.get_context("fork").Pool(1) as pool:
        child = pool.apply_async(_threaded_rollout).get(timeout=HANG_GUARD_S)
    np.testing.assert_array_equal(child, parent)
