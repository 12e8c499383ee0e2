"""Threads of the compiled kernels: one process and two side by side, measured in one run.

Usage::

    python benchmarks/bench_threads.py [--envs 4096] [--seconds 10] [--actions zero]

Steps the native vector env (``gymnasium.make_vec("uasep/Formation-v3")``, 3 UAVs, one
obstacle) in fresh processes and prints agent-steps/s for

* one process, threads decided by the package (``UASEP_THREADS``/``UASEP_WORKERS`` unset);
* one process with the serial loops (``UASEP_THREADS=1``);
* two processes side by side, as ``train/seeds.py --parallel 2`` and ``uasep-eval --workers 2``
  start them (``UASEP_WORKERS=2``: each takes its share of the cores);
* two processes side by side, each with the parallel loops on every core (``UASEP_THREADS``
  = the cores: two scripts started by hand, oversubscribing the cores);

then the ratios: the package's choice against the serial loops alone, and the processes
that share the cores against those that oversubscribe them.
Needs numba (``pip install -e ".[fast]"``); each process compiles or loads the kernels first
(not timed).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _worker(envs: int, seconds: float, actions: str) -> None:
    """In a child: agent-steps/s of the vector env, printed as JSON on the last line."""
    import gymnasium
    import numpy as np

    import uasep_env  # noqa: F401  (registers the ids)
    from uasep_env import _numba

    vec = gymnasium.make_vec("uasep/Formation-v3", num_envs=envs)
    vec.reset(seed=0)
    rng = np.random.default_rng(0)
    shape = vec.action_space.shape
    zero = np.zeros(shape, dtype=np.float32)

    def act() -> np.ndarray:
        return zero if actions == "zero" else rng.uniform(-1, 1, shape).astype(np.float32)

    for _ in range(20):  # compile or load the kernels, fill the caches
        vec.step(act())
    steps, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        vec.step(act())
        steps += 1
    n_uavs = shape[1] // 3  # (envs, 3 * n_uavs): one 3-axis command per UAV
    threads = _numba.kernels().common.THREADS[0] if _numba.available() else 0
    print(json.dumps({"rate": steps * envs * n_uavs / elapsed, "threads": threads}))


def _run(n: int, env: dict[str, str], args: argparse.Namespace) -> list[dict]:
    """``n`` worker processes started together; their results."""
    cmd = [sys.executable, __file__, "--worker", "--envs", str(args.envs)]
    cmd += ["--seconds", str(args.seconds), "--actions", args.actions]
    full = dict(os.environ, PYTHONPATH=str(ROOT), **env)
    procs = [subprocess.Popen(cmd, env=full, stdout=subprocess.PIPE, text=True) for _ in range(n)]
    out = []
    for p in procs:
        stdout, _ = p.communicate()
        if p.returncode != 0:
            raise SystemExit(f"a worker failed (exit {p.returncode})")
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def main() -> None:
    """Run the four cases and print the rates and ratios."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--envs", type=int, default=4096, help="environments per process")
    p.add_argument("--seconds", type=float, default=10.0, help="timed seconds per process")
    p.add_argument("--actions", choices=("zero", "random"), default="zero")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        _worker(args.envs, args.seconds, args.actions)
        return
    cores = str(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    clean = {"UASEP_THREADS": "", "UASEP_WORKERS": ""}
    cases = {
        "one process, package's choice": (1, clean),
        "one process, serial loops": (1, {**clean, "UASEP_THREADS": "1"}),
        "two side by side, package's choice": (2, {**clean, "UASEP_WORKERS": "2"}),
        f"two side by side, parallel loops on {cores} cores each": (
            2,
            {**clean, "UASEP_THREADS": cores},
        ),
    }
    rates = {}
    print(f"{args.envs} envs per process, {args.actions} actions, {cores} cores")
    for name, (n, env) in cases.items():
        res = _run(n, env, args)
        rates[name] = [r["rate"] for r in res]
        each = ", ".join(f"{r['rate'] / 1e6:.3f}M ({r['threads']} threads)" for r in res)
        print(f"{name:<52} agent-steps/s per process: {each}")
    names = list(rates)

    def mean(k: int) -> float:
        return sum(rates[names[k]]) / len(rates[names[k]])

    print(f"ratio alone, package's choice / serial loops:          {mean(0) / mean(1):.2f}x")
    print(f"ratio side by side, shared cores / oversubscribed:     {mean(2) / mean(3):.2f}x")


if __name__ == "__main__":
    main()
