"""The cost channel (uasep_env.interface.costs): > 0 exactly on loss of separation, in every
view."""

import numpy as np
import pytest

import uasep_env
from uasep_env import make_config
from uasep_env.config import CostWeights, RewardWeights
from uasep_env.envs.core import EnvCore
from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.vector import FormationVectorEnv
from uasep_env.interface.costs import COST_TERMS, TERMS
from uasep_env.interface.rewards import step_reward_bounds
from uasep_env.metrics import obstacle_distances, pairwise_uav_distances

# Noise off (the geometry below stays as placed); 40 s: the obstacle arrives after ~7 s.
CFG = {"scenario": "paper", "noise": False, "episode_duration": 40.0}


def _collision_course(world, env: int = 0) -> None:
    """Obstacle 0 at UAV 0's altitude, 60 m ahead of it and flying straight at it; UAV 2
    5 m beside UAV 1 (inside the 8 m separation, outside the 3 m collision distance)."""
    w, ob = world, world.obstacles
    vel = w.uav_vel[env, 0].copy()
    vel[2] = 0.0
    d = vel / np.linalg.norm(vel)
    ob.pos[env, 0] = w.uav_pos[env, 0] + 60.0 * d
    ob.heading[env, 0] = np.arctan2(-d[1], -d[0])
    ob.turn_rate[env, 0] = ob.climb_rate[env, 0] = 0.0
    ob.switch_prob[env, 0] = 0.0  # no random manoeuvre
    ob.active[env, 0] = True
    side = np.array([-d[1], d[0], 0.0])
    w.uav_pos[env, 2] = w.uav_pos[env, 1] + 5.0 * side
    w.uav_vel[env, 2] = w.uav_vel[env, 1]


def _losses(world, env: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Each UAV's loss of separation now, from the metrics' own distances (not the env's)."""
    cfg = world.config
    pos = world.uav_pos[env][None]
    d_uav = pairwise_uav_distances(pos)[0].min(axis=-1)
    ob = world.obstacles
    d_obs = obstacle_distances(pos, ob.pos[env][None], ob.active[env][None])[0]
    d_obs = d_obs.min(axis=-1, initial=np.inf)
    return d_uav < cfg.uav.separation_distance, d_obs < cfg.uav.obstacle_separation


def _check(cost, terms, world, env, seen) -> None:
    """``cost > 0`` exactly where a UAV is in loss; the terms are the two losses."""
    los_uav, los_obs = _losses(world, env)
    lost = los_uav | los_obs
    np.testing.assert_array_equal(np.asarray(cost) > 0, lost)
    np.testing.assert_array_equal(terms["separation_uav"], los_uav.astype(float))
    np.testing.assert_array_equal(terms["separation_obstacle"], los_obs.astype(float))
    assert (np.asarray(cost) >= 0).all()
    seen.update(zip(lost.tolist(), los_obs.tolist(), strict=True))


def _assert_both_seen(seen) -> None:
    # Steps with and without a loss, and an obstacle loss (UAV 0 meets the obstacle).
    assert (False, False) in seen and (True, True) in seen and (True, False) in seen


def test_pettingzoo_cost_is_positive_exactly_on_loss():
    env = uasep_env.parallel_env(**CFG)
    env.reset(seed=0)
    _collision_course(env.world)
    seen: set = set()
    zero = {a: np.zeros(3, np.float32) for a in env.possible_agents}
    while env.agents:
        *_, infos = env.step(dict(zero))
        cost = [infos[a]["cost"] for a in env.possible_agents]
        terms = {k: [infos[a]["cost_terms"][k] for a in env.possible_agents] for k in COST_TERMS}
        _check(cost, terms, env.world, 0, seen)
        assert all(isinstance(c, float) for c in cost)
        assert terms["region"] == [float(infos[a]["in_reachable_region"]) for a in infos]
    _assert_both_seen(seen)


def test_gymnasium_cost_is_positive_exactly_on_loss():
    env = FormationEnv(**CFG)
    env.reset(seed=0)
    _collision_course(env.world)
    seen: set = set()
    done = False
    while not done:
        _, _, term, trunc, info = env.step(np.zeros(9, np.float32))
        done = term or trunc
        los_uav, los_obs = _losses(env.world)
        # The Gymnasium view reports the terms' team means only (checked below).
        terms = {"separation_uav": los_uav * 1.0, "separation_obstacle": los_obs * 1.0}
        _check(info["costs"], terms, env.world, 0, seen)
        assert info["cost"] == float(info["costs"].mean())
        assert (info["cost"] > 0) == bool(info["costs"].any())
        for k in COST_TERMS:
            assert isinstance(info["cost_" + k], float)
        assert info["cost_separation_obstacle"] == los_obs.mean()
        assert info["cost_separation_uav"] == los_uav.mean()
    _assert_both_seen(seen)


def test_vector_cost_is_positive_exactly_on_loss():
    env = FormationVectorEnv(num_envs=2, **CFG)
    env.reset(seed=0)
    _collision_course(env.world, env=0)  # environment 1 flies the plain encounter
    seen: set = set()
    for _ in range(200):
        _, _, term, trunc, infos = env.step(np.zeros((2, 9), np.float32))
        if (term | trunc).any():
            break
        assert infos["cost"].shape == (2,) and infos["costs"].shape == (2, 3)
        for e in range(2):
            los_uav, los_obs = _losses(env.world, e)
            terms = {"separation_uav": los_uav * 1.0, "separation_obstacle": los_obs * 1.0}
            _check(infos["costs"][e], terms, env.world, e, seen)
            assert (infos["cost"][e] > 0) == bool((los_uav | los_obs).any())
            assert infos["cost_separation_uav"][e] == los_uav.mean()
        assert infos["cost"][1] == 0.0
    else:
        pytest.fail("the collision course did not end the episode")
    _assert_both_seen(seen)


def test_sb3_cost_is_positive_exactly_on_loss():
    pytest.importorskip("stable_baselines3")
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    venv = UAVSharedVecEnv(n_envs=1, **CFG)
    venv.reset()
    _collision_course(venv.core.world)
    seen: set = set()
    for _ in range(200):
        venv.step_async(np.zeros((3, 3), np.float32))
        _, _, dones, infos = venv.step_wait()
        if dones.any():  # reset in the same step: the world is the next episode's
            assert infos[0]["cost"] > 0  # UAV 0 ended the episode on the obstacle
            break
        cost = [i["cost"] for i in infos]
        terms = {k: [i["cost_terms"][k] for i in infos] for k in COST_TERMS}
        _check(cost, terms, venv.core.world, 0, seen)
    else:
        pytest.fail("the collision course did not end the episode")
    _assert_both_seen(seen)


def _play(config: dict, read_cost: bool, steps: int = 200):
    """A seeded episode on the collision course with small random actions: everything each
    step returns except the cost, and each step's rewards recomputed from the world."""
    from uasep_env.interface.rewards import compute_rewards

    env = uasep_env.parallel_env(**config)
    obs, _ = env.reset(seed=11)
    _collision_course(env.world)
    rng = np.random.default_rng(0)
    out, costs = [obs], []
    for _ in range(steps):
        if not env.agents:
            break
        act = {a: rng.uniform(-0.2, 0.2, 3).astype(np.float32) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(act)
        if read_cost:
            costs.append([i["cost"] for i in infos.values()])
        for info in infos.values():
            del info["cost"], info["cost_terms"]
        own, _ = compute_rewards(env.world, env.config.reward)
        np.testing.assert_array_equal(list(rew.values()), own[0])  # nothing but the terms
        out.append((obs, rew, term, trunc, infos, env.world.uav_pos.copy()))
    return out, costs


def _same(a, b) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_equal(x, y)  # bit for bit: observations, rewards, infos, states


def test_cost_changes_no_reward_and_no_episode():
    base, _ = _play(CFG, read_cost=False)
    read, costs = _play(CFG, read_cost=True)
    _same(base, read)
    assert np.max(costs) > 0 and np.min(costs) == 0  # the episode has losses and none
    # Other cost weights (the region term on): the same episode and rewards, bit for bit.
    heavy = {**CFG, "cost": {"separation_uav": 7.0, "separation_obstacle": 0.0, "region": 3.0}}
    other, other_costs = _play(heavy, read_cost=True)
    _same(base, other)
    assert other_costs != costs


def test_cost_weights_combine_terms():
    core = EnvCore(make_config(**CFG, cost={"separation_uav": 2.0, "region": 0.5}), n_envs=1)
    core.reset(seed=0)
    _collision_course(core.world)
    for _ in range(40):
        res = core.step(np.zeros((1, 3, 3)))
        t = res.cost_terms
        expected = 2.0 * t["separation_uav"] + t["separation_obstacle"] + 0.5 * t["region"]
        np.testing.assert_array_equal(res.cost, expected)
        for row in TERMS:
            np.testing.assert_array_equal(t[row.name], res.safety[row.safety] * 1.0)
            assert ((t[row.name] >= row.low) & (t[row.name] <= row.high)).all()
        if res.terminated.any():
            break


def test_bad_cost_config_is_named():
    with pytest.raises(ValueError, match=r"cost\.separation_uav=-1"):
        make_config(cost={"separation_uav": -1})
    with pytest.raises(ValueError, match=r"cost\.region=nan"):
        make_config(cost={"region": float("nan")})
    with pytest.raises(TypeError, match=r"cost\.colision"):
        make_config(cost={"colision": 1.0})
    with pytest.raises(ValueError, match="'taks'"):
        make_config(reward="taks")
    assert CostWeights().region == 0.0  # default: > 0 exactly on a loss of separation


def test_task_reward_preset_and_its_bounds():
    cfg = make_config(reward="task")
    assert cfg.reward == RewardWeights.task()
    w = cfg.reward
    assert w.separation_inner == w.separation_obstacle == w.separation_region == 0.0
    assert w.collision == 0.0
    for name in ("deviation", "control", "smoothness", "progress"):
        assert getattr(w, name) == getattr(RewardWeights(), name)
    assert make_config(reward="default").reward == RewardWeights()
    assert step_reward_bounds(RewardWeights()) == pytest.approx((0.0, 1.0), abs=1e-12)
    low, high = step_reward_bounds(w)
    assert (low, high) == pytest.approx((0.75, 1.0))
    # Real steps with random actions stay within the bounds.
    core = EnvCore(make_config(scenario="random", reward="task", episode_duration=30.0), 8)
    core.reset(seed=2)
    rng = np.random.default_rng(1)
    alive = np.ones(8, dtype=bool)
    for _ in range(150):
        res = core.step(rng.uniform(-1, 1, size=(8, 3, 3)), active=alive)
        r = res.rewards[alive]
        assert (r >= low - 1e-12).all() and (r <= high + 1e-12).all()
        alive &= ~(res.terminated | res.truncated)
        if not alive.any():
            break


def test_sb3_agent_infos_are_the_plain_construction_in_order_and_distinct():
    """The written-out info maker gives what ``dict(zip(...))`` per agent gives."""
    pytest.importorskip("stable_baselines3")
    from uasep_env.envs import sb3

    rng = np.random.default_rng(4)
    n = 50
    clipped = rng.integers(0, 4, n).tolist()
    cost = rng.random(n).tolist()
    columns = [(rng.random(n) < 0.3).astype(float).tolist() for _ in COST_TERMS]
    infos = sb3._agent_infos(clipped, cost, *columns)
    want = [
        {"clipped_actions": c, "cost": k, "cost_terms": dict(zip(COST_TERMS, row, strict=True))}
        for c, k, row in zip(clipped, cost, zip(*columns, strict=True), strict=True)
    ]
    assert infos == want
    assert [list(i) for i in infos] == [list(w) for w in want]  # key order too
    assert [list(i["cost_terms"]) for i in infos] == [list(COST_TERMS)] * n
    assert len({id(i) for i in infos}) == n and len({id(i["cost_terms"]) for i in infos}) == n
    with pytest.raises(ValueError, match="zip"):
        sb3._agent_infos(clipped, cost[:-1], *columns)  # columns of unequal length


# ------------------------------------------------------- the cost table drives the flags
def _outcome_case(weights: CostWeights):
    """A stepped world's outcome inputs, with distances straddling every flag's threshold."""
    from uasep_env.interface import outcome, rewards

    core = EnvCore({"n_uavs": 4, "n_obstacles": 3, "scenario": "random"}, 12)
    core.reset(seed=3)
    rng = np.random.default_rng(4)
    for _ in range(5):
        core.step(rng.uniform(-1, 1, size=(12, 4, 3)))
    w, cfg = core.world, core.config
    x = rewards._gather_inputs(w, w.region_distances())
    x = type(x)(*(np.array(a, copy=True) for a in x))
    u = cfg.uav
    x.min_uav_dist[::2] = rng.uniform(0.0, 2 * u.separation_distance, x.min_uav_dist[::2].shape)
    x.min_obstacle_dist[1::2] = rng.uniform(
        0.0, 2 * u.obstacle_separation, x.min_obstacle_dist[1::2].shape
    )
    x.region[::3, :, 0] = rng.uniform(-5.0, 5.0, x.region[::3, :, 0].shape)
    rw, c = rewards._vectors(cfg.reward, u, cfg.max_steps)
    return x, c, rw, outcome.outcome_constants(u.lost_distance, weights)


@pytest.mark.parametrize("term", TERMS, ids=COST_TERMS)
def test_each_table_term_is_computed_alike_by_numpy_and_the_kernel(term):
    """Every row of the cost table: its flag and its cost are the same bits from the numpy
    reference and the compiled kernel, take both values, and the cost is the flag."""
    from uasep_env import _numba
    from uasep_env.interface import outcome

    if _numba.kernels() is None:
        pytest.skip("numba not in use")
    weights = CostWeights(**{t.name: 1.0 if t is term else 0.0 for t in TERMS})
    args = _outcome_case(weights)
    fast, slow = outcome.step_outcome(*args), outcome.step_outcome.reference(*args)
    for name, f, s in zip(outcome.Outcome._fields, fast, slow, strict=True):
        assert f.dtype == s.dtype and f.shape == s.shape, name
        assert np.array_equal(f, s, equal_nan=True), name
        assert f.tobytes() == s.tobytes(), name
    flag = fast.flags[outcome._FLAG_INDEX._fields.index(term.safety)]
    assert flag.any() and not flag.all()  # the case takes both sides of the threshold
    k = COST_TERMS.index(term.name)
    np.testing.assert_array_equal(fast.cost_terms[k], flag.astype(np.float64))
    np.testing.assert_array_equal(fast.cost, flag.astype(np.float64))


def test_safety_flags_agree_between_cost_table_numpy_kernel_weights_and_infos():
    """A cost term cannot be half-added: the table's flags, the numpy flags, the kernel's
    writes (by name, no literal row, no hand-sized array), the weights, the docstrings and
    the safety keys of the infos name the same things."""
    import dataclasses
    import re
    from pathlib import Path

    from uasep_env.envs.core import SAFETY_KEYS
    from uasep_env.interface import costs, outcome

    # The kernel read as text: it imports numba, which the floors' job does not install.
    source = (Path(outcome.__file__).parents[1] / "_kernels" / "rewards.py").read_text()
    kernel_fields = re.search(r'_FlagIndex = namedtuple\(\s*"_FlagIndex", "([^"]*)"', source)
    agent = source[source.index("def _outcome_agent(") :]
    agent = agent[: agent.index("\n@") if "\n@" in agent else len(agent)]
    flags = tuple(dict.fromkeys(t.safety for t in TERMS))
    assert costs.SAFETY_FLAGS == outcome.SAFETY_FLAGS == flags
    assert outcome._FLAG_INDEX._fields == tuple(kernel_fields.group(1).split()) == flags
    assert tuple(outcome._FLAG_INDEX) == tuple(range(len(flags)))
    x, c, _, _ = _outcome_case(CostWeights())
    assert tuple(outcome._flag_values(x, c, x.region.min(axis=-1))) == flags
    written = re.findall(r"flags\[fx\.(\w+), e, i\]", agent)
    assert sorted(written) == sorted(flags)  # each row once, by name
    assert not re.search(r"flags\[\d", source)  # no literal rows
    assert not re.search(r"np\.empty\(\(\d+, e, n\)", source)  # no hand-sized arrays
    assert tuple(f.name for f in dataclasses.fields(CostWeights)) == COST_TERMS
    for name in (*COST_TERMS, *flags):
        assert f"``{name}``" in costs.__doc__ or f'"{name}"' in costs.__doc__
    assert tuple(k for k in SAFETY_KEYS if k in flags) == flags
