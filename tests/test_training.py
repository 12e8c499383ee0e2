"""A short PPO run through the SB3 adapter learns something measurable."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")


@pytest.mark.slow
def test_ppo_parameter_sharing_reduces_deviation():
    import torch
    from stable_baselines3 import PPO

    from uasep_env import make_config
    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.policies import SB3Policy
    from uasep_env.rollout import run_episodes

    torch.set_num_threads(1)
    weights = dict.fromkeys(
        ("separation_inner", "separation_obstacle", "separation_region", "control"), 0.0
    )
    cfg = make_config(
        n_uavs=2,
        n_obstacles=0,
        scenario="crossing",
        noise=False,
        episode_duration=30.0,
        reward={**weights, "smoothness": 0.0, "collision": 0.0, "deviation": 1.0},
    )
    venv = UAVSharedVecEnv(n_envs=16, config=cfg, seed=0)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=512,
        n_epochs=5,
        learning_rate=1e-3,
        gamma=0.95,
        seed=0,
        device="cpu",
    )
    seeds = list(range(1000, 1016))  # held-out encounters

    def rms_deviation() -> float:
        episodes = run_episodes(SB3Policy(model, cfg), cfg, seeds)
        return float(
            np.mean(
                [
                    np.sqrt(np.mean(np.sum((e.record.uav_pos - e.record.planned_pos) ** 2, -1)))
                    for e in episodes
                ]
            )
        )

    before = rms_deviation()
    model.learn(300_000)
    after = rms_deviation()
    assert after < 0.6 * before, (before, after)
