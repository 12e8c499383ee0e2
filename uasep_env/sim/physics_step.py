"""One physics step of every world: UAVs, obstacles, sensing, Kalman filters and safety.

:func:`physics_step` is the numpy reference of the whole physics step of
:class:`uasep_env.sim.world.World`, in the order of :mod:`uasep_env.sim.world`'s steps 1-4: the
double integrator with its process noise (:mod:`uasep_env.sim.dynamics`), the obstacles' Dubins
motion (:mod:`uasep_env.sim.obstacles`, or a replay's recorded tracks), the noisy measurements
and both Kalman filters (:mod:`uasep_env.sim.estimation`), and the running minimum separations
(:mod:`uasep_env.sim.geometry`). It composes those modules' numpy functions; its compiled twin
(``_kernels.physics.physics_step``) does the same arithmetic in three kernels between
numpy's sines and cosines, so that a step costs three compiled calls instead of a dozen
numpy and compiled ones (the Python between them is most of a small batch's step).
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.sim.dynamics import measure, step_double_integrator
from uasep_env.sim.estimation import gain_table, kalman_correct
from uasep_env.sim.geometry import nearest_separations
from uasep_env.sim.obstacles import N_UNIFORMS, ObstacleState, obstacle_velocity, step_obstacles

__all__ = ["PhysicsArrays", "PhysicsParams", "physics_step"]


class PhysicsArrays(NamedTuple):
    """The world's arrays a physics step updates in place (C-contiguous).

    Attributes:
        time: ``(E,)`` time since reset (s).
        kf_count: ``(E,)`` int64, Kalman updates since the tracks started.
        uav_pos: ``(E, N, 3)`` true UAV positions (m).
        uav_vel: ``(E, N, 3)`` true UAV velocities (m/s).
        uav_acc: ``(E, N, 3)`` the accelerations applied over the step (m/s^2), written.
        accel_cmd: ``(E, N, 3)`` commanded accelerations (m/s^2), read.
        est_pos: ``(E, N, 3)`` estimated UAV positions (m).
        est_vel: ``(E, N, 3)`` estimated UAV velocities (m/s).
        obstacle_est_pos: ``(E, M, 3)`` estimated obstacle positions (m).
        obstacle_est_vel: ``(E, M, 3)`` estimated obstacle ground velocities (m/s).
        min_uav_dist: ``(E, N)`` smallest UAV-UAV distance so far this env step (m).
        min_obstacle_dist: ``(E, N)`` smallest UAV-obstacle distance so far (m).
    """

    time: np.ndarray
    kf_count: np.ndarray
    uav_pos: np.ndarray
    uav_vel: np.ndarray
    uav_acc: np.ndarray
    accel_cmd: np.ndarray
    est_pos: np.ndarray
    est_vel: np.ndarray
    obstacle_est_pos: np.ndarray
    obstacle_est_vel: np.ndarray
    min_uav_dist: np.ndarray
    min_obstacle_dist: np.ndarray


class PhysicsParams(NamedTuple):
    """The constants of a physics step.

    Attributes:
        dt: Physics step (s).
        max_speed: UAV speed limit ``V_max`` (m/s).
        max_accel: Per-axis acceleration bound (m/s^2).
        kalman: Whether the estimates are Kalman filtered (else the measurements).
        uav_gains: ``(K, 2, 2)`` the UAV tracks' gain table
            (:attr:`uasep_env.sim.estimation.KalmanModel.gains`).
        obstacle_gains: ``(K', 2, 2)`` the obstacle tracks' gain table.
    """

    dt: float
    max_speed: float
    max_accel: float
    kalman: bool
    uav_gains: np.ndarray
    obstacle_gains: np.ndarray


class Replay(Protocol):
    """Moves replayed obstacles after the Dubins step (:class:`~.replay.ReplayTracks`)."""

    def step(self, obs: ObstacleState, time: np.ndarray) -> None: ...


@compiled_twin("physics_step", n_uniforms=N_UNIFORMS)
def physics_step(
    w: PhysicsArrays,
    obs: ObstacleState,
    normals: np.ndarray,
    uniforms: np.ndarray,
    p: PhysicsParams,
    replay: Replay | None = None,
) -> None:
    """Advance every world one physics step ``p.dt``, in place.

    Args:
        w: The world's arrays (updated).
        obs: The obstacles' state (updated; ``heading``, ``turn_rate`` and ``climb_rate``
            get new arrays, as :func:`uasep_env.sim.obstacles.step_obstacles` gives them).
        normals: ``(E, K)`` this step's scaled Gaussian noise: each UAV's acceleration
            (``3 N`` columns), then each UAV's and each obstacle's measured position and
            velocity (6 columns each).
        uniforms: ``(E, M * N_UNIFORMS)`` the obstacle pilots' uniforms.
        p: The step's constants.
        replay: Recorded tracks that move the replayed obstacles after the Dubins step.
    """
    e, n = w.uav_pos.shape[:2]
    m = obs.heading.shape[1]
    acc_noise = normals[:, : n * 3].reshape(e, n, 3)
    applied = step_double_integrator.reference(
        w.uav_pos, w.uav_vel, w.accel_cmd, acc_noise, p.dt, p.max_speed, p.max_accel
    )
    w.uav_acc[...] = applied
    if m:
        step_obstacles.reference(obs, uniforms.reshape(e, m, N_UNIFORMS), p.dt, w.time)
        if replay is not None:
            replay.step(obs, w.time)
    w.time[...] += p.dt
    z = normals[:, n * 3 : n * 9].reshape(e, n, 6)
    mp, mv = measure(w.uav_pos, w.uav_vel, z[..., :3], z[..., 3:])
    z_obs = normals[:, n * 9 :].reshape(e, m, 6)
    omp, omv = measure(obs.pos, obstacle_velocity(obs), z_obs[..., :3], z_obs[..., 3:])
    if p.kalman:
        w.kf_count[...] += 1
        count = w.kf_count
        kalman_correct.reference(
            w.est_pos, w.est_vel, applied - acc_noise, mp, mv, count,
            gain_table(p.uav_gains, count), p.dt,
        )  # fmt: skip
        kalman_correct.reference(
            w.obstacle_est_pos, w.obstacle_est_vel, None, omp, omv, count,
            gain_table(p.obstacle_gains, count), p.dt,
        )  # fmt: skip
    else:
        w.est_pos[...], w.est_vel[...] = mp, mv
        w.obstacle_est_pos[...], w.obstacle_est_vel[...] = omp, omv
    d_uav, d_obstacle = nearest_separations.reference(w.uav_pos, obs.pos, obs.active)
    np.minimum(w.min_uav_dist, d_uav, out=w.min_uav_dist)
    np.minimum(w.min_obstacle_dist, d_obstacle, out=w.min_obstacle_dist)
