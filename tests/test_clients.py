"""Clients of the ecosystem, each used the way its documentation wraps an env (issue 12).

Short real runs (a few hundred steps). The heavy clients (TorchRL, Ray RLlib, SuperSuit)
come with the ``clients`` extra, which ``make test`` installs; without it these tests are
skipped, unless ``UASEP_REQUIRE_CLIENTS=1`` (set by ``make test``) makes a missing client a
failure. The README's "Works with" table points here.
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    seed_test,
)

import uasep_env

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"episode_duration": 10.0}  # 50 steps: the runs below cross episode ends


def _need(module: str):
    """Import a client; skip when it is missing, fail instead under ``make test``."""
    if os.environ.get("UASEP_REQUIRE_CLIENTS") == "1":
        return importlib.import_module(module)
    return pytest.importorskip(module, reason="pip install 'uasep-env[clients]'")


# --- PettingZoo's own tests ----------------------------------------------------------------------


def test_pettingzoo_api_test_aec():
    api_test(uasep_env.env(**SHORT), num_cycles=300)


def test_pettingzoo_parallel_api_test():
    parallel_api_test(uasep_env.parallel_env(**SHORT), num_cycles=300)


def test_pettingzoo_max_cycles_test():
    max_cycles_test(uasep_env)


def test_pettingzoo_seed_tests():
    seed_test(lambda: uasep_env.env(**SHORT), num_cycles=100)
    parallel_seed_test(lambda: uasep_env.parallel_env(**SHORT), num_cycles=100)


# --- TorchRL -------------------------------------------------------------------------------------


def test_torchrl_gym_env():
    _need("torchrl")
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv("uasep/Formation-v2", **SHORT)  # TorchRL passes frameskip: a TypeError
    check_env_specs(env)
    td = env.rollout(300, break_when_any_done=False)
    assert td.batch_size == (300,)
    assert td["next", "done"].sum() >= 6  # episodes of at most 50 steps, reset by TorchRL


def test_torchrl_gym_vector_env():
    _need("torchrl")
    from torchrl.envs import GymEnv
    from torchrl.envs.utils import check_env_specs

    # TorchRL steps num_envs copies in subprocesses: the "module:id" form imports
    # uasep_env there (which registers the ids) before gymnasium.make looks the id up.
    env = GymEnv("uasep_env:uasep/Formation-v2", num_envs=2, **SHORT)
    check_env_specs(env)
    td = env.rollout(120, break_when_any_done=False)
    assert td.batch_size == (2, 120)
    assert td["next", "done"].sum() >= 4


def test_torchrl_wraps_the_native_vector_env():
    """TorchRL takes a SameStep (or Disabled) vector env; it failed on the nested infos."""
    _need("torchrl")
    import gymnasium
    from torchrl.envs import GymWrapper
    from torchrl.envs.utils import check_env_specs

    vec = gymnasium.make_vec("uasep/Formation-v2", num_envs=2, autoreset_mode="SameStep", **SHORT)
    env = GymWrapper(vec)
    check_env_specs(env)
    td = env.rollout(120, break_when_any_done=False)
    assert td.batch_size == (2, 120)
    assert td["next", "done"].sum() >= 4


def test_torchrl_pettingzoo_wrapper():
    _need("torchrl")
    from torchrl.envs import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    env = PettingZooWrapper(env=uasep_env.parallel_env(**SHORT), return_state=True)
    check_env_specs(env)
    td = env.rollout(200, break_when_any_done=False)
    assert td.batch_size == (200,)
    group = next(iter(env.group_map))
    assert td["next", group, "observation"].shape[1] == 3  # the three UAVs of the formation


# --- SuperSuit vector wrappers into stable-baselines3 ----------------------------------------


def test_supersuit_vector_wrappers_into_sb3_ppo():
    ss = _need("supersuit")
    from stable_baselines3 import PPO

    venv = ss.pettingzoo_env_to_vec_env_v1(uasep_env.parallel_env(**SHORT))
    venv = ss.concat_vec_envs_v1(venv, 2, num_cpus=0, base_class="stable_baselines3")
    assert venv.num_envs == 6  # 2 formations of 3 UAVs, one shared policy
    # No seed=: SB3 would call venv.seed(), which SuperSuit's ConcatVecEnv (3.11) lacks;
    # venv.reset(seed=...) seeds it.
    model = PPO("MlpPolicy", venv, n_steps=50, batch_size=100, n_epochs=1, device="cpu")
    model.learn(300)
    assert model.num_timesteps >= 300
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (6, 3)


# --- Ray: RLlib multi-agent PPO and uasep-eval --ray -----------------------------------------


@pytest.fixture(scope="module")
def local_ray():
    ray = _need("ray")
    _need("ray.rllib")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.mark.xdist_group("ray")
def test_rllib_multi_agent_ppo_shared_policy(local_ray):
    sys.path.insert(0, str(ROOT / "train"))
    try:
        import rllib_ppo
    finally:
        sys.path.remove(str(ROOT / "train"))
    config = rllib_ppo.build_config(SHORT, train_batch_size=300, minibatch_size=100, epochs=1)
    algo = config.build_algo()
    try:
        result = algo.train()
        assert result["num_env_steps_sampled_lifetime"] >= 100  # 3 agent steps per env step
        module = algo.get_module(rllib_ppo.POLICY)  # the one policy every UAV maps to
        assert module is not None
        assert list(config.policies) == [rllib_ppo.POLICY]
    finally:
        algo.stop()


@pytest.mark.xdist_group("ray")
def test_uasep_eval_on_ray_equals_one_worker(local_ray, tmp_path):
    from uasep_env.evaluation import main

    def run(*extra):
        path = tmp_path / f"r{len(extra)}.json"
        common = ["--policy", "apf,random", "--episodes", "3", "--batch-size", "2"]
        args = [*common, "--config", "episode_duration=12", "--json", str(path), "--quiet"]
        assert main([*args, *extra]) == 0
        import json

        return json.loads(path.read_text())

    one = run("--workers", "1")
    on_ray = run("--ray")
    assert on_ray["settings"]["ray"] == "local"
    assert on_ray["results"] == one["results"]
    assert [e["seed"] for e in on_ray["results"]["random"]["episodes"]] == [0, 1, 2]
    assert np.isfinite(on_ray["results"]["apf"]["aggregate"]["episode.steps"]["mean"])


# --- skrl (reads the observation_spaces / action_spaces dicts) ---------------------------------


def test_skrl_pettingzoo_wrapper():
    _need("skrl")
    import torch
    from skrl.envs.wrappers.torch import wrap_env

    env = wrap_env(uasep_env.parallel_env(**SHORT), wrapper="pettingzoo")
    assert env.possible_agents == ["uav_0", "uav_1", "uav_2"]
    assert env.action_spaces["uav_0"].shape == (3,)
    obs, _ = env.reset()
    ends = 0
    for _ in range(120):
        act = {a: torch.rand((1, 3)) * 2 - 1 for a in env.possible_agents}
        obs, rew, term, trunc, _ = env.step(act)
        assert obs["uav_0"].shape == (1, *env.observation_spaces["uav_0"].shape)
        assert rew["uav_0"].shape == (1, 1)
        if any(bool(t) for t in term.values()) or any(bool(t) for t in trunc.values()):
            ends += 1
            obs, _ = env.reset()  # skrl's trainers reset finished episodes the same way
    assert ends >= 2
