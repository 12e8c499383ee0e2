"""Each named reward term reacts as documented in uasep_env.interface.rewards."""

import itertools

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.config import RewardWeights
from uasep_env.envs.core import EnvCore
from uasep_env.interface.rewards import REWARD_TERMS, compute_rewards, term_bounds


@pytest.fixture
def core():
    # The enclosing ellipsoid: the tests below walk along its lateral semi-axis.
    c = EnvCore(
        make_config(scenario="paper", noise=False, prediction={"fit": "enclosing"}), n_envs=1
    )
    c.reset(seed=0)
    c.step(np.zeros((1, 3, 3)))
    return c


def _terms_with_uav2_at(core, pos, cmd=None, prev=None):
    w = core.world
    w.uav_pos[0, 2] = pos
    if cmd is not None:
        w.accel_cmd[0, 2] = cmd
    if prev is not None:
        w.prev_accel_cmd[0, 2] = prev
    w._start_safety(np.arange(1))
    _, terms = compute_rewards(w, core.config.reward)
    return {k: v[0, 2] for k, v in terms.items()}


def test_moving_into_reachable_region_lowers_region_term(core):
    w = core.world
    center = w.pred_center[0, 0]
    axes = w.pred_axes[0, 0]
    values = []
    # From well outside, through the surface, to the centre of the ellipsoid (laterally).
    lateral = np.array([-np.sin(w.pred_heading[0, 0]), np.cos(w.pred_heading[0, 0]), 0.0])
    for k in np.linspace(3.0, 0.0, 13):
        values.append(
            _terms_with_uav2_at(core, center + lateral * axes[1] * k)["separation_region"]
        )
    assert values[0] == 0.0
    assert all(b <= a for a, b in itertools.pairwise(values))
    assert values[-1] < values[6] < 0.0


def test_obstacle_and_inner_separation_terms(core):
    w = core.world
    obs = w.obstacles.pos[0, 0]
    far = _terms_with_uav2_at(core, obs + np.array([0.0, 0.0, -200.0]))
    near = _terms_with_uav2_at(core, obs + np.array([0.0, 0.0, -5.0]))
    assert far["separation_obstacle"] == 0.0 and near["separation_obstacle"] < 0.0
    assert near["collision"] == 0.0
    hit = _terms_with_uav2_at(core, obs + np.array([0.0, 0.0, -1.0]))
    assert hit["collision"] == -core.config.max_steps
    other = w.uav_pos[0, 0].copy()
    close = _terms_with_uav2_at(core, other + np.array([0.0, 4.0, 0.0]))
    closer = _terms_with_uav2_at(core, other + np.array([0.0, 3.5, 0.0]))
    assert closer["separation_inner"] < close["separation_inner"] < 0.0


def test_deviation_control_smoothness_terms(core):
    w = core.world
    plan, _ = w.planned()
    on = _terms_with_uav2_at(core, plan[0, 2], cmd=np.zeros(3), prev=np.zeros(3))
    off = _terms_with_uav2_at(core, plan[0, 2] + np.array([0, 0, 20.0]))
    assert on["deviation"] == pytest.approx(0.0, abs=1e-12)
    assert off["deviation"] == pytest.approx(-0.5)  # 20 m off: half the cap
    far = _terms_with_uav2_at(core, plan[0, 2] + np.array([0, 0, 180.0]))
    assert far["deviation"] == pytest.approx(-0.9)
    assert on["control"] == 0.0 and on["smoothness"] == 0.0
    a = core.config.uav.max_accel
    t = _terms_with_uav2_at(core, plan[0, 2], cmd=np.array([a, 0, 0]), prev=np.array([-a, 0, 0]))
    assert t["control"] == pytest.approx(-1 / 3) and t["smoothness"] == pytest.approx(-4 / 3)


def test_weights_and_sharing_combine_terms(core):
    w = core.world
    w.uav_pos[0, 2] += np.array([0.0, 0.0, 30.0])  # only uav_2 deviates much
    zeros = dict.fromkeys(REWARD_TERMS, 0.0)
    only_dev = RewardWeights(**{**zeros, "deviation": 1.0})
    own, terms = compute_rewards(w, only_dev)
    np.testing.assert_allclose(own, terms["deviation"])
    shared = RewardWeights(**{**zeros, "deviation": 1.0, "shared": 1.0})
    team, _ = compute_rewards(w, shared)
    np.testing.assert_allclose(team, np.broadcast_to(terms["deviation"].mean(), (1, 3)))


@pytest.mark.parametrize("n", [1, 2, 3, 7, 8, 12])
def test_team_mean_is_numpy_mean_bit_for_bit(n):
    from uasep_env.interface.rewards import team_mean

    x = (
        np.random.default_rng(n).normal(0, 1, size=(5, 300, n))
        * 10.0 ** np.arange(-3, 2)[:, None, None]
    )
    got = team_mean(x)
    assert got.shape == (5, 300)
    np.testing.assert_array_equal(got, x.mean(axis=-1))


def _weights_max_penalty(w: RewardWeights) -> float:
    """The most a step alive can lose: every per-step penalty at its bound (the term table)."""
    from uasep_env.interface.rewards import TERMS

    return sum(-t.low * getattr(w, t.name) for t in TERMS if t.high <= 0 and not t.per_episode)


def test_default_step_reward_is_in_zero_one():
    # Worst case of every penalty at once (smoothness reaches -4 with a full reversal)
    # stays within the alive bonus, so no step alive is worth less than ending the episode.
    w = RewardWeights()
    assert w.progress == 1.0
    assert _weights_max_penalty(w) == pytest.approx(1.0)
    # And over real episodes with random actions (many collide, many drift far off).
    core = EnvCore(make_config(scenario="random", episode_duration=60.0), n_envs=16)
    core.reset(seed=3)
    rng = np.random.default_rng(0)
    alive = np.ones(16, dtype=bool)
    bounds = term_bounds(core.config.max_steps)
    for _ in range(300):
        res = core.step(rng.uniform(-1, 1, size=(16, 3, 3)), active=alive)
        for name, (low, high) in bounds.items():  # every term within its table bounds
            t = res.terms[name][alive]
            assert (t >= low).all() and (t <= high).all(), name
        no_collision = res.terms["collision"] == 0.0
        r = res.rewards[alive][no_collision[alive]]
        assert (r >= 0.0).all() and (r <= 1.0).all()
        alive &= ~(res.terminated | res.truncated)
        if not alive.any():
            break


def _play(cfg, seed, crash_at=None):
    """APF episode return (mean over agents); with ``crash_at``, UAV 1 is put onto UAV 0."""
    from uasep_env.policies import APF

    core = EnvCore(cfg, n_envs=1)
    obs = core.reset(seed=seed)
    apf = APF(cfg)
    total, k = 0.0, 0
    while True:
        k += 1
        if crash_at is not None and k == crash_at:
            w = core.world
            w.uav_pos[0, 1] = w.uav_pos[0, 0] + np.array([0.0, 1.0, 0.0])
            w.uav_vel[0, 1] = w.uav_vel[0, 0]
        res = core.step(apf(obs))
        obs = res.obs
        total += float(res.rewards.mean())
        if res.terminated[0] or res.truncated[0]:
            return total, bool(res.terminated[0]), k


@pytest.mark.parametrize("scenario", ["paper", "crossing"])
def test_collision_never_pays(scenario):
    """An episode ending in a collision returns less than the collision-free one, at any step."""
    cfg = make_config(scenario=scenario, episode_duration=60.0)
    safe, terminated, steps = _play(cfg, seed=7)
    assert not terminated and steps == cfg.max_steps
    assert safe > 0.0
    for crash_at in (1, 2, steps // 3, steps // 2, steps - 5, steps - 1, steps):
        crashed, terminated, k = _play(cfg, seed=7, crash_at=crash_at)
        assert terminated and k == crash_at
        assert crashed < 0.0 < safe, (crash_at, crashed, safe)


def test_a_lost_uav_ends_the_episode():
    cfg = make_config(scenario="paper", episode_duration=60.0)
    core = EnvCore(cfg, n_envs=2)
    core.reset(seed=1)
    res = core.step(np.zeros((2, 3, 3)))
    assert not res.terminated.any() and not res.safety["lost"].any()
    w = core.world
    w.uav_pos[1, 2] = w.plan_pos[1, 2] + np.array([0.0, cfg.uav.lost_distance + 20.0, 0.0])
    res = core.step(np.zeros((2, 3, 3)))
    assert list(res.terminated) == [False, True]
    assert res.safety["lost"][1].tolist() == [False, False, True]
    # Being lost is not a collision: no collision penalty, only the rest of the episode lost.
    assert (res.terms["collision"] == 0.0).all() and (res.rewards[1] >= 0.0).all()


def test_lost_distance_is_validated():
    with pytest.raises(ValueError, match=r"uav\.lost_distance"):
        make_config(uav={"lost_distance": 5.0})


def test_cores_of_different_configs_stepped_in_turn_keep_their_own_constants():
    """The outcome's constants are looked up once per config: two cores in turn, each its own.

    The second core weighs the terms otherwise and counts a UAV lost sooner; each step of
    each core must give the rewards of its own weights (``compute_rewards``, which looks
    them up on its own) and the lost flags of its own distance.
    """
    plain = make_config(scenario="random", episode_duration=30.0)
    other = make_config(
        scenario="random",
        episode_duration=30.0,
        reward={"deviation": 3.0, "control": 0.5},
        uav={"lost_distance": 40.0},
    )
    actions = np.random.default_rng(3).uniform(-1, 1, size=(40, 2, 3, 3))
    actions[:, :, 0] = 1.0  # one UAV flies off its plan
    cores = [EnvCore(plain, n_envs=2), EnvCore(other, n_envs=2)]
    lost = [0, 0]
    for core in cores:
        core.reset(seed=5)
    for a in actions:
        for k, core in enumerate(cores):
            got = core.step(a)
            w = core.world
            np.testing.assert_array_equal(got.rewards, compute_rewards(w, core.config.reward)[0])
            off = np.linalg.norm(w.uav_pos - w.plan_pos, axis=-1)
            np.testing.assert_array_equal(got.safety["lost"], off > core.config.uav.lost_distance)
            lost[k] += int(got.safety["lost"].any())
    assert lost[1] > lost[0]  # the other lost distance shows


def test_the_deviation_scale_keeps_the_slope_far_from_the_plan(core):
    """``reward.deviation_scale``: ``-d / (d + s)``, the core's step and compute_rewards alike."""
    w = core.world
    plan, _ = w.planned()
    wide = make_config(scenario="paper", noise=False, prediction={"fit": "enclosing"},
                       reward={"deviation_scale": 200.0})  # fmt: skip
    w.uav_pos[0, 2] = plan[0, 2] + np.array([0, 0, 100.0])
    w._start_safety(np.arange(1))
    default = compute_rewards(w, core.config.reward)[1]["deviation"][0, 2]
    sloped = compute_rewards(w, wide.reward)[1]["deviation"][0, 2]
    assert default == pytest.approx(-100 / 120) and sloped == pytest.approx(-100 / 300)
    configs = (make_config(scenario="random"),
               make_config(scenario="random", reward={"deviation_scale": 200.0}))  # fmt: skip
    cores = [EnvCore(c, n_envs=2) for c in configs]
    a = np.full((2, 3, 3), 0.7)
    for c in cores:
        c.reset(seed=2)
    for _ in range(30):
        got = [c.step(a) for c in cores]
    for c, g in zip(cores, got, strict=True):
        dev = np.linalg.norm(c.world.uav_pos - c.world.plan_pos, axis=-1)
        s = c.config.reward.deviation_scale
        np.testing.assert_allclose(g.terms["deviation"], -dev / (dev + s), rtol=1e-12)
    with pytest.raises(ValueError, match=r"reward\.deviation_scale"):
        make_config(reward={"deviation_scale": 0.0})
