"""Episode ends: the vector env with zero and with random actions, side by side in one run.

Usage::

    python benchmarks/bench_resets.py [--envs 4096] [--warmup 300] [--chunk 50] [--rounds 4]

Two native vector envs (``gymnasium.make_vec("uasep/Formation-v3")``, 3 UAVs, one obstacle,
``random`` scenario) in one process: one stepped with zero actions (almost no episode
ends), one with uniform random actions in ``[-1, 1]`` (UAVs get lost: a few of 4096
environments end and are reset every step). Both are first stepped ``--warmup`` steps, so that
the random one's episode ends reach their steady rate, then timed in alternating chunks of
``--chunk`` steps (``--rounds`` of each), so that other work on the machine slows both alike.
Prints agent-steps/s of each, the episode ends per step, the time the random one's steps
spend in the partial resets (``World.reset``, timed around each call), and the ratio
random / zero (the target of issue 30: at least 0.9).
"""

from __future__ import annotations

import argparse
import time

import gymnasium
import numpy as np

import uasep_env  # noqa: F401  (registers the ids)


def timed_resets(vec: object) -> list[float]:
    """Wrap ``vec``'s world's ``reset`` to add the seconds of each call to the returned list."""
    world = vec.unwrapped.core.world  # type: ignore[attr-defined]
    inner, spent = world.reset, [0.0]

    def reset(*args: object, **kwargs: object) -> None:
        start = time.perf_counter()
        try:
            inner(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - start

    world.reset = reset
    return spent


def main() -> None:
    """Step both envs, time them in alternating chunks and print the rates and ratio."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--warmup", type=int, default=300, help="untimed steps of each env first")
    p.add_argument("--chunk", type=int, default=50, help="steps per timed chunk")
    p.add_argument("--rounds", type=int, default=4, help="timed chunks of each env")
    args = p.parse_args()
    rng = np.random.default_rng(0)
    envs, actions = {}, {}
    for mode in ("zero", "random"):
        vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=args.envs)
        vec.reset(seed=0)
        envs[mode] = vec
        shape = vec.action_space.shape
        if mode == "zero":
            zero = np.zeros(shape, dtype=np.float32)
            actions[mode] = lambda zero=zero: zero
        else:
            actions[mode] = lambda shape=shape: rng.uniform(-1, 1, shape).astype(np.float32)
    n_uavs = envs["zero"].action_space.shape[1] // 3
    resets = timed_resets(envs["random"])
    for mode, vec in envs.items():
        for _ in range(args.warmup):
            vec.step(actions[mode]())
    resets[0] = 0.0
    seconds = dict.fromkeys(envs, 0.0)
    ends = dict.fromkeys(envs, 0)
    for _ in range(args.rounds):
        for mode, vec in envs.items():
            act = actions[mode]
            start = time.perf_counter()
            for _ in range(args.chunk):
                _, _, terminated, truncated, _ = vec.step(act())
                ends[mode] += int((terminated | truncated).sum())
            seconds[mode] += time.perf_counter() - start
    steps = args.rounds * args.chunk
    rates = {m: steps * args.envs * n_uavs / s for m, s in seconds.items()}
    print(f"{args.envs} envs, {n_uavs} UAVs, {steps} timed steps of each, alternating chunks")
    for mode in envs:
        print(
            f"{mode:>6} actions: {rates[mode] / 1e6:.3f}M agent-steps/s, "
            f"{1e3 * seconds[mode] / steps:.2f} ms a step, "
            f"{ends[mode] / steps:.2f} episode ends a step"
        )
    print(f"partial resets in the random actions' steps: {1e3 * resets[0] / steps:.2f} ms a step")
    print(f"ratio random / zero: {rates['random'] / rates['zero']:.3f} (target >= 0.9)")


if __name__ == "__main__":
    main()
