r"""The small quadratic program of the CBF filter, solved exactly and batched.

For every agent of a batch (leading shape ``B``), with ``u`` the commanded acceleration
(3, m/s^2) and ``s`` one slack (m/s^2):

.. math::

    \min_{u, s}\ \tfrac12 |u - u_0|^2 + \tfrac12 \rho s^2 \quad\text{s.t.}\quad
    a_k \cdot u + s \ge b_k \ (k \text{ valid}),\quad l \le u \le h,\quad s \ge 0.

The objective is strictly convex and the problem always feasible (the slack absorbs any
shortfall), so the minimiser is unique. A penalised slack is never exactly zero where a
constraint binds: the constraint is short by ``1 / (1 + rho)`` of the change it asks for.
Its active constraints have linearly independent
gradients and non-negative multipliers, and at most four of them are needed (the problem has
four unknowns). :func:`solve_filter_qp` therefore enumerates every set of at most four
constraints (no set holding both bounds of one axis), solves the equality-constrained
problem of each in closed form (a 4x4 system), keeps the candidates that satisfy every
constraint and returns the one nearest ``(u_0, 0)``: the minimiser is among them and no
other feasible candidate is nearer. It is exact, has no iteration count or tolerance to tune
beyond a feasibility tolerance at round-off level, and is deterministic. Agents whose
``u_0`` already satisfies every constraint (most of them, most of the time) skip the
enumeration. ``tests/test_cbf.py`` checks it against ``qpsolvers`` (Clarabel) on random
instances, infeasible ones (slack active) included.

Its range: ``rho`` up to 1e6 (``CBFParams.slack_penalty``'s cap;
``tests/test_head_on_and_exactness.py`` checks it there against scipy). The slack's column
is ``1 / sqrt(rho)``, and past about 1e6 the pivots of a set holding it fall under the
linear-dependence test, so the true active set is rejected and a costlier candidate wins
(at 1e8, 22 of 83 instances worse than Clarabel).
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

__all__ = ["solve_filter_qp"]

_N = 4  # unknowns: u (3) and the slack
_MAX_ACTIVE = 4


@functools.lru_cache(maxsize=16)
def _active_sets(n_rows: int, n_barriers: int) -> np.ndarray:
    """Every candidate active set, padded with ``n_rows`` (a zero row): ``(C, 4)`` int.

    Rows: ``n_barriers`` barrier rows, the slack bound, then lower and upper bound of each
    axis (``n_barriers + 1 + 2 j`` and ``n_barriers + 2 + 2 j``).
    """
    opposite = {(n_barriers + 1 + 2 * j, n_barriers + 2 + 2 * j) for j in range(3)}
    sets = []
    for size in range(_MAX_ACTIVE + 1):
        for combo in itertools.combinations(range(n_rows), size):
            if any(pair[0] in combo and pair[1] in combo for pair in opposite):
                continue
            sets.append(combo + (n_rows,) * (_MAX_ACTIVE - size))
    return np.array(sets, dtype=np.intp)


def _dot(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``sum_n p[..., n] q[..., n]`` over the last axis (4), added left to right."""
    return (
        p[..., 0] * q[..., 0]
        + p[..., 1] * q[..., 1]
        + p[..., 2] * q[..., 2]
        + p[..., 3] * q[..., 3]
    )


def _cholesky_solve(gram: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``gram lam = rhs`` for a batch of 4x4 Gram matrices, element-wise.

    Written out (Cholesky, then two triangular solves) rather than ``np.linalg.solve``: the
    batch is hundreds of thousands of 4x4 systems, and element-wise array arithmetic is many
    times faster than one LAPACK call per matrix (and the same in any batch shape). A pivot
    below ``1e-10`` of its diagonal entry means linearly dependent rows: ``ok`` is False
    there (and ``lam`` meaningless).

    Returns:
        ``lam`` ``(..., 4)`` and ``ok`` ``(...)`` bool.
    """
    n = _MAX_ACTIVE
    low = [[None] * n for _ in range(n)]
    ok = np.ones(gram.shape[:-2], dtype=bool)
    for j in range(n):
        d = gram[..., j, j] - sum(low[j][k] * low[j][k] for k in range(j))
        ok &= d > 1e-10 * np.maximum(gram[..., j, j], 1e-300)
        low[j][j] = np.sqrt(np.where(ok, d, 1.0))
        for i in range(j + 1, n):
            off = gram[..., i, j] - sum(low[i][k] * low[j][k] for k in range(j))
            low[i][j] = off / low[j][j]
    y = [None] * n
    for i in range(n):
        y[i] = (rhs[..., i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i]
    lam = [None] * n
    for i in reversed(range(n)):
        lam[i] = (y[i] - sum(low[k][i] * lam[k] for k in range(i + 1, n))) / low[i][i]
    return np.stack(lam, axis=-1), ok


def _enumerate(g: np.ndarray, h: np.ndarray, n_barriers: int) -> np.ndarray:
    """The minimum-norm ``x`` with ``g x >= h`` for each row of the batch (``(B, 4)``)."""
    batch, m, _ = g.shape
    sets = _active_sets(m, n_barriers)  # (C, 4)
    g_pad = np.concatenate([g, np.zeros((batch, 1, _N))], axis=1)
    h_pad = np.concatenate([h, np.zeros((batch, 1))], axis=1)
    # Products summed in one fixed order, never by BLAS (whose order depends on the CPU),
    # so a filtered episode is the same on every machine.
    full = _dot(g_pad[:, :, None, :], g_pad[:, None, :, :])  # (B, m+1, m+1): row pairs
    gram = full[:, sets[:, :, None], sets[:, None, :]]  # (B, C, 4, 4): the active rows'
    pad = sets == m  # (C, 4)
    gram = gram + np.where(pad[:, :, None] & np.eye(_MAX_ACTIVE, dtype=bool), 1.0, 0.0)
    lam, ok = _cholesky_solve(gram, h_pad[:, sets])  # dependent (or zero) rows: no candidate
    gs = g_pad[:, sets]  # (B, C, 4, 4)
    x = (  # (B, C, 4)
        gs[:, :, 0, :] * lam[:, :, 0, None]
        + gs[:, :, 1, :] * lam[:, :, 1, None]
        + gs[:, :, 2, :] * lam[:, :, 2, None]
        + gs[:, :, 3, :] * lam[:, :, 3, None]
    )
    slack = _dot(x[:, :, None, :], g[:, None, :, :]) - h[:, None, :]  # (B, C, m), >= 0: ok
    tol = 1e-9 * np.maximum(1.0, np.abs(h).max(axis=-1))[:, None]
    worst = slack.min(axis=-1)
    norm = _dot(x, x)
    feasible = ok & (worst >= -tol)
    # The minimiser is a feasible candidate; fall back to the least violated one should
    # round-off reject every candidate (never seen; kept so the answer is always defined).
    score = np.where(feasible, norm, np.inf)
    best = np.argmin(score, axis=-1)
    none = ~feasible.any(axis=-1)
    if none.any():
        best = np.where(none, np.argmax(np.where(ok, worst, -np.inf), axis=-1), best)
    return x[np.arange(batch), best]


def solve_filter_qp(
    u0: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    valid: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    slack_penalty: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Solve the filter's QP (module docstring) for a batch of agents.

    Args:
        u0: Nominal accelerations ``(..., 3)`` (m/s^2).
        a: Constraint normals ``(..., K, 3)`` (unit vectors, so the slack is in m/s^2).
        b: Constraint bounds ``(..., K)`` (m/s^2): ``a_k . u + s >= b_k``.
        valid: Which of the ``K`` rows are constraints ``(..., K)`` (bool).
        lower: Lower bound of ``u`` per axis ``(..., 3)`` (m/s^2), ``<= upper``.
        upper: Upper bound of ``u`` per axis ``(..., 3)`` (m/s^2).
        slack_penalty: ``rho > 0``, the weight of the squared slack (dimensionless); exact
            up to 1e6 (module docstring).

    Returns:
        ``u`` ``(..., 3)`` and the slack ``s`` ``(...)``, float64.
    """
    u0 = np.asarray(u0, dtype=float)
    lead = u0.shape[:-1]
    k = np.shape(b)[-1]
    u0f = u0.reshape(-1, 3)
    af = np.asarray(a, dtype=float).reshape(-1, k, 3)
    bf = np.asarray(b, dtype=float).reshape(-1, k)
    vf = np.asarray(valid, dtype=bool).reshape(-1, k)
    lo = np.asarray(lower, dtype=float).reshape(-1, 3)
    hi = np.asarray(upper, dtype=float).reshape(-1, 3)
    root_rho = float(np.sqrt(slack_penalty))
    # Rows g . x >= h in the scaled offset x = L (z - z_0), L = diag(1, 1, 1, sqrt(rho)):
    # the K barriers (an invalid one is 0 . x >= -1), s >= 0 (s_0 = 0), then each axis's
    # lower and upper bound.
    batch = u0f.shape[0]
    g = np.zeros((batch, k + 7, _N))
    h = np.zeros((batch, k + 7))
    g[:, :k, :3] = np.where(vf[..., None], af, 0.0)
    g[:, :k, 3] = np.where(vf, 1.0 / root_rho, 0.0)
    h[:, :k] = np.where(vf, bf - np.einsum("bkj,bj->bk", af, u0f), -1.0)
    g[:, k, 3] = 1.0 / root_rho
    for j in range(3):
        g[:, k + 1 + 2 * j, j] = 1.0
        h[:, k + 1 + 2 * j] = lo[:, j] - u0f[:, j]
        g[:, k + 2 + 2 * j, j] = -1.0
        h[:, k + 2 + 2 * j] = u0f[:, j] - hi[:, j]
    x = np.zeros((batch, _N))
    rows = np.flatnonzero((h > 0.0).any(axis=-1))  # u0 violates something: solve
    if rows.size:
        x[rows] = _enumerate(g[rows], h[rows], k)
    u = u0f + x[:, :3]
    s = np.maximum(x[:, 3] / root_rho, 0.0)
    return u.reshape(*lead, 3), s.reshape(lead)
