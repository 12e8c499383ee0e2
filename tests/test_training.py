"""The shipped PPO recipe learns, with the default reward, and its artefacts round-trip."""

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "train"))

import ppo_shared

from uasep_env.policies import RandomPolicy, ZeroPolicy, load_policy
from uasep_env.rollout import run_episodes

# Formation keeping without obstacles, short episodes; every reward weight at its default.
REDUCED = dict(
    scenario="crossing", n_uavs=2, n_obstacles=0, episode_duration=30.0,
    n_envs=16, n_steps=64, batch_size=512, n_epochs=5, learning_rate=1e-3, gamma=0.95,
    log_std_init=-0.5, hidden="64,64", progress=False,
)  # fmt: skip


def _rms_deviation(policy, cfg, seeds, no_collision=False):
    episodes = run_episodes(policy, cfg, seeds)
    if no_collision:  # learned by flying, not by ending episodes early
        assert not any(e.terminated for e in episodes)
    return float(
        np.mean(
            [
                np.sqrt(np.mean(np.sum((e.record.uav_pos - e.record.planned_pos) ** 2, -1)))
                for e in episodes
            ]
        )
    )


@pytest.mark.slow
def test_recipe_learns_formation_keeping(tmp_path):
    import torch

    torch.set_num_threads(1)
    args = ppo_shared.Args(**REDUCED, out_dir=str(tmp_path))
    cfg = ppo_shared.make_env_config(args)
    venv, model = ppo_shared.build(args, cfg)
    model.learn(300_000)
    path = ppo_shared.export_policy(model, venv, cfg, args, tmp_path / "policy.zip", {})
    learned = load_policy(path, cfg)

    seeds = list(range(4_000_000, 4_000_016))  # validation seeds, never trained on
    trained = _rms_deviation(learned, cfg, seeds, no_collision=True)
    random = _rms_deviation(RandomPolicy(cfg, seed=0), cfg, seeds)
    zero = _rms_deviation(ZeroPolicy(cfg), cfg, seeds)
    assert trained < 0.4 * random and trained < 0.5 * zero, (trained, random, zero)


def test_checkpoint_resume_restores_the_run(tmp_path):
    import torch

    torch.set_num_threads(1)
    args = ppo_shared.Args(**{**REDUCED, "n_envs": 4, "n_steps": 32, "batch_size": 64},
                           out_dir=str(tmp_path))  # fmt: skip
    cfg = ppo_shared.make_env_config(args)
    venv, model = ppo_shared.build(args, cfg)
    model.learn(1024)
    info = {"agent_steps": int(model.num_timesteps), "wall_s": 1.0}
    ppo_shared.save_checkpoint(model, venv, cfg, args, tmp_path / "ck", info)

    venv2, model2 = ppo_shared.build(args, cfg)
    restored = ppo_shared.load_checkpoint(model2, venv2, tmp_path / "ck")
    assert model2.num_timesteps == model.num_timesteps == restored["agent_steps"]
    np.testing.assert_array_equal(venv2.obs_rms.mean, venv.obs_rms.mean)
    obs = np.random.default_rng(0).normal(size=(8, venv.observation_space.shape[0]))
    a1, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    a2, _ = model2.predict(venv2.normalize_obs(obs), deterministic=True)
    np.testing.assert_array_equal(a1, a2)
    # The exported policy is the same actor, in numpy.
    policy = load_policy(tmp_path / "ck" / "policy.zip", cfg)
    np.testing.assert_allclose(policy(obs.astype(np.float32)), np.clip(a1, -1, 1), atol=1e-5)


def test_training_rejects_seeds_of_the_held_out_bank(tmp_path):
    args = ppo_shared.Args(**{**REDUCED, "seed": 5_000_000}, out_dir=str(tmp_path))
    with pytest.raises(ValueError, match="disjoint from the held-out bank"):
        ppo_shared.build(args, ppo_shared.make_env_config(args))
