"""Soak test: many steps of a PettingZoo env and a vector env; memory must stay flat.

Usage: python benchmarks/soak.py [--steps 20000] [--vec-steps 2000] [--num-envs 256]
       [--max-growth-mib 64] [--seed 0]

Steps a PettingZoo env (``--steps`` steps) and a Gymnasium vector env of ``--num-envs``
environments (``--vec-steps`` steps), half of the time with random actions in ``[-1.2, 1.2]``
(so that clipping is exercised) and half with the APF policy, resetting at episode ends
(the vector env autoresets). Resident memory is sampled every 10 % of each run, after a
warm-up tenth. Exits non-zero on growth beyond ``--max-growth-mib`` from the first sample
after the warm-up, on any NaN or infinity in observations or rewards, or on any exception.
Prints its figures.
"""

from __future__ import annotations

import argparse
import gc
import resource
import sys
import time
import traceback
from collections.abc import Callable, Iterator

import numpy as np

import uasep_env
from uasep_env.envs.vector import FormationVectorEnv
from uasep_env.policies import APF


def rss_mib() -> float:
    """Resident set size of this process (MiB), from /proc (peak RSS where unavailable)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        return pages * resource.getpagesize() / 2**20
    except OSError:  # pragma: no cover - not Linux
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _check_finite(what: str, *arrays: np.ndarray) -> None:
    for a in arrays:
        if not np.isfinite(a).all():
            raise FloatingPointError(f"non-finite value in {what}")


def _sampled(steps: int, run: Callable[[int], None]) -> Iterator[tuple[int, float]]:
    """Run ``run(k)`` for each step; yield ``(step, rss)`` at every tenth after the first."""
    tenth = max(1, steps // 10)
    for k in range(steps):
        run(k)
        if (k + 1) % tenth == 0 and k + 1 > tenth:
            gc.collect()
            yield k + 1, rss_mib()


def soak_pettingzoo(steps: int, seed: int) -> tuple[list[tuple[int, float]], dict]:
    """Step the PettingZoo env; returns memory samples and counters."""
    env = uasep_env.parallel_env(scenario="random", n_obstacles=2, episode_duration=60.0)
    apf = APF(env.config)
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    stats = {"episodes": 0, "clipped": 0}

    def step(k: int) -> None:
        nonlocal obs
        if not env.agents:
            obs, _ = env.reset()
            apf.reset()
            stats["episodes"] += 1
        if (k // 500) % 2 == 0:  # alternate blocks of random and APF actions
            acts = {a: rng.uniform(-1.2, 1.2, 3) for a in env.agents}
        else:
            joint = apf(np.stack([obs[a] for a in env.possible_agents]))
            acts = dict(zip(env.possible_agents, joint, strict=True))
        obs, rew, _, _, infos = env.step(acts)
        _check_finite("pettingzoo step", np.stack(list(obs.values())), np.array(list(rew.values())))
        stats["clipped"] += sum(i["clipped_actions"] for i in infos.values())

    return list(_sampled(steps, step)), stats


def soak_vector(steps: int, num_envs: int, seed: int) -> tuple[list[tuple[int, float]], dict]:
    """Step the vector env (NextStep autoreset); returns memory samples and counters."""
    vec = FormationVectorEnv(num_envs, scenario="random", n_obstacles=2, episode_duration=60.0)
    n = vec.config.n_uavs
    apf = APF(vec.config)
    rng = np.random.default_rng(seed)
    obs, _ = vec.reset(seed=seed)
    stats = {"episodes": 0, "clipped": 0}

    def step(k: int) -> None:
        nonlocal obs
        if (k // 100) % 2 == 0:
            act = rng.uniform(-1.2, 1.2, vec.action_space.shape)
        else:
            act = apf(obs.reshape(num_envs, n, -1)).reshape(num_envs, -1)
        obs, rew, term, trunc, info = vec.step(act)
        _check_finite("vector step", obs, rew)
        stats["episodes"] += int((term | trunc).sum())
        # Absent when every environment was reset this step (as in SyncVectorEnv).
        stats["clipped"] += int(info.get("clipped_actions", np.zeros(1)).sum())

    return list(_sampled(steps, step)), stats


def _report(
    name: str, steps: int, samples: list, stats: dict, seconds: float, bound: float
) -> bool:
    rss = [r for _, r in samples]
    growth = rss[-1] - rss[0] if rss else 0.0
    ok = growth <= bound
    print(
        f"{name}: {steps} steps in {seconds:.1f} s, {stats['episodes']} episode ends, "
        f"{stats['clipped']} clipped action components; RSS after warm-up "
        f"{rss[0] if rss else float('nan'):.1f} MiB, last {rss[-1] if rss else float('nan'):.1f}"
        f" MiB, max {max(rss, default=float('nan')):.1f} MiB, growth {growth:+.1f} MiB "
        f"(bound {bound:g}) -> {'ok' if ok else 'FAIL'}"
    )
    return ok


def main(argv: list[str] | None = None) -> int:
    """Run both soaks; 0 when memory stayed within the bound and nothing failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="PettingZoo steps")
    parser.add_argument("--vec-steps", type=int, default=2_000, help="vector env steps")
    parser.add_argument("--num-envs", type=int, default=256, help="environments of the vector env")
    parser.add_argument("--max-growth-mib", type=float, default=64.0, help="allowed RSS growth")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if min(args.steps, args.vec_steps, args.num_envs) < 20:
        parser.error("--steps, --vec-steps and --num-envs must be >= 20")
    ok = True
    try:
        t = time.perf_counter()
        samples, stats = soak_pettingzoo(args.steps, args.seed)
        ok &= _report(
            "pettingzoo", args.steps, samples, stats, time.perf_counter() - t, args.max_growth_mib
        )
        t = time.perf_counter()
        samples, stats = soak_vector(args.vec_steps, args.num_envs, args.seed)
        ok &= _report(
            f"vector x{args.num_envs}",
            args.vec_steps,
            samples,
            stats,
            time.perf_counter() - t,
            args.max_growth_mib,
        )
    except Exception:
        traceback.print_exc()
        print("soak: FAIL (exception)")
        return 1
    print("soak: ok" if ok else "soak: FAIL (memory growth)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
