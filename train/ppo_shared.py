"""Train one PPO policy shared by every UAV (parameter sharing), then compare it with the APF.

A single-file script in the CleanRL style: every option is a field of :class:`Args`.

    python train/ppo_shared.py --total-timesteps 2000000 --n-envs 64 --scenario random

Each UAV of each of ``n_envs`` batched environments is one SB3 sub-environment
(:class:`uasep_env.envs.sb3.UAVSharedVecEnv`). After training, the model is saved and
evaluated against the APF on the same seeded encounters with :mod:`uasep_env.rollout` and
:mod:`uasep_env.metrics`; the summary is printed. Requires the ``train`` extra (install
``torch==2.13.0`` first).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass
class Args:
    """Command-line options (``--total-timesteps``, ``--n-envs``, ...)."""

    scenario: str = "random"
    n_uavs: int = 3
    n_obstacles: int = 1
    episode_duration: float = 120.0  # s
    total_timesteps: int = 500_000  # agent-steps
    n_envs: int = 32
    n_steps: int = 128  # rollout length per sub-environment
    batch_size: int = 4096
    learning_rate: float = 3e-4
    gamma: float = 0.99
    seed: int = 0
    eval_episodes: int = 20
    out_dir: str = "runs/ppo_shared"
    tensorboard: bool = False
    torch_threads: int = 1


def parse_args(argv: list[str] | None = None) -> Args:
    """Build :class:`Args` from the command line (one ``--kebab-case`` flag per field)."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        if f.type in ("bool", bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default)
        else:
            cast = {"int": int, "float": float, "str": str}[str(f.type)]
            parser.add_argument(flag, type=cast, default=f.default)
    return Args(**vars(parser.parse_args(argv)))


def main(argv: list[str] | None = None) -> dict:
    """Train, save, evaluate; returns the evaluation summary."""
    args = parse_args(argv)
    import torch  # lazy: the training extra
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from uasep_env import make_config
    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.metrics import aggregate, episode_metrics
    from uasep_env.policies import APF, SB3Policy
    from uasep_env.rollout import run_episodes

    torch.set_num_threads(args.torch_threads)
    config = make_config(
        scenario=args.scenario,
        n_uavs=args.n_uavs,
        n_obstacles=args.n_obstacles,
        episode_duration=args.episode_duration,
    )
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    venv = VecMonitor(UAVSharedVecEnv(n_envs=args.n_envs, config=config, seed=args.seed))
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        learning_rate=args.learning_rate,
        gamma=args.gamma,
        seed=args.seed,
        device="cpu",
        verbose=1,
        tensorboard_log=str(out / "tb") if args.tensorboard else None,
    )
    start = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, progress_bar=False)
    train_s = time.perf_counter() - start
    model.save(out / "model.zip")

    seeds = list(range(10_000, 10_000 + args.eval_episodes))  # held-out encounters
    summary: dict = {"config": config.to_dict(), "train_seconds": train_s, "policies": {}}
    for name, policy in (("ppo", SB3Policy(model, config)), ("apf", APF(config))):
        episodes = run_episodes(policy, config, seeds)
        agg = aggregate([episode_metrics(e.record) for e in episodes])
        summary["policies"][name] = {
            k: agg[k]["mean"] if "mean" in agg[k] else agg[k].get("rate")
            for k in (
                "episode.min_uav_separation",
                "episode.min_obstacle_distance",
                "episode.collision",
                "episode.loss_of_separation",
                "episode.max_deviation",
            )
            if k in agg
        }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    print(json.dumps(summary["policies"], indent=2, default=str))
    return summary


if __name__ == "__main__":
    main()
