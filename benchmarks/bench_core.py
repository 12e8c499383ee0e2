"""Core throughput: World.step steps/s at several batch sizes (no timed unit tests).

Usage: python benchmarks/bench_core.py [--sizes 1 4096] [--seconds 3]
Prints env-steps/s and agent-steps/s of the bare batched core (physics, noise, Kalman
filters, reachable-set prediction), with zero actions.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uasep_env import World, make_config


def measure(n_envs: int, seconds: float, config: dict) -> tuple[float, int]:
    """Env-steps/s of ``World.step`` for ``n_envs`` environments."""
    cfg = make_config(**config)
    world = World(cfg, n_envs)
    world.reset(seed=0)
    actions = np.zeros((n_envs, cfg.n_uavs, 3))
    for _ in range(3):
        world.step(actions)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        world.step(actions)
        steps += 1
    return steps * n_envs / (time.perf_counter() - start), cfg.n_uavs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 4096])
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    config = {"n_uavs": 3, "n_obstacles": 1, "scenario": "random", "episode_duration": 1e5}
    print(f"{'n_envs':>8} {'env-steps/s':>14} {'agent-steps/s':>14}")
    for n in args.sizes:
        rate, n_uavs = measure(n, args.seconds, config)
        print(f"{n:>8} {rate:>14,.0f} {rate * n_uavs:>14,.0f}")


if __name__ == "__main__":
    main()
