"""The Gymnasium vector env and the stable-baselines3 adapter."""

import importlib.util

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import uasep_env  # noqa: F401 - registers the ids
from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.vector import FormationVectorEnv

SHORT = {"episode_duration": 3.0, "n_obstacles": 2}


def test_make_vec_uses_native_vector_env():
    vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=8, **SHORT)
    assert isinstance(vec.unwrapped, FormationVectorEnv)
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (8, *vec.single_observation_space.shape)
    assert vec.observation_space.contains(obs)
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP


def test_vector_env_matches_single_envs_across_autoreset():
    n = 4
    vec = FormationVectorEnv(n, **SHORT)
    singles = [FormationEnv(**SHORT) for _ in range(n)]
    obs_v, _ = vec.reset(seed=10)
    obs_s = [env.reset(seed=10 + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(obs_v, np.stack(obs_s))
    rng = np.random.default_rng(0)
    pending = np.zeros(n, dtype=bool)
    ended = 0
    for _ in range(40):
        act = rng.uniform(-1, 1, size=vec.action_space.shape).astype(np.float32)
        obs_v, rew_v, term_v, trunc_v, _ = vec.step(act)
        for i, env in enumerate(singles):
            if pending[i]:  # NextStep autoreset: this step resets env i, action ignored
                o, r, te, tr = env.reset()[0], 0.0, False, False
            else:
                o, r, te, tr, _ = env.step(act[i])
            np.testing.assert_array_equal(obs_v[i], o)
            assert rew_v[i] == pytest.approx(r, abs=1e-12)
            assert (term_v[i], trunc_v[i]) == (te, tr)
        pending = term_v | trunc_v
        ended += int(pending.sum())
    assert ended >= n  # every env went through at least one autoreset


def test_same_step_autoreset_final_obs():
    vec = FormationVectorEnv(3, autoreset_mode="SameStep", **SHORT)
    single = FormationEnv(**SHORT)
    vec.reset(seed=5)
    single.reset(seed=5)
    zero = np.zeros(vec.action_space.shape, np.float32)
    for _ in range(200):
        obs, _, term, trunc, info = vec.step(zero)
        o, _, te, tr, _ = single.step(zero[0])
        if te or tr:
            assert term[0] or trunc[0]
            assert info["_final_obs"][0]
            np.testing.assert_array_equal(info["final_obs"][0], o)
            assert obs[0].tolist() != o.tolist()  # the returned obs is the new episode's
            return
        np.testing.assert_array_equal(obs[0], o)
    pytest.fail("episode did not end")


def test_vector_bad_actions_and_modes():
    vec = FormationVectorEnv(2, **SHORT)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 9\)"):
        vec.step(np.zeros((3, 9)))
    bad = np.zeros((2, 9))
    bad[1, 4] = np.inf
    with pytest.raises(ValueError, match=r"non-finite value inf at index \(1, 4\)"):
        vec.step(bad)
    with pytest.raises(ValueError, match="autoreset_mode 'Sometimes'"):
        FormationVectorEnv(2, autoreset_mode="Sometimes")
    with pytest.raises(ValueError, match="num_envs"):
        FormationVectorEnv(0)
    with pytest.raises(TypeError, match=r"must be real numbers.*bool"):
        vec.step(np.zeros((2, 9), bool))
    with pytest.raises(TypeError, match="n_uavz"):
        FormationVectorEnv(2, n_uavz=3)
    with pytest.raises(TypeError, match="n_uavz"):
        gymnasium.make_vec("uasep/Formation-v3", num_envs=2, n_uavz=3)


def test_vector_clips_and_counts_actions():
    vec = FormationVectorEnv(2, **SHORT)
    ref = FormationVectorEnv(2, **SHORT)
    vec.reset(seed=0)
    ref.reset(seed=0)
    act = np.zeros((2, 9))
    act[1, [3, 4, 5]] = [5.0, -2.0, 1.0]
    obs, rew, *_, info = vec.step(act)
    obs_ref, rew_ref, *_, info_ref = ref.step(np.clip(act, -1, 1))
    assert info["clipped_actions"].tolist() == [[0, 0, 0], [0, 2, 0]]
    assert info["_clipped_actions"].all()
    assert not info_ref["clipped_actions"].any()
    np.testing.assert_array_equal(obs, obs_ref)
    np.testing.assert_array_equal(rew, rew_ref)
    strict = FormationVectorEnv(2, action={"strict": True}, **SHORT)
    strict.reset(seed=0)
    with pytest.raises(ValueError, match=r"value 5.0 at index \(1, 3\) is outside"):
        strict.step(act)


def test_vector_seeds_are_checked():
    """Issue 13 item 3: vector seed "12345678" became the seeds 1..8."""
    vec = FormationVectorEnv(8, **SHORT)
    for seed, err, match in [
        ("12345678", TypeError, "got '12345678'"),
        (1.5, TypeError, "got 1.5"),
        ([1, 2], ValueError, "expected 8 seeds, got 2"),
        ([0, 1, 2, 3, 4, 5, 6, 7.0], TypeError, r"seed\[7\] must be None or a non-negative int"),
        ([0, 1, 2, 3, 4, 5, 6, -7], ValueError, r"seed\[7\] must be >= 0, got -7"),
        ([True] * 8, TypeError, r"seed\[0\]"),
        (-1, ValueError, "got -1"),
    ]:
        with pytest.raises(err, match=match):
            vec.reset(seed=seed)
    obs_list, _ = vec.reset(seed=list(range(10, 18)))
    obs_int, _ = FormationVectorEnv(8, **SHORT).reset(seed=10)
    np.testing.assert_array_equal(obs_list, obs_int)
    with pytest.raises(TypeError, match="options must be a dict"):
        vec.reset(options=5)


def test_vector_lifecycle():
    vec = FormationVectorEnv(2, autoreset_mode="Disabled", episode_duration=0.4)
    zero = np.zeros(vec.action_space.shape)
    with pytest.raises(RuntimeError, match="before reset"):
        vec.step(zero)
    with pytest.raises(RuntimeError, match="first reset"):
        vec.reset(options={"reset_mask": np.array([True, False])})
    vec.reset(seed=0)
    vec.step(zero)
    *_, trunc, _ = vec.step(zero)
    assert trunc.all()
    with pytest.raises(RuntimeError, match=r"environments \[0, 1\] have finished"):
        vec.step(zero)
    vec.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(RuntimeError, match=r"environments \[1\] have finished"):
        vec.step(zero)
    vec.reset(options={"reset_mask": np.array([False, True])})
    vec.step(zero)


def test_vector_disabled_mode_reset_mask():
    vec = FormationVectorEnv(2, autoreset_mode="Disabled", **SHORT)
    vec.reset(seed=0)
    zero = np.zeros(vec.action_space.shape, np.float32)
    for _ in range(3):
        vec.step(zero)
    t_before = vec.world.time.copy()
    vec.reset(options={"reset_mask": np.array([True, False])})
    assert vec.world.time[0] == 0.0 and vec.world.time[1] == t_before[1]


# Per test, not at module level: a module-level importorskip would skip every vector test
# on an install without SB3 (the minimum-versions job).
needs_sb3 = pytest.mark.skipif(
    importlib.util.find_spec("stable_baselines3") is None, reason="needs stable-baselines3"
)


@needs_sb3
def test_sb3_adapter_passes_sb3_checks_and_terminal_obs():
    from stable_baselines3.common.vec_env import VecMonitor

    from uasep_env.envs.sb3 import UAVSharedVecEnv

    venv = UAVSharedVecEnv(n_envs=2, seed=3, **SHORT)
    assert venv.num_envs == 2 * 3
    obs = venv.reset()
    assert obs.shape == (6, venv.observation_space.shape[0])
    mon = VecMonitor(venv)
    mon.reset()
    finished = False
    for _ in range(100):
        venv.step_async(np.zeros((6, 3), np.float32))
        obs, rew, dones, infos = venv.step_wait()
        assert rew.shape == (6,) and dones.shape == (6,)
        if dones.any():
            k = int(np.flatnonzero(dones)[0])
            assert "terminal_observation" in infos[k]
            assert infos[k]["TimeLimit.truncated"] is True
            assert not np.array_equal(infos[k]["terminal_observation"], obs[k])
            finished = True
            break
    assert finished
    with pytest.raises(ValueError, match=r"shape \(6, 3\)"):
        venv.step_async(np.zeros((5, 3)))
        venv.step_wait()


@needs_sb3
def test_sb3_adapter_hostile_actions_and_clipping():
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    venv = UAVSharedVecEnv(n_envs=2, seed=3, **SHORT)
    venv.reset()
    # Issue 13 item 7: a ragged list gave numpy's "setting an array element with a sequence".
    with pytest.raises(ValueError, match="must be real numbers, got a nested sequence"):
        venv.step_async([[0, 0, 0]] * 5 + [[0, 0]])
    # Indices are positions in the (n, 3) input, not (env, uav, axis).
    bad = np.zeros((6, 3))
    bad[4, 2] = np.nan
    with pytest.raises(ValueError, match=r"non-finite value nan at index \(4, 2\)"):
        venv.step_async(bad)
    with pytest.raises(TypeError, match=r"must be real numbers, got None at index \(1, 0\)"):
        venv.step_async([[0, 0, 0], [None, 0, 0]] + [[0, 0, 0]] * 4)
    act = np.zeros((6, 3))
    act[5] = [2.0, 2.0, -2.0]
    venv.step_async(act)
    _, _, _, infos = venv.step_wait()
    assert [i["clipped_actions"] for i in infos] == [0, 0, 0, 0, 0, 3]
    with pytest.raises(TypeError, match="seed must be None or a non-negative int, got '1'"):
        venv.seed("1")
    with pytest.raises(TypeError, match="n_uavz"):
        UAVSharedVecEnv(n_envs=1, n_uavz=2)
    strict = UAVSharedVecEnv(n_envs=2, seed=3, action={"strict": True}, **SHORT)
    strict.reset()
    with pytest.raises(ValueError, match=r"value 2.0 at index \(5, 0\) is outside"):
        strict.step_async(act)


@pytest.mark.parametrize("numba_on", [True, False])
def test_reset_some_builds_only_the_reset_rows_exactly(monkeypatch, numba_on):
    """Same-step autoresets rebuild the reset environments' observations only, exactly."""
    from uasep_env import _numba
    from uasep_env.envs.core import EnvCore

    if not numba_on:
        monkeypatch.setitem(_numba._state, "numba", None)
    core = EnvCore({"n_uavs": 3, "n_obstacles": 2, "scenario": "random"}, n_envs=6)
    core.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(5):
        core.step(rng.uniform(-1, 1, size=(6, 3, 3)))
    mask = np.array([False, True, False, False, True, True])
    got = core.reset_some(mask)
    assert got.shape == (3, 3, core.obs_dim)
    np.testing.assert_array_equal(got, core.observations()[mask])


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_vector_info_masks_are_right_and_each_its_own_array(mode):
    """Each info key's mask is its own array (as ``SyncVectorEnv``'s), with its rows."""
    # Environment 0's UAVs fly off their plan and get lost: it ends while the others fly on.
    config = {**SHORT, "episode_duration": 30.0, "uav": {"lost_distance": 40.0}}
    vec = FormationVectorEnv(4, autoreset_mode=mode, **config)
    vec.reset(seed=3)
    act = np.zeros(vec.action_space.shape, np.float32)
    act[0] = 1.0
    seen_partial = False
    done = np.zeros(4, dtype=bool)
    for _ in range(60):
        _, _, term, trunc, infos = vec.step(act)
        parts = [infos] + ([infos["final_info"]] if "final_info" in infos else [])
        for part in parts:
            masks = [v for k, v in part.items() if k.startswith("_") and k[1:] in part]
            for i, a in enumerate(masks):
                assert not any(np.shares_memory(a, b) for b in masks[i + 1 :])
        # NextStep: the rows reset this step have the reset's (empty) info; SameStep: the
        # rows that ended, whose info is in final_info.
        want = ~done if mode == "NextStep" else ~(term | trunc)
        seen_partial |= not want.all() and bool(want.any())
        for k in ("rewards", "cost", "min_uav_distance"):
            if want.any():
                np.testing.assert_array_equal(infos["_" + k], want)
            else:  # no row has this step's info: no key (as SyncVectorEnv)
                assert "_" + k not in infos
        done = term | trunc
    assert seen_partial


def test_vector_infos_term_means_are_each_environments_own():
    """The infos' reward and cost terms' team means (made from the step's terms arrays):
    each environment's own terms, in order."""
    from uasep_env.interface.costs import compute_costs
    from uasep_env.interface.rewards import compute_rewards

    vec = FormationVectorEnv(num_envs=6, scenario="random")
    vec.reset(seed=3)
    rng = np.random.default_rng(5)
    seen = 0
    for _ in range(40):
        *_, infos = vec.step(rng.uniform(-1.0, 1.0, (6, 9)).astype(np.float32))
        _, terms = compute_rewards(vec.core.world, vec.config.reward)
        _, cost_terms = compute_costs(infos, vec.config.cost)
        for prefix, values in (("reward_", terms), ("cost_", cost_terms)):
            for k, v in values.items():
                mask = infos["_" + prefix + k]
                np.testing.assert_array_equal(
                    infos[prefix + k][mask], v.mean(axis=-1)[mask], err_msg=k, strict=True
                )
                seen += int(mask.sum())
    assert seen > 0


def test_vector_infos_from_a_step_result_without_its_terms_arrays():
    """A ``StepResult`` built with the term dicts only (its arrays ``None``, the fields'
    defaults) gives the same infos, the rows stacked."""
    import dataclasses

    vec = FormationVectorEnv(num_envs=4, scenario="random")
    vec.reset(seed=1)
    res = vec.core.step(np.random.default_rng(2).uniform(-1.0, 1.0, (4, 3, 3)))
    bare = dataclasses.replace(res, terms_array=None, cost_terms_array=None)
    held = np.array([1])
    want = FormationVectorEnv._info_values(res, held)
    got = FormationVectorEnv._info_values(bare, held)
    assert got.keys() == want.keys()
    for k, v in want.items():
        np.testing.assert_array_equal(got[k], v, err_msg=k, strict=True)
    assert not got["reward_" + next(iter(res.terms))][1]  # the held row's means zeroed
