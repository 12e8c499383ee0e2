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

    env = GymEnv("uasep/Formation-v3", **SHORT)  # TorchRL passes frameskip: a TypeError
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
    env = GymEnv("uasep_env:uasep/Formation-v3", num_envs=2, **SHORT)
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

    vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=2, autoreset_mode="SameStep", **SHORT)
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


# --- A CleanRL-style PPO loop on the native vector env (issue 23) ------------------------------


def test_cleanrl_style_ppo_on_make_vec():
    """CleanRL's ppo_continuous_action loop, on gymnasium.make_vec and its vector wrappers."""
    torch = _need("torch")
    import gymnasium
    from gymnasium.wrappers import vector as vw
    from torch import nn

    n_envs, n_steps, gamma, lam, clip = 2, 64, 0.99, 0.95, 0.2
    envs = gymnasium.make_vec("uasep/Formation-v3", num_envs=n_envs, **SHORT)
    envs = vw.RecordEpisodeStatistics(envs)
    envs = vw.ClipAction(envs)
    envs = vw.NormalizeObservation(envs)
    envs = vw.NormalizeReward(envs, gamma=gamma)
    obs_dim = envs.single_observation_space.shape[0]
    act_dim = envs.single_action_space.shape[0]
    torch.manual_seed(0)
    critic = nn.Sequential(nn.Linear(obs_dim, 64), nn.Tanh(), nn.Linear(64, 1))
    actor = nn.Sequential(nn.Linear(obs_dim, 64), nn.Tanh(), nn.Linear(64, act_dim))
    log_std = nn.Parameter(torch.zeros(1, act_dim))
    params = [*critic.parameters(), *actor.parameters(), log_std]
    optimizer = torch.optim.Adam(params, lr=3e-4, eps=1e-5)
    before = [p.detach().clone() for p in params]

    def dist(x):
        return torch.distributions.Normal(actor(x), log_std.expand(len(x), -1).exp())

    obs_np, _ = envs.reset(seed=0)
    next_obs, next_done = torch.as_tensor(obs_np), torch.zeros(n_envs)
    episodes = 0
    for _ in range(2):  # iterations
        buf = {k: [] for k in ("obs", "act", "logp", "rew", "done", "val")}
        for _ in range(n_steps):
            with torch.no_grad():
                d = dist(next_obs)
                action = d.sample()
                buf["logp"].append(d.log_prob(action).sum(-1))
                buf["val"].append(critic(next_obs).squeeze(-1))
            buf["obs"].append(next_obs)
            buf["act"].append(action)
            buf["done"].append(next_done)
            obs_np, reward, term, trunc, infos = envs.step(action.numpy())
            buf["rew"].append(torch.as_tensor(reward, dtype=torch.float32))
            next_obs = torch.as_tensor(obs_np)
            next_done = torch.as_tensor(np.logical_or(term, trunc), dtype=torch.float32)
            if "episode" in infos:
                episodes += int(infos["_episode"].sum())
        b = {k: torch.stack(v) for k, v in buf.items()}
        with torch.no_grad():
            next_value = critic(next_obs).squeeze(-1)
        adv = torch.zeros_like(b["rew"])
        last = torch.zeros(n_envs)
        for t in reversed(range(n_steps)):
            nonterminal = 1.0 - (next_done if t == n_steps - 1 else b["done"][t + 1])
            value_next = next_value if t == n_steps - 1 else b["val"][t + 1]
            delta = b["rew"][t] + gamma * value_next * nonterminal - b["val"][t]
            adv[t] = last = delta + gamma * lam * nonterminal * last
        ret = adv + b["val"]
        flat = {k: v.reshape(n_steps * n_envs, *v.shape[2:]) for k, v in b.items()}
        adv, ret = adv.reshape(-1), ret.reshape(-1)
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        ratio = (dist(flat["obs"]).log_prob(flat["act"]).sum(-1) - flat["logp"]).exp()
        pg_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1 - clip, 1 + clip)).mean()
        v_loss = 0.5 * ((critic(flat["obs"]).squeeze(-1) - ret) ** 2).mean()
        loss = pg_loss + 0.5 * v_loss
        optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(params, 0.5)
        optimizer.step()
        assert torch.isfinite(loss)
    envs.close()
    assert episodes >= 4  # 50-step episodes, 128 steps in each of 2 envs: RecordEpisodeStatistics
    assert all(not torch.equal(a, p.detach()) for a, p in zip(before, params, strict=True))


# --- SB3 off-policy on the shared adapter, SubprocVecEnv with spawn (issue 23) ------------------


def test_sb3_sac_on_the_shared_adapter():
    sb3 = _need("stable_baselines3")
    from stable_baselines3.common.evaluation import evaluate_policy

    from uasep_env.envs.sb3 import UAVSharedVecEnv

    venv = UAVSharedVecEnv(n_envs=2, seed=0, **SHORT)  # 6 UAVs, one shared SAC policy
    model = sb3.SAC(
        "MlpPolicy", venv, learning_starts=30, batch_size=32, buffer_size=1000, seed=0, device="cpu"
    )
    model.learn(total_timesteps=330)  # 55 steps of 6 UAVs: crosses the episode end (50)
    assert model.num_timesteps >= 330 and model.replay_buffer.size() > 0
    mean, _ = evaluate_policy(model, venv, n_eval_episodes=6)
    assert np.isfinite(mean)


def test_sb3_subproc_vec_env_spawn():
    """make_vec_env with SubprocVecEnv(start_method="spawn"): the workers import the package
    (registering the ids) from the id's "module:" prefix."""
    sb3 = _need("stable_baselines3")
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    venv = make_vec_env(
        "uasep_env:uasep/PaperEncounter-v3",
        n_envs=2,
        seed=0,
        env_kwargs=SHORT,
        vec_env_cls=SubprocVecEnv,
        vec_env_kwargs={"start_method": "spawn"},
    )
    try:
        model = sb3.PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, device="cpu")
        model.learn(128)
        assert model.num_timesteps >= 128
        assert len(model.ep_info_buffer) >= 2  # episodes of 50 steps finished in the workers
    finally:
        venv.close()
