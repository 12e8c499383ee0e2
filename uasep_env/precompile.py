"""``python -m uasep_env.precompile``: compile the numba kernels at install time.

Plays one episode of the paper's scenario through ``uasep-eval``'s code path
(:func:`uasep_env._numba.warm_up`), so that numba's disk cache holds every kernel such a run
uses and the first real evaluation does not wait on the compiler. Does nothing without
numba (or with ``UASEP_NUMBA=0``).
"""

from __future__ import annotations

from uasep_env import _numba


def main() -> None:
    """Compile (or load) the kernels and say how long it took."""
    seconds = _numba.warm_up()
    status = f"compiled or loaded in {seconds:.1f} s" if _numba.available() else "not in use"
    print(f"uasep-env numba kernels: {status}")


if __name__ == "__main__":
    main()
