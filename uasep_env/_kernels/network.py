"""One layer of a policy's network: :func:`uasep_env.policies.checkpoint_policy.dense_sums`."""

from __future__ import annotations

import numba
import numpy as np

from uasep_env._kernels.common import _JIT


@numba.njit(**_JIT)
def dense(x, wt, b):  # noqa: ANN001, ANN202
    """``x @ wt + b``, row by row, as the numpy reference computes each element.

    The bias, then input ``i``'s products added in the order of ``i``, in float64 (the
    caller, :func:`uasep_env.policies.checkpoint_policy.dense`, rounds them once to float32).
    """
    rows, n_in = x.shape
    n_out = b.shape[0]
    out = np.empty((rows, n_out), dtype=np.float64)
    for r in range(rows):
        for j in range(n_out):
            out[r, j] = b[j]
        for i in range(n_in):
            xi = np.float64(x[r, i])
            for j in range(n_out):
                out[r, j] += xi * wt[i, j]
    return out
