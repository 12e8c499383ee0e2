"""Optional numba support: the package runs without it, faster with it.

numba is not a dependency (``pip install "uasep-env[fast]"`` adds it). Callers of a kernel
that has a compiled form (:mod:`uasep_env._kernels`) ask :func:`available`; when numba is
missing, or disabled with the environment variable ``UASEP_NUMBA=0``, they use its numpy
form. Compiled kernels are cached on disk (``cache=True``), so only the first run of a
new installation pays the compilation (about 30 s on one core for the kernels an evaluation
uses). ``python -m uasep_env.precompile`` pays it at install time (``make eval`` and
``make test`` run it after installing): :func:`warm_up` plays one episode through the code
path of ``uasep-eval``, which compiles exactly the kernels such a run uses into the cache.
"""

from __future__ import annotations

import os
from typing import Any

__all__ = ["available", "kernels", "warm_up"]

_state: dict[str, Any] = {}


def _numba() -> Any:
    if "numba" not in _state:
        module = None
        if os.environ.get("UASEP_NUMBA", "1").strip() not in {"0", "false", "no", "off"}:
            try:
                import numba as module
            except ImportError:  # pragma: no cover - depends on the installation
                module = None
        _state["numba"] = module
    return _state["numba"]


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

        _state["kernels"] = _kernels
    return _state["kernels"]


def warm_up() -> float:
    """Compile (or load from the disk cache) the kernels an evaluation uses; the seconds taken.

    Returns 0 without doing anything when compiled kernels are not in use.
    """
    if not available():
        return 0.0
    import time

    from uasep_env.evaluation import evaluate

    t0 = time.perf_counter()
    # A whole episode: some call sites (the metrics' distances) meet new argument types
    # only when the encounter comes. The compiled episode itself takes under a second.
    evaluate(["apf"], {"scenario": "paper"}, [0])
    return time.perf_counter() - t0
