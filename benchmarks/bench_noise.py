"""The noise refill: numpy's per-environment draws against their compiled twin, in one run.

Usage::

    python benchmarks/bench_noise.py [--envs 4096] [--rounds 5]

Refills one block of noise (64 physics steps: 33 Gaussian and 4 uniform columns, the
default formation's) for every one of ``--envs`` environments, as
:meth:`uasep_env.sim.noise.NoiseStreams._refill` does when their blocks run out together, with
the numpy reference (:func:`uasep_env.sim.noise.refill_noise` ``.reference``: a
``standard_normal`` and a ``random`` call per environment) and with the compiled twin
(:mod:`uasep_env._kernels.noise`), alternately, on one thread. Prints the best milliseconds
of each, the ratio, and whether both gave the same numbers and generator states. Needs
numba (``pip install -e ".[fast]"``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uasep_env import _numba
from uasep_env.sim.noise import refill_noise

BLOCK, N_NORMAL, N_UNIFORM = 64, 33, 4


def _run(fn: object, envs: int, rounds: int) -> tuple[list[float], np.ndarray, list]:
    """Best-of timing of ``rounds`` full refills; the last buffers and generators."""
    rngs = [np.random.default_rng(i) for i in range(envs)]
    std = np.random.default_rng(9).uniform(0.1, 2.0, N_NORMAL)
    normal_buf = np.zeros((BLOCK, envs, N_NORMAL))
    unif_buf = np.zeros((BLOCK, envs, N_UNIFORM))
    rows = np.arange(envs)
    fn(rngs, rows, std, normal_buf, unif_buf)  # compile or load; the generators' addresses
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        fn(rngs, rows, std, normal_buf, unif_buf)
        times.append(time.perf_counter() - start)
    return times, np.concatenate([normal_buf.ravel(), unif_buf.ravel()]), rngs


def main() -> None:
    """Time both forms and print the figures and the ratio."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--rounds", type=int, default=5, help="refills timed per form and pair")
    args = p.parse_args()
    if not _numba.available():
        raise SystemExit("numba is not in use: nothing to compare")
    best = {"numpy": [], "compiled": []}
    out = {}
    for _ in range(2):  # alternate, so that the machine's drift touches both
        for name, fn in (("numpy", refill_noise.reference), ("compiled", refill_noise)):
            times, out[name], rngs = _run(fn, args.envs, args.rounds)
            best[name].append(min(times))
            out[name + " states"] = [g.bit_generator.state for g in rngs]
    numpy_ms, compiled_ms = min(best["numpy"]) * 1e3, min(best["compiled"]) * 1e3
    same = np.array_equal(out["numpy"], out["compiled"])
    same &= out["numpy states"] == out["compiled states"]
    print(f"{args.envs} environments, one block of {BLOCK} steps each, one thread")
    print(f"numpy reference: {numpy_ms:8.1f} ms a refill (best)")
    print(f"compiled twin:   {compiled_ms:8.1f} ms a refill (best)")
    ratio = numpy_ms / compiled_ms
    print(f"ratio numpy / compiled: {ratio:.2f}x; the same numbers and states: {same}")


if __name__ == "__main__":
    main()
