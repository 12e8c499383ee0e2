"""The plan at a time: :func:`uasep_env.sim.formation.planned_state`."""

from __future__ import annotations

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, frozen


@numba.njit(**_JIT)
def _plan_rows(time, speed, length, cum, waypoints, direction, offsets, center, d_out, pos, vel):  # noqa: ANN001, ANN202
    for e in range(time.shape[0]):
        t = time[e]
        s = min(speed[e] * max(t, 0.0), length[e])
        # Segment index: how many inner way-points lie at or before s, at most the last.
        idx = 0
        for k in range(1, cum.shape[1] - 1):
            if cum[e, k] <= s:
                idx += 1
        idx = min(idx, direction.shape[1] - 1)
        along = s - cum[e, idx]
        moving = speed[e] * t < length[e]
        for a in range(3):
            d = direction[e, idx, a]
            c = waypoints[e, idx, a] + along * d
            v = speed[e] * d if moving else 0.0
            center[e, a] = c
            d_out[e, a] = d
            for i in range(pos.shape[1]):
                pos[e, i, a] = c + offsets[e, idx, i, a]
                vel[e, i, a] = v


def plan_now(
    plan: object, time: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.sim.formation.planned_state`: the plan at ``time``.

    Args:
        plan: The :class:`uasep_env.sim.formation.PlannedTrajectory` (its arrays are read).
        time: ``(E,)`` times (s).
        offsets: ``(E, W - 1, N, 3)`` slots rotated along each segment (m).

    Returns:
        ``(E, 3)`` planned centre (m) and direction, ``(E, N, 3)`` planned UAV positions (m)
        and velocities (m/s).
    """
    e, _, n, _ = offsets.shape
    center, d = np.empty((e, 3)), np.empty((e, 3))
    pos, vel = np.empty((e, n, 3)), np.empty((e, n, 3))
    inputs = (time, plan.cruise_speed, plan.length, plan.cum, plan.waypoints, plan.direction,
              offsets)  # fmt: skip
    _plan_rows(*map(frozen, inputs), center, d, pos, vel)  # one compiled signature
    return center, d, pos, vel
