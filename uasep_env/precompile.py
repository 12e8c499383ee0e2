"""``python -m uasep_env.precompile``: compile the numba kernels at install time.

Plays one episode of the paper's scenario through ``uasep-eval``'s code path
(:func:`warm_up`), so that numba's disk cache holds every kernel such a run uses and the
first real evaluation does not wait on the compiler. Does nothing without numba (or with
``UASEP_NUMBA=0``).
"""

from __future__ import annotations

import time

from uasep_env import _numba


def warm_up() -> float:
    """Compile (or load from the disk cache) the kernels an evaluation uses; the seconds taken.

    Returns 0 without doing anything when compiled kernels are not in use.
    """
    if not _numba.available():
        return 0.0
    from uasep_env.evaluation import evaluate

    t0 = time.perf_counter()
    # A whole episode: some call sites (the metrics' distances) meet new argument types
    # only when the encounter comes. The compiled episode itself takes under a second.
    evaluate(["apf"], {"scenario": "paper"}, [0])
    return time.perf_counter() - t0


def main() -> None:
    """Compile (or load) the kernels and say how long it took."""
    seconds = warm_up()
    status = f"compiled or loaded in {seconds:.1f} s" if _numba.available() else "not in use"
    print(f"uasep-env numba kernels: {status}")


if __name__ == "__main__":
    main()
