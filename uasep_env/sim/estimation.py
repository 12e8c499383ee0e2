"""Estimation: a batched Kalman filter for the UAVs' and obstacles' tracks.

The paper has each UAV Kalman-filter the states it receives (section 2.1.1). Every UAV
senses its own state and broadcasts it; every member runs the same filter on the same
broadcast measurement, so one estimate per UAV serves the whole formation (which is what
the paper's scheme computes). Obstacles are tracked the same way from their noisy
radar/ADS-B tracks, with zero known input and a process noise that covers their manoeuvres.

The model is the double integrator of eq. 1, separately on each NED axis, with state
``(p, v)``, input the known acceleration, process noise ``Q = s_a^2 B B^T`` and measurement
noise ``R = diag(s_p^2, s_v^2)`` (``C = I``, eq. 2). Because ``A``, ``Q`` and ``R`` are the same
for every track, the covariance and the gain depend only on the number of updates since
the track started: the gain sequence is computed once (:class:`KalmanModel`) and each
track keeps a counter. This is the exact Kalman filter, not a steady-state approximation;
after the covariance has converged (to 1e-12) the last gain is reused.
"""

from __future__ import annotations

import numpy as np

from uasep_env._numba import compiled_twin

__all__ = ["KalmanModel", "gain_table", "kalman_correct"]


class KalmanModel:
    """Per-axis constant-acceleration-input Kalman filter shared by many tracks.

    Args:
        dt: Time between updates (s).
        accel_std: Process noise on the acceleration (m/s^2).
        position_std: Measurement noise on the position (m).
        velocity_std: Measurement noise on the velocity (m/s).
        max_table: Largest number of gains precomputed before the last is reused.

    Attributes:
        gains: ``(K, 2, 2)`` gain per update index; index 0 is the initialisation
            (estimate = first measurement, covariance = ``R``).
        covariances: ``(K, 2, 2)`` posterior covariance per update index.
    """

    def __init__(
        self,
        dt: float,
        accel_std: float,
        position_std: float,
        velocity_std: float,
        max_table: int = 4096,
    ) -> None:
        self.dt = float(dt)
        a = np.array([[1.0, dt], [0.0, 1.0]])
        b = np.array([[0.5 * dt * dt], [dt]])
        q = accel_std**2 * (b @ b.T)
        r = np.diag([position_std**2, velocity_std**2])
        p = r.copy()
        gains = [np.eye(2)]
        covs = [p.copy()]
        for _ in range(1, max_table):
            p_pred = a @ p @ a.T + q
            s = p_pred + r
            # pinv: with zero noise both P and R vanish and any gain is exact; pinv gives 0.
            k = p_pred @ np.linalg.pinv(s)
            p_new = (np.eye(2) - k) @ p_pred
            p_new = 0.5 * (p_new + p_new.T)
            converged = np.max(np.abs(p_new - p)) <= 1e-12 * max(1.0, float(np.max(np.abs(p))))
            p = p_new
            gains.append(k)
            covs.append(p.copy())
            if converged:
                break
        self.gains = np.array(gains)
        self.covariances = np.array(covs)

    def update(self, *track: np.ndarray | None) -> None:
        """Predict with the known input then correct with the measurement, in place.

        Args:
            *track: :func:`kalman_correct`'s first six arguments, ``(est_pos, est_vel,
                accel, meas_pos, meas_vel, count)`` (``count`` >= 1 here); this model
                supplies the gain table and the time step.
        """
        count = track[5]
        kalman_correct(*track, gain_table(self.gains, count), self.dt)

    def steady_state_position_std(self) -> float:
        """Posterior position standard deviation once the filter has converged (m)."""
        return float(np.sqrt(max(0.0, self.covariances[-1, 0, 0])))


def gain_table(gains: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The gains :func:`kalman_correct` needs for tracks at ``count`` updates.

    Once every track has converged (the usual case), the last gain alone: a table whose
    every index gives it, which :func:`kalman_correct` applies without a gather.

    Args:
        gains: ``(K, 2, 2)`` the gain table (:attr:`KalmanModel.gains`).
        count: ``(n_envs,)`` updates since each env's tracks started.
    """
    return gains[-1:] if count.min() >= len(gains) - 1 else gains


@compiled_twin("kalman_correct")
def kalman_correct(
    est_pos: np.ndarray,
    est_vel: np.ndarray,
    accel: np.ndarray | None,
    meas_pos: np.ndarray,
    meas_vel: np.ndarray,
    count: np.ndarray,
    gains: np.ndarray,
    dt: float,
) -> None:
    """One Kalman step of every track, in place (:meth:`KalmanModel.update`'s arithmetic).

    Args:
        est_pos: Estimated positions (m), ``(n_envs, n, 3)``; updated.
        est_vel: Estimated velocities (m/s), ``(n_envs, n, 3)``; updated.
        accel: Known acceleration over the step (m/s^2) or ``None`` (zero input).
        meas_pos: Measured positions (m), same shape.
        meas_vel: Measured velocities (m/s), same shape.
        count: ``(n_envs,)`` updates since each env's tracks started; row ``e`` uses the
            gain ``gains[min(count[e], len(gains) - 1)]``.
        gains: ``(K, 2, 2)`` gain table (:attr:`KalmanModel.gains`, or its last gain alone
            once every track has converged).
        dt: Time between updates (s).
    """
    if accel is None:
        pred_p = est_pos + dt * est_vel
        pred_v = est_vel
    else:
        pred_p = est_pos + dt * est_vel + (0.5 * dt * dt) * accel
        pred_v = est_vel + dt * accel
    last = len(gains) - 1
    if last == 0:
        # One gain for every track: scalars, no gather (they show at small batches).
        k00, k01, k10, k11 = (float(g) for g in gains[0].ravel())
    else:
        k = gains[np.minimum(count, last)][:, None, None]  # (n_envs, 1, 1, 2, 2)
        k00, k01, k10, k11 = k[..., 0, 0], k[..., 0, 1], k[..., 1, 0], k[..., 1, 1]
    ip = meas_pos - pred_p
    iv = meas_vel - pred_v
    est_pos[...] = pred_p + k00 * ip + k01 * iv
    est_vel[...] = pred_v + k10 * ip + k11 * iv
