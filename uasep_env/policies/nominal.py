"""Plan tracking: the nominal command every reference controller modifies.

The paper's attraction (eqs. 19-22) pulls a UAV towards its planned formation centre, its
slot and the planned velocity, and damps its motion relative to the formation; the speed
and acceleration bounds (eq. 4) turn any commanded acceleration into a normalised action.
The three APFs add repulsion to :func:`plan_tracking`; MVP and ORCA
(:mod:`uasep_env.policies.mvp`, :mod:`uasep_env.policies.orca`) change the velocity it
would reach. One copy, so every method tracks the plan the same way and a comparison
isolates how each one resolves conflicts.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["TrackingGains", "bounded_action", "norm", "plan_tracking"]


class TrackingGains(Protocol):
    """The attraction gains (:class:`~uasep_env.policies.apf.APFGains` has them)."""

    k_goal: float  # 1/s^2
    goal_saturation: float  # m
    k_slot: float  # 1/s^2
    k_vel: float  # 1/s
    k_damp: float  # 1/s


def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis (the controllers' one form, so their sums agree)."""
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _cap_norm(f: np.ndarray, cap: float) -> np.ndarray:
    n = norm(f)
    return f * np.minimum(1.0, cap / np.maximum(n, 1e-12))[..., None]


def plan_tracking(o: dict[str, np.ndarray], gains: TrackingGains) -> np.ndarray:
    """Eqs. 19-22: goal, slot, velocity matching and damping (m/s^2).

    ``F = K_g sat(p_g - p_o) + K_p (p_d - p) + K_v (v_d - v) - K_d (v - v_o)``.

    Args:
        o: Decoded observations (:meth:`~uasep_env.interface.observation.ObservationLayout.decode`).
        gains: The attraction gains.

    Returns:
        The nominal acceleration ``(..., 3)`` in m/s^2 (unbounded).
    """
    goal = _cap_norm(o["goal_offset"], gains.goal_saturation)
    return (
        gains.k_goal * goal
        + gains.k_slot * o["slot_offset"]
        + gains.k_vel * (o["plan_velocity"] - o["velocity"])
        - gains.k_damp * (o["velocity"] - o["formation_velocity"])
    )


def bounded_action(
    accel: np.ndarray, velocity: np.ndarray, max_speed: float, max_accel: float, dt: float
) -> np.ndarray:
    """Eq. 4 and the acceleration bound: normalised actions in ``[-1, 1]``.

    The component of ``accel`` along the velocity is capped so that the speed stays below
    ``max_speed`` after a step of ``dt``; then each axis is clipped to ``max_accel``.

    Args:
        accel: Commanded accelerations ``(..., 3)`` (m/s^2).
        velocity: Current velocities ``(..., 3)`` (m/s).
        max_speed: ``V_max`` (m/s).
        max_accel: Per-axis bound (m/s^2).
        dt: Step duration (s).
    """
    speed = norm(velocity)
    v_hat = velocity / np.maximum(speed, 1e-9)[..., None]
    along = np.einsum("...i,...i->...", accel, v_hat)
    limit = (max_speed - speed) / dt  # most speed gain allowed this step
    excess = np.maximum(0.0, along - np.maximum(limit, 0.0))
    accel = accel - excess[..., None] * v_hat
    return np.clip(accel / max_accel, -1.0, 1.0)
