"""The ecosystem's conventions the clients rely on (issue 12, "What to build" item 1)."""

import gc
import weakref

import gymnasium
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from pettingzoo.test import max_cycles_test

import uasep_env
from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.vector import FormationVectorEnv
from uasep_env.interface.rewards import REWARD_TERMS
from uasep_env.registration import ENV_IDS

# --- unknown keywords: TypeError, as Python raises for an unexpected keyword ------------------


def test_torchrl_frameskip_keyword_is_a_type_error():
    """TorchRL's GymEnv passes ``frameskip`` and drops it only on a TypeError."""
    with pytest.raises(TypeError, match="frameskip"):
        gymnasium.make("uasep/Formation-v3", frameskip=1)
    with pytest.raises(TypeError, match="frameskip"):
        uasep_env.parallel_env(frameskip=1)


# --- PettingZoo: max_cycles, spaces dicts, envs freed -------------------------------------------


def test_max_cycles_convention():
    env = uasep_env.parallel_env(max_cycles=4, n_obstacles=0)
    assert env.config.max_steps == 4
    env.reset(seed=0)
    steps = 0
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        steps += 1
    assert steps == 4
    max_cycles_test(uasep_env)  # the package is the env module: parallel_env and env


@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "4"])
def test_bad_max_cycles_is_named(bad):
    with pytest.raises(ValueError, match=rf"max_cycles must be a positive integer, got {bad!r}"):
        uasep_env.parallel_env(max_cycles=bad)


def test_max_cycles_and_a_different_episode_duration_disagree():
    with pytest.raises(ValueError, match="disagree"):
        uasep_env.parallel_env(max_cycles=4, episode_duration=10.0)
    assert uasep_env.parallel_env(max_cycles=3, episode_duration=0.6).config.max_steps == 3


def test_spaces_dicts_are_declared():
    env = uasep_env.parallel_env(n_uavs=4)
    assert list(env.observation_spaces) == env.possible_agents
    assert list(env.action_spaces) == env.possible_agents
    for a in env.possible_agents:
        assert env.observation_spaces[a] is env.observation_space(a)
        assert env.action_spaces[a] is env.action_space(a)
    with pytest.raises(ValueError, match="unknown agent 'uav_9'"):
        env.observation_space("uav_9")


def test_env_is_freed_after_del():
    env = uasep_env.parallel_env()
    env.observation_space("uav_0")
    env.action_space("uav_1")
    ref = weakref.ref(env)
    del env
    gc.collect()
    assert ref() is None


# --- reset options -----------------------------------------------------------------------------


def test_pettingzoo_unknown_reset_option_warns_and_is_ignored():
    env = uasep_env.parallel_env()
    obs_ref, _ = env.reset(seed=3)
    with pytest.warns(UserWarning, match=r"reset option\(s\) \['options'\] ignored"):
        obs, _ = env.reset(seed=3, options={"options": 1})
    np.testing.assert_array_equal(obs["uav_0"], obs_ref["uav_0"])


# --- Gymnasium: spec.max_episode_steps ---------------------------------------------------------


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_spec_declares_max_episode_steps(env_id):
    env = gymnasium.make(env_id)
    assert env.spec.max_episode_steps == env.unwrapped.config.max_steps == 1000
    vec = gymnasium.make_vec(env_id, num_envs=2)
    assert vec.unwrapped.config.max_steps == 1000


def test_vector_max_episode_steps_the_earlier_limit_wins():
    vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=2, max_episode_steps=5)
    assert vec.unwrapped.config.max_steps == 5
    assert FormationVectorEnv(2, episode_duration=1.0, max_episode_steps=50).config.max_steps == 5
    with pytest.raises(ValueError, match="max_episode_steps must be a positive integer, got 0"):
        FormationVectorEnv(2, max_episode_steps=0)


# --- the native vector env is SyncVectorEnv, exactly --------------------------------------------

SHORT = {"episode_duration": 2.0, "n_obstacles": 2}


def _assert_same_infos(mine, ref, path="infos"):
    assert sorted(mine) == sorted(ref), path
    for k, v in ref.items():
        w = mine[k]
        if isinstance(v, dict):
            _assert_same_infos(w, v, f"{path}[{k!r}]")
            continue
        assert isinstance(w, np.ndarray), f"{path}[{k!r}]"
        assert (w.dtype, w.shape) == (v.dtype, v.shape), f"{path}[{k!r}]"
        if v.dtype == object:
            for a, b in zip(w, v, strict=True):
                assert (a is None) == (b is None), f"{path}[{k!r}]"
                if b is not None:
                    assert a.dtype == b.dtype
                    np.testing.assert_array_equal(a, b)
        elif v.dtype.kind == "f":
            np.testing.assert_allclose(w, v, rtol=0, atol=1e-12, err_msg=f"{path}[{k!r}]")
        else:
            np.testing.assert_array_equal(w, v, err_msg=f"{path}[{k!r}]")


@pytest.mark.parametrize("mode", list(AutoresetMode))
def test_vector_env_matches_sync_vector_env(mode):
    n = 3
    mine = FormationVectorEnv(n, autoreset_mode=mode, **SHORT)
    ref = SyncVectorEnv([lambda: FormationEnv(**SHORT) for _ in range(n)], autoreset_mode=mode)
    o1, i1 = mine.reset(seed=7)
    o2, i2 = ref.reset(seed=7)
    np.testing.assert_array_equal(o1, o2)
    _assert_same_infos(i1, i2)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(35):
        act = rng.uniform(-1.2, 1.2, size=mine.action_space.shape).astype(np.float32)
        r1, r2 = mine.step(act), ref.step(act)
        np.testing.assert_array_equal(r1[0], r2[0])
        np.testing.assert_allclose(r1[1], r2[1], rtol=0, atol=1e-12)
        np.testing.assert_array_equal(r1[2], r2[2])
        np.testing.assert_array_equal(r1[3], r2[3])
        _assert_same_infos(r1[4], r2[4])
        done = r1[2] | r1[3]
        ended += int(done.sum())
        if mode == AutoresetMode.DISABLED and done.any():
            o1, i1 = mine.reset(options={"reset_mask": done})
            o2, i2 = ref.reset(options={"reset_mask": done})
            np.testing.assert_array_equal(o1, o2)
            _assert_same_infos(i1, i2)
    assert ended >= 2 * n  # every mode went through autoresets


def test_same_step_infos_no_stray_keys():
    vec = FormationVectorEnv(2, autoreset_mode="SameStep", **SHORT)
    vec.reset(seed=0)
    for _ in range(20):
        _, _, term, trunc, info = vec.step(np.zeros(vec.action_space.shape, np.float32))
        if (term | trunc).any():
            break
    assert "_final_obs" not in info["final_info"]
    assert info["final_obs"].dtype == object
    assert "reward_terms" not in info  # flat keys: TorchRL batches nested dicts badly
    assert {"reward_" + k for k in REWARD_TERMS} <= set(info["final_info"])


def test_unknown_keyword_uses_pythons_wording():
    """TorchRL drops ``frameskip`` only on "unexpected keyword argument 'frameskip'"."""
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'"):
        gymnasium.make("uasep/Formation-v3", frameskip=1)
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'noise\.acel_std'"):
        uasep_env.parallel_env(noise={"acel_std": 1.0})
