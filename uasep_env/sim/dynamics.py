"""UAV dynamics: the discrete double integrator of paper eqs. 1-4.

Each UAV is a point mass in the north-east-down (NED) frame with state
``x = [p, v]`` (m, m/s). Over one physics step ``dt`` (s) with acceleration ``a`` (m/s^2)::

    x(t+1) = A x(t) + B a(t),   A = [[I, dt I], [0, I]],   B = [[dt^2/2 I], [dt I]]

(eq. 1 with the erratum of the notes: the extracted ``B`` is garbled). The commanded
acceleration is bounded per axis by ``a_max``; Gaussian process noise ``S_w`` is added to it
(the flight controller and the wind disturb the realised acceleration); then eq. 4 is applied
as the notes decide: the new velocity's norm never exceeds ``V_max``. The acceleration that
was really applied (after the speed limit) is returned so that the estimator and the metrics
see it.

Arrays are batch-first: ``(n_envs, n_uavs, 3)``.
"""

from __future__ import annotations

import numpy as np

from uasep_env._numba import compiled_twin

__all__ = ["AXES", "measure", "step_double_integrator", "transition_matrices"]
#: NED axes (north, east, down), as metric and plot names.
AXES: tuple[str, str, str] = ("x", "y", "z")


def transition_matrices(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The 6x6 ``A`` and 6x3 ``B`` of eq. 1 for the state ``[p, v]``.

    Args:
        dt: Physics step (s).

    Returns:
        ``(A, B)``.
    """
    eye = np.eye(3)
    a = np.block([[eye, dt * eye], [np.zeros((3, 3)), eye]])
    b = np.vstack([0.5 * dt * dt * eye, dt * eye])
    return a, b


@compiled_twin("double_integrator")
def step_double_integrator(
    pos: np.ndarray,
    vel: np.ndarray,
    accel_cmd: np.ndarray,
    accel_noise: np.ndarray | None,
    dt: float,
    max_speed: float,
    max_accel: float,
) -> np.ndarray:
    """Advance positions and velocities one step, in place.

    Args:
        pos: Positions (m), shape ``(..., 3)``; updated in place.
        vel: Velocities (m/s), shape ``(..., 3)``; updated in place.
        accel_cmd: Commanded accelerations (m/s^2), shape ``(..., 3)``; each axis is bounded
            to ``[-max_accel, max_accel]`` (the action space's box).
        accel_noise: Process noise ``S_w`` added to the bounded command (m/s^2), or ``None``.
        dt: Physics step (s).
        max_speed: ``V_max`` (m/s); ``|v|`` after the step never exceeds it (eq. 4).
        max_accel: Per-axis acceleration bound (m/s^2).

    Returns:
        The acceleration really applied over the step (m/s^2), shape ``(..., 3)``: the
        bounded command plus noise, reduced where the speed limit bit.
    """
    accel = np.minimum(np.maximum(accel_cmd, -max_accel), max_accel)  # np.clip, less overhead
    if accel_noise is not None:
        accel = accel + accel_noise
    new_vel = vel + dt * accel
    speed2 = np.einsum("...i,...i->...", new_vel, new_vel)
    over = speed2 > max_speed * max_speed
    if over.any():
        # Scale the new velocity onto the V_max sphere; slightly inside so that rounding
        # can never leave |v| above V_max.
        scale = np.where(
            over, (max_speed * (1.0 - 1e-12)) / np.sqrt(np.maximum(speed2, 1e-300)), 1.0
        )
        new_vel *= scale[..., None]
        accel = np.where(over[..., None], (new_vel - vel) / dt, accel)
    # Exact double-integrator position update with the applied (constant) acceleration.
    pos += 0.5 * dt * (vel + new_vel)
    vel[...] = new_vel
    return accel


def measure(
    pos: np.ndarray,
    vel: np.ndarray,
    pos_noise: np.ndarray | None,
    vel_noise: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sensed state ``y = C x + S_v`` (eq. 2 with the notes' erratum, ``C = I``).

    Args:
        pos: True positions (m).
        vel: True velocities (m/s).
        pos_noise: Additive position noise (m) or ``None``.
        vel_noise: Additive velocity noise (m/s) or ``None``.

    Returns:
        ``(measured_pos, measured_vel)`` (new arrays).
    """
    mp = pos + pos_noise if pos_noise is not None else pos.copy()
    mv = vel + vel_noise if vel_noise is not None else vel.copy()
    return mp, mv
