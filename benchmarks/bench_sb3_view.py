"""The SB3 view's step, as the residual recipe trains on it (no timed unit tests).

Usage::

    python benchmarks/bench_sb3_view.py [--envs 128] [--steps 2000] [--repeat 6]
        [--against /path/to/other/checkout]

Steps ``UAVSharedVecEnv`` (every UAV of ``--envs`` environments as one SB3 ``VecEnv``) with
the residual recipe's environment (:func:`uasep_env.training.args.make_env_config` of its
defaults) and a fixed pool of uniform random actions, in a fresh process per run, and prints
milliseconds a step. With ``--against`` each run is paired with one of the other
checkout's code (``PYTHONPATH``), one after the other, and the ratio this / against is
printed per pair and as the median: below 1, this checkout steps faster. Pairing keeps the
ratio meaningful on a machine whose speed drifts.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import sys, time
import numpy as np
import uasep_env
from uasep_env.envs.sb3 import UAVSharedVecEnv
from uasep_env.training.args import make_env_config
from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS

envs, steps = int(sys.argv[1]), int(sys.argv[2])
venv = UAVSharedVecEnv(envs, config=make_env_config(RESIDUAL_DEFAULTS), seed=0)
venv.reset()
pool = np.random.default_rng(0).uniform(-1, 1, (64, venv.num_envs, 3)).astype(np.float32)
for i in range(50):  # compile and warm up
    venv.step_async(pool[i % 64])
    venv.step_wait()
start = time.perf_counter()
for i in range(steps):
    venv.step_async(pool[i % 64])
    venv.step_wait()
print((time.perf_counter() - start) / steps * 1e3, uasep_env.__file__)
"""


def run(checkout: Path, envs: int, steps: int) -> float:
    """Milliseconds a step under ``checkout``'s code, in a fresh process."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(envs), str(steps)],
        cwd=checkout,
        env=env,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise SystemExit(f"the run under {checkout} failed:\n{done.stderr[-2000:]}")
    ms, module = done.stdout.split()
    if not Path(module).resolve().is_relative_to(checkout):  # the code measured is theirs
        raise SystemExit(f"the run under {checkout} imported {module}")
    return float(ms)


def main() -> None:
    """Run, pair and print."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=128, help="environments (x3 UAVs: SB3's envs)")
    p.add_argument("--steps", type=int, default=2000, help="timed steps a run")
    p.add_argument("--repeat", type=int, default=6, help="runs (pairs with --against)")
    p.add_argument("--against", type=Path, default=None, help="another checkout")
    a = p.parse_args()
    for name in ("envs", "steps", "repeat"):
        if getattr(a, name) < 1:
            p.error(f"--{name} {getattr(a, name)}: must be >= 1")
    other = a.against.resolve() if a.against is not None else None
    print(f"{a.envs} envs x 3 UAVs, the residual recipe's env, random actions, "
          f"{a.steps} steps a run")  # fmt: skip
    ratios = []
    for k in range(a.repeat):
        this = run(ROOT, a.envs, a.steps)
        line = f"run {k + 1}: this {this:.3f} ms a step"
        if other is not None:
            theirs = run(other, a.envs, a.steps)
            ratios.append(this / theirs)
            line += f", against {theirs:.3f} ms: ratio {ratios[-1]:.3f}"
        print(line, flush=True)
    if ratios:
        print(f"median ratio this / against: {statistics.median(ratios):.3f} "
              f"(min {min(ratios):.3f}, max {max(ratios):.3f})")  # fmt: skip


if __name__ == "__main__":
    main()
