"""One layer of a policy's network: :func:`uasep_env.policies.checkpoint_policy.dense_sums`."""

from __future__ import annotations

import numba
import numpy as np

from uasep_env._kernels.common import _JIT


@numba.njit(**_JIT)
def _dense_into(x, wt, b, out):  # noqa: ANN001, ANN202
    rows, n_in = x.shape
    n_out = b.shape[0]
    for r in range(rows):
        for j in range(n_out):
            out[r, j] = b[j]
        for i in range(n_in):
            xi = np.float64(x[r, i])
            for j in range(n_out):
                out[r, j] += xi * wt[i, j]


def dense(x: np.ndarray, wt: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x @ wt + b``, row by row, as the numpy reference computes each element.

    The bias, then input ``i``'s products added in the order of ``i``, in float64 (the
    caller, :func:`uasep_env.policies.checkpoint_policy.dense`, rounds them once to float32).
    """
    out = np.empty((x.shape[0], b.shape[0]), dtype=np.float64)
    _dense_into(x, wt, b, out)
    return out
