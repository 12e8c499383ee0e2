"""The share of the machine's cores this process may use, decided once per process.

The compiled kernels' loops and the noise-drawing threads size themselves from it, so that
``N`` processes started side by side (``uasep-eval --workers N``, ``train/seeds.py
--parallel N``, a user's own pool) never ask for more threads than there are cores: each
takes its affinity mask's cores divided by ``UASEP_WORKERS``. ``UASEP_THREADS`` sets it
outright. This module imports nothing of the package (the kernels read it too).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping

__all__ = [
    "PARALLEL_MIN_THREADS",
    "PARALLEL_MIN_THREADS_OTHER",
    "THREADS_VARIABLE",
    "WORKERS_VARIABLE",
    "check_variables",
    "core_share",
    "decide_threads",
    "explicit_threads",
    "kernel_threads",
    "process_share",
]

#: The fewest threads the compiled loops run in parallel on by default, by numba's threading
#: layer. OpenMP's threads wait asleep (:func:`uasep_env._numba.kernels` starts them with
#: ``OMP_WAIT_POLICY=PASSIVE``): two of them pay on a 2-core machine at 4096 environments,
#: and processes sharing the cores lose little to them; spinning as they did by default,
#: two processes of two threads each lost half their throughput. numba's own ``workqueue``
#: layer (no OpenMP runtime) gained nothing with two threads, nor is any other measured:
#: four there (``benchmarks/bench_threads.py``, ``docs/speed.md``).
PARALLEL_MIN_THREADS = {"omp": 2}
#: :data:`PARALLEL_MIN_THREADS` of the layers it does not name.
PARALLEL_MIN_THREADS_OTHER = 4
#: ``UASEP_THREADS=N``: the threads of this process (the user's choice wins).
THREADS_VARIABLE = "UASEP_THREADS"
#: ``UASEP_WORKERS=N``: set by the project's tools in the ``N`` processes they start side by
#: side, which share the cores the machine gives them.
WORKERS_VARIABLE = "UASEP_WORKERS"


def _positive_int(name: str, value: str) -> int:
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{name}={value!r}: must be a whole number >= 1")
    return n


def explicit_threads(environ: Mapping[str, str] | None = None) -> int | None:
    """``UASEP_THREADS`` as a number, or None where it is unset or empty.

    Raises:
        ValueError: For a value that is not a whole number >= 1, naming the variable.
    """
    env = os.environ if environ is None else environ
    value = env.get(THREADS_VARIABLE, "").strip()
    return _positive_int(THREADS_VARIABLE, value) if value else None


def check_variables(environ: Mapping[str, str] | None = None) -> None:
    """Check ``UASEP_THREADS`` and ``UASEP_WORKERS`` up front (a command's first step).

    Both are read only when the first kernel runs, deep in a run; a command checks them at
    its start so that a bad value is one line, not a traceback from inside the kernels.

    Raises:
        ValueError: For a set variable that is not a whole number >= 1, naming it.
    """
    env = os.environ if environ is None else environ
    explicit_threads(env)
    workers = env.get(WORKERS_VARIABLE, "").strip()
    if workers:
        _positive_int(WORKERS_VARIABLE, workers)


def core_share(environ: Mapping[str, str] | None = None, cores: int | None = None) -> int:
    """The threads this process may use: ``UASEP_THREADS``, else its share of the cores.

    Args:
        environ: The environment variables (default ``os.environ``).
        cores: The cores this process may run on (default: its affinity mask).

    Returns:
        ``UASEP_THREADS`` if set; else the cores divided among the ``UASEP_WORKERS``
        processes started side by side (1 if unset), at least 1.

    Raises:
        ValueError: For a variable that is not a whole number >= 1, naming it.
    """
    env = os.environ if environ is None else environ
    explicit = explicit_threads(env)
    if explicit is not None:
        return explicit
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
    workers = env.get(WORKERS_VARIABLE, "").strip()
    return max(1, cores // _positive_int(WORKERS_VARIABLE, workers) if workers else cores)


@functools.cache
def process_share() -> int:
    """:func:`core_share` of this process, decided on first use."""
    return core_share()


def decide_threads(
    environ: Mapping[str, str] | None = None, cores: int | None = None, layer: str = "omp"
) -> int:
    """The threads of this process's compiled loops (1: the serial loops).

    ``UASEP_THREADS`` if set (the user's choice); else this process's share of the cores
    (:func:`core_share`), or 1 where that share is under ``layer``'s
    :data:`PARALLEL_MIN_THREADS`.

    Args:
        environ: The environment variables (default ``os.environ``).
        cores: The cores this process may run on (default: its affinity mask).
        layer: numba's threading layer (``numba.threading_layer()``).
    """
    share = core_share(environ, cores)
    chosen = explicit_threads(environ) is not None
    least = PARALLEL_MIN_THREADS.get(layer, PARALLEL_MIN_THREADS_OTHER)
    return share if chosen or share >= least else 1


@functools.cache
def kernel_threads(layer: str = "omp") -> int:
    """:func:`decide_threads` of this process with numba's threading ``layer``, decided once."""
    return decide_threads(layer=layer)
