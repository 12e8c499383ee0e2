"""The PettingZoo parallel env and the Gymnasium views."""

import re
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

import uasep_env
from uasep_env.registration import ENV_IDS

GRID = [
    {"n_uavs": 2, "n_obstacles": 0},
    {"n_uavs": 3, "n_obstacles": 1, "noise": False},
    {"n_uavs": 5, "n_obstacles": 3, "scenario": "multi_obstacle", "formation": "v"},
    {"n_uavs": 4, "n_obstacles": 2, "prediction": {"mode": "terminal", "kalman": False}},
    {"n_uavs": 3, "scenario": "climbing", "decision_interval": 3},
    {"n_uavs": 8, "n_obstacles": 2, "scenario": "large_formation", "formation": "grid"},
    {"n_uavs": 32, "n_obstacles": 8, "scenario": "random", "observation": {"k_uavs": 4}},
]


@pytest.mark.parametrize("cfg", GRID)
def test_pettingzoo_parallel_api(cfg):
    env = uasep_env.parallel_env(**cfg, episode_duration=20.0)
    parallel_api_test(env, num_cycles=120)


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_gymnasium_check_env_every_id(env_id):
    env = gymnasium.make(env_id, episode_duration=10.0)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


@pytest.mark.parametrize("cfg", GRID[:5])
def test_gymnasium_check_env_grid(cfg):
    env = gymnasium.make("uasep/Formation-v3", **cfg)
    check_env(env.unwrapped, skip_render_check=True)


def test_gymnasium_make_validates_config():
    with pytest.raises(TypeError, match="n_uavz"):
        gymnasium.make("uasep/Formation-v3", n_uavz=3)
    with pytest.raises(ValueError, match="n_uavs=99"):
        gymnasium.make("uasep/PaperEncounter-v3", n_uavs=99)


def test_registration_survives_spawned_subprocesses():
    vec = gymnasium.make_vec(
        "uasep/Formation-v3",
        num_envs=2,
        vectorization_mode="async",
        vector_kwargs={"context": "spawn"},
        episode_duration=5.0,
    )
    try:
        obs, _ = vec.reset(seed=0)
        obs, *_ = vec.step(np.zeros(vec.action_space.shape, dtype=np.float32))
        assert obs.shape[0] == 2
    finally:
        vec.close()


def test_import_registers_ids_in_a_fresh_interpreter():
    code = (
        "import gymnasium, uasep_env; e = gymnasium.make('uasep/PaperEncounter-v3'); "
        "print(e.reset(seed=0)[0].shape)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().startswith("(")


def _random_rollout(seed, steps, cfg):
    env = uasep_env.parallel_env(**cfg)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed + 1000)
    out = [np.stack([obs[a] for a in env.possible_agents])]
    rewards = []
    for _ in range(steps):
        if not env.agents:
            obs, _ = env.reset()
        acts = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in env.agents}
        obs, rew, _term, _trunc, _info = env.step(acts)
        out.append(np.stack([obs[a] for a in env.possible_agents]))
        rewards.append([rew[a] for a in env.possible_agents])
    return np.array(out), np.array(rewards), env.state()


def test_n_step_determinism_1000_steps():
    # pettingzoo<=1.27's parallel_seed_test checks one step only: check 1000, across resets.
    cfg = {"scenario": "random", "n_obstacles": 2, "episode_duration": 60.0}
    o1, r1, s1 = _random_rollout(42, 1000, cfg)
    o2, r2, s2 = _random_rollout(42, 1000, cfg)
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(s1, s2)
    o3, _, _ = _random_rollout(43, 50, cfg)
    assert not np.array_equal(o1[:51], o3)


@pytest.fixture
def env():
    e = uasep_env.parallel_env(scenario="paper", noise=False)
    e.reset(seed=0)
    return e


def _zero(env):
    return {a: np.zeros(3, np.float32) for a in env.agents}


@pytest.mark.parametrize(
    "mutate,match",
    [
        (lambda a: a.pop("uav_0"), r"missing \['uav_0'\]"),
        (lambda a: a.update(uav_9=np.zeros(3)), r"unknown \['uav_9'\]"),
        (lambda a: a.update(uav_1=np.zeros(2)), r"action of uav_1 must have shape \(3,\)"),
        (
            lambda a: a.update(uav_2=np.array([0, np.nan, 0])),
            "uav_2 contains a non-finite value nan",
        ),
        (
            lambda a: a.update(uav_2=np.array([0, 0, np.inf])),
            "uav_2 contains a non-finite value inf",
        ),
        (lambda a: a.update(uav_1=[0.0, -np.inf, 2.0]), "uav_1 contains a non-finite value -inf"),
        (lambda a: a.update(uav_1=0.5), r"action of uav_1 must have shape \(3,\), got \(\)"),
        (
            lambda a: a.update(uav_2=[0.1, "x", 0.2]),
            r"action of uav_2 must be real numbers, got 'x' at index \(1,\)",
        ),
        (
            lambda a: a.update(uav_0=np.array(["a", "b", "c"])),
            # numpy >= 2 writes np.str_('a'), numpy 1.x 'a'.
            r"action of uav_0 must be real numbers, got (np\.str_\()?'a'",
        ),
        # Issue 13 item 2: only real numbers are actions.
        (
            lambda a: a.update(uav_1=np.array([0, 0, complex(0, np.nan)])),
            r"action of uav_1 must be real numbers.*dtype complex128",
        ),
        (
            lambda a: a.update(uav_1=np.array([1, 2, 3], dtype="datetime64[s]")),
            r"action of uav_1 must be real numbers.*dtype datetime64",
        ),
        (
            lambda a: a.update(uav_1=np.array([1, 2, 3], dtype="timedelta64[s]")),
            r"action of uav_1 must be real numbers.*dtype timedelta64",
        ),
        (lambda a: a.update(uav_0=["1", "-1", "0.5"]), "uav_0 must be real numbers, got '1'"),
        (lambda a: a.update(uav_0=b"abc"), "uav_0 must be real numbers, got b'abc'"),
        (lambda a: a.update(uav_0=np.ones(3, bool)), "uav_0 must be real numbers.*dtype bool"),
        (lambda a: a.update(uav_0=[True, 0.0, 0.0]), "uav_0 must be real numbers, got True"),
        (
            lambda a: a.update(uav_2=np.array([0.1, "x", 0.2], dtype=object)),
            r"uav_2 must be real numbers, got 'x' at index \(1,\)",
        ),
        # Issue 13 item 7: None is named as None, not as a non-finite nan.
        (lambda a: a.update(uav_2=[0.0, None, 0.0]), r"uav_2 must be real numbers, got None"),
    ],
)
def test_bad_actions_raise_clear_errors(env, mutate, match):
    acts = _zero(env)
    mutate(acts)
    with pytest.raises(ValueError, match=match):
        env.step(acts)
    assert env.agents  # a rejected action does not step: the episode goes on


def test_non_numbers_are_type_errors(env):
    acts = _zero(env)
    acts["uav_1"] = ["0.5", 0, 0]
    with pytest.raises(TypeError, match=r"uav_1 must be real numbers, got '0\.5'"):
        env.step(acts)


def test_out_of_box_actions_are_clipped_and_counted(env):
    ref = uasep_env.parallel_env(scenario="paper", noise=False)
    ref.reset(seed=0)
    acts = _zero(env)
    acts["uav_0"] = np.array([0.0, 1.5, -7.0])
    acts["uav_2"] = [3, 0, 0]
    obs, rew, _, _, infos = env.step(acts)
    clipped = {"uav_0": np.array([0.0, 1.0, -1.0]), "uav_1": np.zeros(3), "uav_2": [1, 0, 0]}
    obs_ref, rew_ref, _, _, infos_ref = ref.step(clipped)
    assert {a: i["clipped_actions"] for a, i in infos.items()} == {
        "uav_0": 2,
        "uav_1": 0,
        "uav_2": 1,
    }
    assert all(i["clipped_actions"] == 0 for i in infos_ref.values())
    for a in env.possible_agents:
        np.testing.assert_array_equal(obs[a], obs_ref[a])
        assert rew[a] == rew_ref[a]


def test_strict_action_option_raises_for_out_of_box_actions():
    env = uasep_env.parallel_env(scenario="paper", action={"strict": True})
    env.reset(seed=0)
    acts = _zero(env)
    acts["uav_0"] = np.array([0.0, 1.5, 0.0])
    with pytest.raises(ValueError, match=r"action of uav_0 value 1.5 at index \(1,\) is outside"):
        env.step(acts)


def test_bad_agent_and_spaces(env):
    with pytest.raises(ValueError, match="unknown agent 'uav_7'"):
        env.observation_space("uav_7")
    assert env.observation_space("uav_0") is env.observation_space("uav_1")


def test_gym_bad_action():
    env = gymnasium.make("uasep/Formation-v3").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(9,\)"):
        env.step(np.zeros(3))
    with pytest.raises(TypeError, match=r"must be real numbers.*complex"):
        env.step(np.zeros(9, complex))


def test_gym_clips_and_counts_and_strict_raises():
    env = gymnasium.make("uasep/PaperEncounter-v3")
    env.reset(seed=0)
    act = np.zeros(9)
    act[[0, 1, 8]] = [2.0, -3.0, 1.5]
    *_, info = env.step(act)
    assert info["clipped_actions"].tolist() == [2, 0, 1]
    *_, info = env.step(np.zeros(9))
    assert info["clipped_actions"].tolist() == [0, 0, 0]
    strict = gymnasium.make("uasep/PaperEncounter-v3", action={"strict": True})
    strict.reset(seed=0)
    with pytest.raises(ValueError, match=r"value 2.0 at index \(0,\) is outside"):
        strict.step(act)


def test_gym_reward_and_info_means_are_each_rows_numpy_mean():
    """The single-agent view's means over the UAVs: the same bits as ``row.mean()``."""
    env = gymnasium.make("uasep/Formation-v3", scenario="random", n_uavs=5).unwrapped
    env.reset(seed=2)
    rng = np.random.default_rng(0)
    for _ in range(30):
        _, reward, term, trunc, info = env.step(rng.uniform(-1, 1, 15).astype(np.float32))
        assert type(reward) is float and reward == float(info["rewards"].mean())
        assert info["cost"] == float(info["costs"].mean())
        world = env.core.world
        _, terms = uasep_env.interface.rewards.compute_rewards(world, env.config.reward)
        for k, v in terms.items():
            got = info["reward_" + k]
            assert type(got) is float and np.float64(got).tobytes() == v[0].mean().tobytes(), k
        if term or trunc:
            env.reset()


def test_gym_stepping_a_finished_episode_raises():
    """Issue 13 item 1: the Gymnasium view kept stepping after its episode ended."""
    g = gymnasium.make("uasep/Formation-v3", formation_spacing=0.5)
    g.reset(seed=4)
    _, _, terminated, _, _ = g.step(np.zeros(9))
    assert terminated  # a collision
    with pytest.raises(RuntimeError, match="reset"):
        g.step(np.full(9, 0.3))
    g = gymnasium.make("uasep/Formation-v3", episode_duration=1.0).unwrapped
    g.reset(seed=0)
    truncated = [g.step(np.zeros(9))[3] for _ in range(5)]
    assert truncated == [False] * 4 + [True]
    with pytest.raises(RuntimeError, match="reset"):
        g.step(np.zeros(9))
    g.reset()
    g.step(np.zeros(9))  # a new episode steps again


@pytest.mark.parametrize("seed", ["5", b"7", [1.9], 1.5, [-5], True, np.float64(2.0), [1, 2]])
def test_bad_seeds_are_named(seed):
    """Issue 13 item 3: seeds were coerced ("5" == 5) or failed inside numpy."""
    for env in (uasep_env.parallel_env(), gymnasium.make("uasep/Formation-v3")):
        with pytest.raises(TypeError, match=re.escape(f"got {seed!r}")):
            env.reset(seed=seed)
    with pytest.raises(ValueError, match="seed must be >= 0, got -1"):
        uasep_env.parallel_env().reset(seed=-1)


def test_numpy_integer_seed_equals_int_seed():
    a, b = gymnasium.make("uasep/Formation-v3"), gymnasium.make("uasep/Formation-v3")
    np.testing.assert_array_equal(a.reset(seed=np.int64(3))[0], b.reset(seed=3)[0])


@pytest.mark.parametrize("options", [5, "config", [("config", {})]])
def test_reset_options_must_be_a_dict(options):
    """Issue 13 item 7: reset(options=5) raised AttributeError or TypeError from inside."""
    for env in (uasep_env.parallel_env(), gymnasium.make("uasep/Formation-v3")):
        with pytest.raises(TypeError, match="options must be a dict or None, got"):
            env.reset(seed=0, options=options)


@pytest.mark.parametrize("changes", [5, "x", [], np.zeros(2)])
def test_reset_options_config_must_be_a_dict(changes):
    env = uasep_env.parallel_env()
    with pytest.raises(TypeError, match=r"options\['config'\] must be a dict, got"):
        env.reset(seed=0, options={"config": changes})


def test_gym_unknown_reset_option_is_named():
    env = gymnasium.make("uasep/Formation-v3")
    with pytest.raises(ValueError, match=r"unknown reset option.*'bogus'"):
        env.reset(seed=0, options={"bogus": 1})


def test_step_after_end_raises():
    env = uasep_env.parallel_env(episode_duration=0.4, n_obstacles=0)
    env.reset(seed=0)
    for _ in range(2):
        _, _, _, trunc, _ = env.step(_zero(env))
    assert all(trunc.values()) and env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_reset_options_config():
    env = uasep_env.parallel_env(scenario="paper")
    env.reset(seed=0, options={"config": {"noise": False, "scenario": "crossing"}})
    assert env.config.noise.is_off and env.config.scenario == "crossing"
    assert env.world.families[0] == "crossing"
    with pytest.raises(ValueError, match="n_uavs"):
        env.reset(options={"config": {"n_uavs": 4}})
    with pytest.raises(TypeError, match=r"noise\.nope"):
        env.reset(options={"config": {"noise": {"nope": 1}}})


def test_infos_carry_reward_terms_and_safety(env):
    _, rew, _, _, infos = env.step(_zero(env))
    info = infos["uav_0"]
    assert set(info["reward_terms"]) == set(uasep_env.interface.rewards.REWARD_TERMS)
    for key in ("min_uav_distance", "min_obstacle_distance", "min_region_distance"):
        assert np.isfinite(info[key])
    for key in ("loss_of_separation_uav", "loss_of_separation_obstacle", "collision"):
        assert isinstance(info[key], bool)
    w = env.config.reward
    expected = sum(getattr(w, k) * v for k, v in info["reward_terms"].items())
    assert rew["uav_0"] == pytest.approx(expected)


def test_state_is_global_true_state(env):
    s = env.state()
    assert env.state_space.contains(s)
    p0 = env.world.uav_pos[0, 0]
    plan_center, _ = env.world.plan.center(env.world.time)
    np.testing.assert_allclose(s[:3], (p0 - plan_center[0]) / 100.0, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(
    "kw",
    [
        {"scenario": "paper"},
        {"n_uavs": 5, "n_obstacles": 3, "scenario": "random",
         "observation": {"k_uavs": 3, "k_obstacles": 2, "optional_features": ["obstacle_class"]}},
        {"n_obstacles": 0, "action": {"mode": "residual_apf"}},
    ],
)  # fmt: skip
def test_decode_columns_are_where_decode_reads(kw):
    """``decode_columns()`` and ``feature_columns()``: each feature's columns, stride, count
    and scale, as ``decode`` reads them (what the APF's kernel decodes with)."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.interface.observation import ObservationLayout

    cfg = make_config(**kw)
    layout = ObservationLayout.from_config(cfg)
    obs = EnvCore(cfg, n_envs=2).reset(seed=3)
    obs = obs + np.arange(obs.shape[-1], dtype=obs.dtype)  # every column its own value
    decoded = layout.decode(obs)
    where = layout.decode_columns()
    assert set(where) == set(decoded) - {"base_action"}
    for key, (start, size, scale, stride, count) in where.items():
        cols = start + (np.arange(count) * stride)[:, None] + np.arange(size)
        shared, shared_scale = layout.feature_columns(key)
        np.testing.assert_array_equal(shared, cols, err_msg=key)
        assert shared_scale == scale and not shared.flags.writeable
        got = obs[..., cols].astype(float) * scale
        want = decoded[key]
        if key.endswith("_mask"):
            np.testing.assert_array_equal(got[..., 0] > 0.5, want, err_msg=key)
        else:
            np.testing.assert_array_equal(got.reshape(want.shape), want, err_msg=key)
    if "obstacle_class" not in where:
        with pytest.raises(KeyError, match="obstacle_class"):
            layout.feature_columns("obstacle_class")


def test_observation_decodes_to_si_quantities():
    env = uasep_env.parallel_env(
        scenario="paper", observation={"sensing_range": 3000.0, "position_scale": 500.0}
    )
    env.reset(seed=0)
    obs, *_ = env.step(_zero(env))
    o = env.layout.decode(obs["uav_2"])
    w = env.world
    np.testing.assert_allclose(o["velocity"], w.est_vel[0, 2], rtol=1e-5, atol=1e-5)
    plan_pos, _ = w.planned()
    np.testing.assert_allclose(o["plan_offset"], plan_pos[0, 2] - w.est_pos[0, 2], atol=1e-3)
    region = w.region_distances(w.est_pos)[0, 2, 0]
    np.testing.assert_allclose(o["obstacle_region_dist"][0, 0], region, rtol=1e-5)
    np.testing.assert_allclose(
        o["obstacle_rel_pos"][0], w.obstacle_est_pos[0, 0] - w.est_pos[0, 2], rtol=1e-5
    )
    np.testing.assert_allclose(
        o["obstacle_rel_vel"][0], w.obstacle_est_vel[0, 0] - w.est_vel[0, 2], atol=1e-5
    )
    # The nearest neighbour's relative position is right and sorted first.
    d = np.linalg.norm(w.est_pos[0] - w.est_pos[0, 2], axis=-1)
    d[2] = np.inf
    j = int(np.argmin(d))
    np.testing.assert_allclose(o["uav_rel_pos"][0], w.est_pos[0, j] - w.est_pos[0, 2], atol=1e-3)
    assert o["uav_mask"].all() and o["obstacle_mask"][0]
    np.testing.assert_allclose(o["obstacle_axes"][0], w.pred_axes[0, 0], rtol=1e-5)
    assert len(env.layout.feature_names()) == env.layout.dim


def test_row_dicts_writes_any_layout_as_the_plain_construction():
    from uasep_env.envs._infos import row_dicts

    names = ("x", "y's", 'z"q', "w\\n")  # any text is a name: written as literals
    make = row_dicts(("a", ("nested", names), "b"))
    cols = [[1, 2], [3.0, 4.0], [5.0, 6.0], [True, False], [None, "s"], [7, 8]]
    got = make(*cols)
    want = [
        {"a": a, "nested": dict(zip(names, (x, y, z, w), strict=True)), "b": b}
        for a, x, y, z, w, b in zip(*cols, strict=True)
    ]
    assert got == want and [list(d) for d in got] == [list(d) for d in want]
    assert got[0]["nested"] is not got[1]["nested"]
    assert row_dicts(("only",))([1, 2]) == [{"only": 1}, {"only": 2}]
    with pytest.raises(ValueError, match="zip"):
        make(*cols[:-1], [7])
    with pytest.raises(TypeError, match="a name or"):
        row_dicts((("a", "b", "c"),))


def test_parallel_infos_have_the_steps_safety_keys_in_order():
    """The infos' keys: the reward terms, then every safety figure of the step, in order."""
    from uasep_env.envs.core import SAFETY_KEYS

    env = uasep_env.parallel_env(scenario="random")
    env.reset(seed=0)
    _, _, _, _, infos = env.step(_zero(env))
    res = env._last
    assert tuple(res.safety) == SAFETY_KEYS
    for i, agent in enumerate(env.possible_agents):
        info = infos[agent]
        assert list(info) == ["reward_terms", *SAFETY_KEYS, "cost", "cost_terms", "clipped_actions"]
        for k in SAFETY_KEYS:
            want = res.safety[k][0, i].item()
            assert info[k] == want and type(info[k]) is type(want), k
        assert info["reward_terms"] == {k: res.terms[k][0, i].item() for k in res.terms}
        assert info["cost_terms"] == {k: v[0, i].item() for k, v in res.cost_terms.items()}
