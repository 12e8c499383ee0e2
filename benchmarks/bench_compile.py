"""Time spent waiting for numba's compiler, from an empty cache, in fresh processes.

Usage::

    python benchmarks/bench_compile.py [--against /path/to/other/checkout] [--repeat 2]

Each case runs in a new Python process with an empty ``NUMBA_CACHE_DIR`` (a fresh
installation: every kernel it uses compiles), importing this checkout, and is timed from
start to exit:

* ``eval``: ``uasep-eval --policy apf --scenario paper --episodes 1 --seed 0``, what
  ``make eval`` runs (import, compile, one APF episode, the metrics printed);
* ``precompile``: ``python -m uasep_env.precompile``, what ``make`` runs at install time;
* ``vector``: ``gymnasium.make_vec("uasep/Formation-v3", num_envs=4096)``, reset, one
  step with random actions (a training's first step).

With ``--against`` each case runs under both checkouts in turn, side by side in one run,
and the ratios (``against`` / this) are printed: above 1, this checkout waits less. The
machine's load moves absolute figures; compare the ratios. Needs numba
(``pip install -e ".[fast]"``).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

EVAL_ARGS = ["--policy", "apf", "--scenario", "paper", "--episodes", "1", "--seed", "0"]
CASES = {
    "eval": [
        "-c",
        f"import sys; from uasep_env.evaluation import main; sys.exit(main({EVAL_ARGS!r}))",
    ],
    "precompile": ["-m", "uasep_env.precompile"],
    "vector": [
        "-c",
        "import gymnasium, numpy as np, uasep_env\n"
        "vec = gymnasium.make_vec('uasep/Formation-v3', num_envs=4096)\n"
        "vec.reset(seed=0)\n"
        "rng = np.random.default_rng(0)\n"
        "vec.step(rng.uniform(-1, 1, vec.action_space.shape).astype(np.float32))\n",
    ],
}


def run_case(case: str, checkout: Path) -> float:
    """Seconds of ``case`` in a fresh process importing ``checkout``, from an empty cache."""
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as cache:
        env = dict(os.environ, PYTHONPATH=str(checkout), NUMBA_CACHE_DIR=cache, MPLBACKEND="Agg")
        env.pop("UASEP_NUMBA", None)
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, *CASES[case]],
            cwd=cache,  # not a checkout: the import comes from PYTHONPATH
            env=env,
            capture_output=True,
            text=True,
        )
        seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{case} under {checkout} failed:\n{done.stderr[-2000:]}")
    return seconds


def main() -> None:
    """Run the cases (under both checkouts with ``--against``) and print seconds and ratios."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", type=Path, help="another checkout to compare with")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each case")
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error(f"--repeat {args.repeat}: must be >= 1")
    trees = {"this": ROOT}
    if args.against is not None:
        trees = {"against": args.against.resolve(), "this": ROOT}
    for name, path in trees.items():
        print(f"{name}: {path}")
    print(f"{'case':<12} {'run':>3} " + " ".join(f"{n + ' (s)':>12}" for n in trees), end="")
    print(f" {'against/this':>13}" if len(trees) == 2 else "")
    for case in args.cases:
        for k in range(args.repeat):
            times = {name: run_case(case, path) for name, path in trees.items()}
            line = f"{case:<12} {k + 1:>3} " + " ".join(f"{t:>12.1f}" for t in times.values())
            if len(trees) == 2:
                line += f" {times['against'] / times['this']:>12.2f}x"
            print(line, flush=True)


if __name__ == "__main__":
    main()
