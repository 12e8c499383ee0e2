"""What the compiled kernels share: numba's options, the loop choice, inputs, 3-vector norms."""

from __future__ import annotations

import math
import os

import numba
import numpy as np

# No reference counting (``_nrt``): every kernel writes into arrays it is given and creates
# none (its wrapper allocates), and numba's atomic reference counts on each array a loop
# passes around cost more than the arithmetic (the observations ran 4.8x slower with them
# at 4096 environments; docs/speed.md).
_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "_nrt": False}

#: Points per call above which the loop is spread over the cores (thread start-up costs).
PARALLEL_MIN = 2048
# numba's OpenMP layer (GNU) kills a forked child that runs a parallel loop after its
# parent has run one; forked children (multiprocessing workers) use the serial loops.
_forked = [False]
os.register_at_fork(after_in_child=lambda: _forked.__setitem__(0, True))
#: The parallel loops' threads, set by :func:`uasep_env._numba.kernels` when it loads
#: the kernels (the process's share of the cores, :func:`uasep_env.runtime.cores.kernel_threads`);
#: 1: the serial loops. A list, so that the value is read at call time.
THREADS = [1]


def _parallel(size: int) -> bool:
    """Whether a loop over ``size`` items is spread over the cores."""
    return size >= PARALLEL_MIN and not _forked[0] and THREADS[0] > 1


def frozen(a: np.ndarray) -> np.ndarray:
    """``a`` C-contiguous and read-only (a view when it is contiguous already).

    numba compiles a kernel once per argument type, and an array's type holds its layout and
    whether it is writable: callers pass broadcast views, copies and the world's own arrays,
    so without this one kernel compiled up to three times (several seconds each). The
    kernels only read their inputs.
    """
    a = np.ascontiguousarray(a)
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)  # sooner than setting the flag
    return a


@numba.njit(inline="always", **_JIT)
def _maximum(x, y):  # noqa: ANN001, ANN202
    """``np.maximum``'s scalar rule: ``x`` unless ``y`` is larger, NaN if either is."""
    return x if (x >= y or x != x) else y


@numba.njit(inline="always", **_JIT)
def _minimum(x, y):  # noqa: ANN001, ANN202
    """``np.minimum``'s scalar rule: ``x`` unless ``y`` is smaller, NaN if either is."""
    return x if (x <= y or x != x) else y


@numba.njit(inline="always", **_JIT)
def _sq3(a, b, c):  # noqa: ANN001, ANN202
    """Squared norm in the order numpy's ``einsum("...i,...i")`` adds (two SIMD lanes)."""
    return (a * a + c * c) + b * b


@numba.njit(inline="always", **_JIT)
def _dist3(a, b, c):  # noqa: ANN001, ANN202
    """Euclidean norm as numpy's ``sqrt(einsum("...i,...i"))``."""
    return math.sqrt(_sq3(a, b, c))


@numba.njit(inline="always", **_JIT)
def _gap(p, e, i, q, j):  # noqa: ANN001, ANN202
    """Distance from ``p[e, i]`` to ``q[e, j]`` (3-vectors), as :func:`_dist3`."""
    return _dist3(q[e, j, 0] - p[e, i, 0], q[e, j, 1] - p[e, i, 1], q[e, j, 2] - p[e, i, 2])


@numba.njit(inline="always", **_JIT)
def _norm3(a, b, c):  # noqa: ANN001, ANN202
    """Euclidean norm in the order ``np.linalg.norm(axis=-1)`` adds (left to right)."""
    return math.sqrt((a * a + b * b) + c * c)


def _sin_cos_agree() -> bool:
    """Whether numpy's float64 sine and cosine give the compiled kernels' numbers.

    The kernels' ``math.sin`` and ``math.cos`` are the C library's, as Python's are, unless
    numba vectorises them with Intel's SVML; numpy's are the C library's on x86 (it has no
    vectorised float64 forms of them). A numpy or C library that differed would differ
    somewhere in the last bit: checked on a dense sweep of the angles the fit uses, and
    beyond, against Python's (nothing to compile).
    """
    if numba.config.USING_SVML:
        return False
    rng = np.random.default_rng(20261204)
    x = np.concatenate(
        [
            np.linspace(-4.0 * np.pi, 4.0 * np.pi, 4097),
            rng.uniform(0.0, np.pi, 8192),
            [0.0, 5e-324, 1e-300, 1e-9, 0.5 * np.pi, np.pi, 1e5],
        ]
    )
    values = x.tolist()
    libm = [[math.sin(v) for v in values], [math.cos(v) for v in values]]
    return bool(np.array_equal(libm, [np.sin(x), np.cos(x)]))


#: :func:`_sin_cos_agree`'s answer, once made (the first call of a kernel that asks).
_SIN_COS: list[bool] = []


def sin_cos_agree() -> bool:
    """Whether numpy's float64 sines and cosines are the kernels' (checked once).

    Where they are not, the kernels that take the fit's sines and cosines decline (numpy's
    run instead). Checked at the first call, not at import (a few milliseconds).
    """
    if not _SIN_COS:
        _SIN_COS.append(_sin_cos_agree())
    return _SIN_COS[0]
