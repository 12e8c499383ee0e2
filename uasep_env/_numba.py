"""Optional numba support: the package runs without it, faster with it.

numba is not a dependency (``pip install "uasep-env[fast]"`` adds it). A numpy function that
has a compiled form in :mod:`uasep_env._kernels` is decorated with :func:`compiled_twin`: a
call runs the compiled kernel when numba is in use and the numpy function (the reference)
otherwise, missing numba or with the environment variable ``UASEP_NUMBA=0``. The pairs are
listed in :data:`TWINS`, and ``tests/test_kernels.py`` checks each of them bit for bit.

Compiled kernels are cached on disk (``cache=True``), so only the first run of a new
installation pays the compilation (about 30 s on one core for the kernels an evaluation
uses); ``python -m uasep_env.precompile`` pays it at install time.

This module imports nothing of the package at import time, and :mod:`uasep_env._kernels`
imports nothing of it at all: the constants a kernel shares with its reference are given
to :func:`compiled_twin` by the numpy module that owns them and passed to the kernel as
keyword arguments, so there is no import cycle.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

__all__ = [
    "TWINS",
    "Twin",
    "available",
    "compiled_twin",
    "kernels",
    "note_slow_kernels",
    "start_threads",
]

_state: dict[str, Any] = {}
F = TypeVar("F", bound=Callable[..., Any])


def _numba() -> Any:
    if "numba" not in _state:
        module = None
        if not _disabled():
            try:
                import numba as module
            except ImportError:  # pragma: no cover - depends on the installation
                module = None
        _state["numba"] = module
    return _state["numba"]


def _disabled() -> bool:
    return os.environ.get("UASEP_NUMBA", "1").strip() in {"0", "false", "no", "off"}


#: What :func:`note_slow_kernels` says when numba is not installed.
SLOW_NOTE = (
    "note: numba is not installed, so the environment runs its numpy reference code: the "
    "same numbers, slower (an evaluation takes about twice as long); "
    'pip install "uasep-env[fast]" for the compiled kernels, or set UASEP_NUMBA=0 to '
    "silence this note"
)


def note_slow_kernels(stream: Any = None) -> bool:
    """Say once per process, on stderr, that compiled kernels are missing (a slow run).

    Silent when the kernels are in use, and when the user turned them off (``UASEP_NUMBA=0``:
    their explicit choice needs no note). Command-line tools call it before long work.

    Args:
        stream: Where to write (default ``sys.stderr``).

    Returns:
        Whether the note was written now.
    """
    import sys

    if _state.get("noted") or available() or _disabled():
        return False
    _state["noted"] = True
    print(SLOW_NOTE, file=stream if stream is not None else sys.stderr)
    return True


def available() -> bool:
    """Whether compiled kernels are in use (numba importable and not disabled)."""
    return _numba() is not None


def kernels() -> Any:
    """:mod:`uasep_env._kernels` when compiled kernels are in use, else ``None``.

    Imported once, on first use (importing it imports numba): the hot paths ask every step.
    """
    if _numba() is None:
        return None
    if "kernels" not in _state:
        from uasep_env import _kernels
        from uasep_env.runtime.cores import kernel_threads, process_share

        # numba's pool starts with every core: this process takes its share
        # (uasep_env.runtime.cores).
        numba = _state["numba"]
        threads = min(process_share(), numba.config.NUMBA_NUM_THREADS)
        if threads > 1:
            layer = start_threads(numba, threads)
            threads = min(kernel_threads(layer), numba.config.NUMBA_NUM_THREADS)
        _kernels.common.THREADS[0] = threads
        _state["kernels"] = _kernels
    return _state["kernels"]


#: OpenMP's setting of how its threads wait between parallel loops.
WAIT_POLICY = "OMP_WAIT_POLICY"


def start_threads(numba: Any, threads: int) -> str:
    """Start numba's pool of ``threads`` threads, its OpenMP threads waiting asleep; its layer.

    OpenMP's threads spin while they wait for the next parallel loop unless told otherwise,
    taking the cores from the process's other threads and from other processes: two
    processes of two threads each on a 2-core machine lost half their throughput to it
    (``docs/speed.md``). The runtime reads ``OMP_WAIT_POLICY`` once, when it loads, which
    is here; the variable is set for that moment only (the user's own value is left as it
    is, and other OpenMP runtimes loaded later, torch's, do not see it).

    Args:
        numba: The numba module.
        threads: The threads of the pool.

    Returns:
        numba's threading layer (``"omp"``, ``"tbb"`` or ``"workqueue"``).
    """
    unset = WAIT_POLICY not in os.environ
    if unset:
        os.environ[WAIT_POLICY] = "PASSIVE"
    try:
        numba.set_num_threads(threads)  # loads the threading layer and starts its pool
    finally:
        if unset:
            del os.environ[WAIT_POLICY]
    return numba.threading_layer()


@dataclass(frozen=True, kw_only=True)
class Twin:
    """A numpy reference and the name of its compiled kernel in :mod:`uasep_env._kernels`.

    Attributes:
        kernel: The kernel's name; it takes the reference's arguments plus ``constants``.
        reference: The numpy function (the fallback, and the numbers the kernel must give).
        constants: Keyword arguments the kernel receives from the reference's module.
        dispatch: The public function: the kernel where numba is in use and it takes the
            inputs, else the reference.
    """

    kernel: str
    reference: Callable[..., Any]
    constants: dict[str, Any] = field(default_factory=dict)
    dispatch: Callable[..., Any]

    def compiled(self) -> Callable[..., Any]:
        """What a call runs when numba is in use (imports numba): :attr:`dispatch`.

        The kernel with the constants bound, or the reference where the kernel declines the
        inputs (returns ``NotImplemented``).

        Raises:
            RuntimeError: Where numba is not in use (a call would run the reference).
        """
        if kernels() is None:
            raise RuntimeError(f"{self.kernel}: numba is not in use")
        return self.dispatch


#: Every numpy function with a compiled twin, by kernel name (filled as modules import).
TWINS: dict[str, Twin] = {}


def compiled_twin(kernel: str, **constants: Any) -> Callable[[F], F]:
    """Decorator: the numpy function runs as the kernel ``kernel`` when numba is in use.

    The kernel takes the same arguments (with the same names) and returns the same
    numbers, bit for bit, or ``NotImplemented`` for inputs it does not take (then the
    reference runs); ``constants`` (values the numpy code owns, e.g. an iteration
    count or column offsets) are passed to it as keyword arguments. The undecorated
    function stays reachable as ``.reference``.

    Args:
        kernel: Name of the compiled form in :mod:`uasep_env._kernels`.
        **constants: Keyword arguments for the kernel.
    """

    def wrap(reference: F) -> F:
        bound = dict(constants)

        @functools.wraps(reference)
        def dispatch(*args: Any, **kwargs: Any) -> Any:
            compiled = kernels()
            if compiled is None:
                return reference(*args, **kwargs)
            out = getattr(compiled, kernel)(*args, **kwargs, **bound)
            if out is NotImplemented:  # the kernel declines these inputs
                return reference(*args, **kwargs)
            return out

        dispatch.reference = reference  # type: ignore[attr-defined]
        TWINS[kernel] = Twin(kernel=kernel, reference=reference, constants=bound, dispatch=dispatch)
        return dispatch  # type: ignore[return-value]

    return wrap
