"""Multi-agent PPO with RLlib: every UAV runs one shared policy, on a laptop or a Ray cluster.

The PettingZoo parallel environment, wrapped as RLlib documents it
(:class:`ray.rllib.env.wrappers.pettingzoo_env.ParallelPettingZooEnv`), trained by RLlib's
PPO with one policy (``"shared"``) that every agent maps to (parameter sharing)::

    python train/rllib_ppo.py --iterations 50                 # local Ray, all cores
    python train/rllib_ppo.py --address auto --env-runners 32 # the cluster this node is in
    python train/rllib_ppo.py --address ray://head:10001 ...  # a remote cluster (Ray client)

Every node of a cluster needs this package installed (``pip install -e ".[clients]"``):
the environment runners import it. Checkpoints are RLlib's (``--checkpoint DIR``), one per
``--checkpoint-every`` iterations and one at the end. Needs the ``clients`` extra (Ray
RLlib and torch; install ``torch==2.13.0`` first for the CPU build).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

ENV_NAME = "uasep_formation_v2"
POLICY = "shared"


def env_creator(env_config: dict | None = None) -> Any:
    """The RLlib multi-agent env: ``ParallelPettingZooEnv(parallel_env(**env_config))``."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    import uasep_env

    return ParallelPettingZooEnv(uasep_env.parallel_env(**dict(env_config or {})))


def _shared_policy(agent_id: str, *args: Any, **kwargs: Any) -> str:
    return POLICY


def build_config(
    env_config: dict | None = None,
    *,
    env_runners: int = 0,
    envs_per_runner: int = 1,
    train_batch_size: int = 4000,
    minibatch_size: int = 256,
    epochs: int = 10,
    lr: float = 3e-4,
    seed: int = 0,
) -> Any:
    """The RLlib ``PPOConfig`` of the shared-policy run.

    Args:
        env_config: Keyword arguments of :func:`uasep_env.parallel_env`.
        env_runners: Remote environment runners (0: sample in the driver process).
        envs_per_runner: Environments per runner.
        train_batch_size: Agent steps per training iteration.
        minibatch_size: SGD minibatch size.
        epochs: SGD passes over each batch.
        lr: Learning rate.
        seed: RLlib's seed (runners' environments are seeded from it).

    Returns:
        The config (``.build_algo()`` makes the algorithm).
    """
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    register_env(ENV_NAME, env_creator)
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config=dict(env_config or {}))
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=envs_per_runner)
        .multi_agent(policies={POLICY}, policy_mapping_fn=_shared_policy)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={POLICY: RLModuleSpec()}))
        .training(
            train_batch_size_per_learner=train_batch_size,
            minibatch_size=minibatch_size,
            num_epochs=epochs,
            lr=lr,
        )
        .debugging(seed=seed)
    )


def _metric(result: dict, *path: str) -> float | None:
    node: Any = result
    for key in path:
        if not isinstance(node, dict) or key not in node:
            return None
        node = node[key]
    return float(node) if isinstance(node, (int, float)) else None


def main(argv: list[str] | None = None) -> int:
    """Command line entry point (``python train/rllib_ppo.py --help``)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--address", default=None, help="Ray cluster address (default: local Ray)")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray")
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--env-runners", type=int, default=0)
    p.add_argument("--envs-per-runner", type=int, default=1)
    p.add_argument("--train-batch-size", type=int, default=4000)
    p.add_argument("--minibatch-size", type=int, default=256)
    p.add_argument("--epochs", type=int, default=10)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--config", default="{}", help='env config as JSON, e.g. \'{"scenario": "random"}\''
    )
    p.add_argument("--checkpoint", type=Path, default=None, help="checkpoint directory")
    p.add_argument("--checkpoint-every", type=int, default=10)
    args = p.parse_args(argv)
    try:
        env_config = json.loads(args.config)
    except json.JSONDecodeError as err:
        p.error(f"--config is not JSON: {err}")
    if not isinstance(env_config, dict):
        p.error(f"--config must be a JSON object, got {args.config!r}")

    import ray

    import uasep_env

    uasep_env.parallel_env(**env_config)  # a bad config fails here, not in a runner
    ray.init(address=args.address, num_cpus=args.num_cpus if args.address is None else None)
    try:
        algo = build_config(
            env_config,
            env_runners=args.env_runners,
            envs_per_runner=args.envs_per_runner,
            train_batch_size=args.train_batch_size,
            minibatch_size=args.minibatch_size,
            epochs=args.epochs,
            lr=args.lr,
            seed=args.seed,
        ).build_algo()
        t0 = time.perf_counter()
        for it in range(1, args.iterations + 1):
            result = algo.train()
            ret = _metric(result, "env_runners", "episode_return_mean")
            steps = _metric(result, "num_env_steps_sampled_lifetime")
            print(
                f"iteration {it}: env steps {steps}, episode return mean {ret}, "
                f"{time.perf_counter() - t0:.0f} s",
                flush=True,
            )
            if args.checkpoint and (it % args.checkpoint_every == 0 or it == args.iterations):
                algo.save_to_path(str(args.checkpoint.resolve()))
        algo.stop()
    finally:
        ray.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
