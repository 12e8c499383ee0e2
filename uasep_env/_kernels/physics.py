"""The physics step's kernels: double integrator, obstacle motion and the Kalman correction.

Twins of :func:`uasep_env.sim.dynamics.step_double_integrator`,
:func:`uasep_env.sim.obstacles.step_obstacles` and :func:`uasep_env.sim.estimation.kalman_correct`,
and of the whole physics step they make with the measurements and separations,
:func:`uasep_env.sim.physics_step.physics_step` (:func:`physics_step`: three kernels that share
the loops of the others). The single-part twins loop over the points serially (a few dozen
operations a point); the whole step's two large loops, over the environments, are spread over
the cores for large batches as the other kernels' are (:func:`~.common._parallel`).

Unlike the read-only kernels these update the world's arrays in place, so they take them as
they are (the world's own arrays are C-contiguous and writable: one specialisation each)
rather than through :func:`uasep_env._kernels.common.frozen`, whose copy of a view would
lose the writes. An argument of the single-part twins that is not C-contiguous is copied
and the result copied back; the whole step takes the world's own arrays only.

Bit-identity notes: the transcendental functions (``sin``, ``cos``) are numpy's, computed
between the loops as the other kernels do (``_kernels.ellipsoids``); ``np.maximum`` and
``np.minimum`` are written as numpy's SIMD loops evaluate them (NaN propagates; of two equal
values the second is returned, which only shows for ``-0.0`` against ``0.0``); ``np.mod`` is
Python's ``%`` on floats (both take ``fmod`` and move the result onto the divisor's sign).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _parallel, _sq3
from uasep_env._kernels.ellipsoids import _ROWS_PER_TASK
from uasep_env._kernels.separations import _nearest


@numba.njit(inline="always", **_JIT)
def _maximum(a, b):  # noqa: ANN001, ANN202
    """``np.maximum(a, b)`` for two floats."""
    return a if (a > b or math.isnan(a)) else b


@numba.njit(inline="always", **_JIT)
def _minimum(a, b):  # noqa: ANN001, ANN202
    """``np.minimum(a, b)`` for two floats."""
    return a if (a < b or math.isnan(a)) else b


def _writable(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous float64 array the kernel may write (a copy if it must be)."""
    return np.ascontiguousarray(a, dtype=np.float64)


# ---------------------------------------------------------------- double integrator
@numba.njit(inline="always", **_JIT)
def _speed_limited(v0, v1, v2, a0, a1, a2, dt, max_speed):  # noqa: ANN001, ANN202
    """The new velocity and the applied acceleration under the speed limit (eq. 4)."""
    n0 = v0 + dt * a0
    n1 = v1 + dt * a1
    n2 = v2 + dt * a2
    speed2 = _sq3(n0, n1, n2)
    if speed2 > max_speed * max_speed:
        scale = (max_speed * (1.0 - 1e-12)) / math.sqrt(_maximum(speed2, 1e-300))
        n0, n1, n2 = n0 * scale, n1 * scale, n2 * scale
        a0, a1, a2 = (n0 - v0) / dt, (n1 - v1) / dt, (n2 - v2) / dt
    return n0, n1, n2, a0, a1, a2


@numba.njit(**_JIT)
def _integrate(pos, vel, cmd, noise, has_noise, dt, max_speed, max_accel, out):  # noqa: ANN001, ANN202
    half_dt = 0.5 * dt
    for k in range(pos.shape[0]):
        a0 = _minimum(_maximum(cmd[k, 0], -max_accel), max_accel)
        a1 = _minimum(_maximum(cmd[k, 1], -max_accel), max_accel)
        a2 = _minimum(_maximum(cmd[k, 2], -max_accel), max_accel)
        if has_noise:
            a0 = a0 + noise[k, 0]
            a1 = a1 + noise[k, 1]
            a2 = a2 + noise[k, 2]
        v0, v1, v2 = vel[k, 0], vel[k, 1], vel[k, 2]
        n0, n1, n2, a0, a1, a2 = _speed_limited(v0, v1, v2, a0, a1, a2, dt, max_speed)
        pos[k, 0] += half_dt * (v0 + n0)
        pos[k, 1] += half_dt * (v1 + n1)
        pos[k, 2] += half_dt * (v2 + n2)
        vel[k, 0], vel[k, 1], vel[k, 2] = n0, n1, n2
        out[k, 0], out[k, 1], out[k, 2] = a0, a1, a2


def double_integrator(
    pos: np.ndarray,
    vel: np.ndarray,
    accel_cmd: np.ndarray,
    accel_noise: np.ndarray | None,
    dt: float,
    max_speed: float,
    max_accel: float,
) -> np.ndarray:
    """:func:`~uasep_env.sim.dynamics.step_double_integrator`, compiled: same bits."""
    shape = pos.shape
    p, v = _writable(pos), _writable(vel)
    cmd = _writable(accel_cmd).reshape(-1, 3)
    noise = cmd if accel_noise is None else _writable(accel_noise).reshape(-1, 3)
    out = np.empty(shape)
    _integrate(p.reshape(-1, 3), v.reshape(-1, 3), cmd, noise, accel_noise is not None,
               float(dt), float(max_speed), float(max_accel), out.reshape(-1, 3))  # fmt: skip
    if p is not pos:
        pos[...] = p
    if v is not vel:
        vel[...] = v
    return out


# ---------------------------------------------------------------- obstacles
# fmt: off
@numba.njit(**_JIT)
def _commands(u, switch_prob, time, has_time, hold_until, straight_prob, max_turn, max_climb,  # noqa: ANN001, ANN202
              turn, climb, pos, band, wind, ground, dt, new_turn, new_climb, y, mid, heading):  # noqa: ANN001
# fmt: on
    """The pilot's commands (turn, climb) and the arc's ``y`` and mid-heading per obstacle."""
    _commands_rows(0, turn.shape[0], u, switch_prob, time, has_time, hold_until, straight_prob,
                   max_turn, max_climb, turn, climb, pos, band, wind, ground, dt, new_turn,
                   new_climb, y, mid, heading)  # fmt: skip


# fmt: off
@numba.njit(inline="always", **_JIT)
def _commands_rows(e0, e1, u, switch_prob, time, has_time, hold_until, straight_prob, max_turn,  # noqa: ANN001, ANN202
                   max_climb, turn, climb, pos, band, wind, ground, dt, new_turn, new_climb, y,  # noqa: ANN001
                   mid, heading):  # noqa: ANN001
# fmt: on
    """:func:`_commands` of the rows ``e0:e1``."""
    for e in range(e0, e1):
        for j in range(turn.shape[1]):
            switch = u[e, j, 0] < switch_prob[e, j]
            if has_time:
                switch = switch and time[e] >= hold_until[e, j]
            if switch:
                straight = u[e, j, 1] < straight_prob[e, j]
                t = 0.0 if straight else (2.0 * u[e, j, 2] - 1.0) * max_turn[e, j]
                c = 0.0 if straight else (2.0 * u[e, j, 3] - 1.0) * max_climb[e, j]
            else:
                t, c = turn[e, j], climb[e, j]
            alt_next = -pos[e, j, 2] + c * dt
            if (alt_next > band[e, j, 1] and c > 0) or (alt_next < band[e, j, 0] and c < 0):
                c = 0.0
            least = _minimum(max_climb[e, j], wind[e, 2] + (ground[e, j] + pos[e, j, 2]) / dt)
            c = _maximum(c, least)
            new_turn[e, j], new_climb[e, j] = t, c
            half = 0.5 * t * dt
            yy = np.pi * (half / np.pi)
            y[e, j] = yy if yy != 0.0 else _EPS
            mid[e, j] = heading[e, j] + half


_EPS = float(np.finfo(float).eps)  # np.sinc's guard against 0 / 0, as obstacles._EPS


# fmt: off
@numba.njit(**_JIT)
def _move(pos, heading, speed, climb, active, wind, ground, dt, y, sin_y, cos_mid, sin_mid,  # noqa: ANN001, ANN202
          turn, new_heading):  # noqa: ANN001
# fmt: on
    """The arc flown (with the wind), the new heading, and the ground floor, per obstacle."""
    two_pi = 2 * np.pi
    for e in range(heading.shape[0]):
        w0, w1, w2 = wind[e, 0] * dt, wind[e, 1] * dt, wind[e, 2] * dt
        for j in range(heading.shape[1]):
            if active[e, j]:
                chord = speed[e, j] * dt * (sin_y[e, j] / y[e, j])
                m0 = chord * cos_mid[e, j] + w0
                m1 = chord * sin_mid[e, j] + w1
                m2 = -climb[e, j] * dt + w2
                half = 0.5 * turn[e, j] * dt
                new_heading[e, j] = (heading[e, j] + 2.0 * half + np.pi) % two_pi - np.pi
            else:  # inactive obstacles stay (numpy adds a zero move: -0.0 becomes 0.0)
                m0 = m1 = m2 = 0.0
                new_heading[e, j] = heading[e, j]
            pos[e, j, 0] += m0
            pos[e, j, 1] += m1
            pos[e, j, 2] = _minimum(pos[e, j, 2] + m2, -ground[e, j])


def obstacle_step(obs, uniforms: np.ndarray, dt: float, time: np.ndarray | None = None) -> None:  # noqa: ANN001
    """:func:`uasep_env.sim.obstacles.step_obstacles`, compiled: same arguments, same bits.

    Like the numpy form it gives ``turn_rate``, ``climb_rate`` and ``heading`` new arrays
    and moves ``pos`` in place.
    """
    shape = obs.heading.shape
    new_turn, new_climb, y, mid, heading = (np.empty(shape) for _ in range(5))
    pos = _writable(obs.pos)
    dt = float(dt)
    has_time = time is not None
    _commands(_writable(uniforms), obs.switch_prob, time if has_time else np.zeros(shape[0]),
              has_time, obs.hold_until, obs.straight_prob, obs.max_turn_rate,
              obs.max_climb_rate, obs.turn_rate, obs.climb_rate, pos, obs.alt_band, obs.wind,
              obs.ground, dt, new_turn, new_climb, y, mid, obs.heading)  # fmt: skip
    # numpy's sin and cos, not libm's: the numpy form's numbers to the last bit.
    _move(pos, obs.heading, obs.speed, new_climb, obs.active, obs.wind, obs.ground, dt, y,
          np.sin(y), np.cos(mid), np.sin(mid), new_turn, heading)  # fmt: skip
    if pos is not obs.pos:
        obs.pos[...] = pos
    obs.turn_rate, obs.climb_rate, obs.heading = new_turn, new_climb, heading


# ---------------------------------------------------------------- Kalman correction
@numba.njit(inline="always", **_JIT)
def _predict_correct(p, v, accel, has_accel, meas_p, meas_v, g, gains, dt):  # noqa: ANN001, ANN202
    """One axis of one track: predicted with the known input, corrected with gain ``g``."""
    if has_accel:
        pred_p = p + dt * v + (0.5 * dt * dt) * accel
        pred_v = v + dt * accel
    else:
        pred_p = p + dt * v
        pred_v = v
    ip = meas_p - pred_p
    iv = meas_v - pred_v
    return (pred_p + gains[g, 0, 0] * ip + gains[g, 0, 1] * iv,
            pred_v + gains[g, 1, 0] * ip + gains[g, 1, 1] * iv)  # fmt: skip


@numba.njit(**_JIT)
def _correct(est_pos, est_vel, accel, has_accel, meas_pos, meas_vel, count, gains, dt):  # noqa: ANN001, ANN202
    """Predict with the known input and correct with the measurement, per track and axis."""
    last = gains.shape[0] - 1
    for e in range(est_pos.shape[0]):
        g = min(count[e], last)
        for i in range(est_pos.shape[1]):
            for a in range(3):
                est_pos[e, i, a], est_vel[e, i, a] = _predict_correct(
                    est_pos[e, i, a], est_vel[e, i, a], accel[e, i, a], has_accel,
                    meas_pos[e, i, a], meas_vel[e, i, a], g, gains, dt)  # fmt: skip


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
    """:func:`uasep_env.sim.estimation.kalman_correct`, compiled: same arguments, same bits."""
    p, v = _writable(est_pos), _writable(est_vel)
    mp, mv = _writable(meas_pos), _writable(meas_vel)
    acc = mp if accel is None else _writable(accel)
    _correct(p, v, acc, accel is not None, mp, mv, np.ascontiguousarray(count, dtype=np.int64),
             _writable(gains), float(dt))  # fmt: skip
    if p is not est_pos:
        est_pos[...] = p
    if v is not est_vel:
        est_vel[...] = v


# ---------------------------------------------------------------- the whole physics step
# Each kernel is a loop over rows (environments), serial or spread over the cores in tasks of
# _ROWS_PER_TASK rows (common._parallel: large batches only); a row's numbers are the same
# either way.
# fmt: off
@numba.njit(inline="always", **_JIT)
def _advance_rows(e0, e1, uav_pos, uav_vel, accel_cmd, normals, uav_acc, dt, max_speed,  # noqa: ANN001, ANN202
                  max_accel, u, switch_prob, time, hold_until, straight_prob, max_turn,  # noqa: ANN001
                  max_climb, turn, climb, pos, band, wind, ground, new_turn, new_climb, y, mid,  # noqa: ANN001
                  heading):  # noqa: ANN001
# fmt: on
    """The UAVs' double integrator with their process noise, then the obstacles' commands."""
    half_dt = 0.5 * dt
    for e in range(e0, e1):
        for i in range(uav_pos.shape[1]):
            z = 3 * i  # the acceleration noise's columns
            a0 = _minimum(_maximum(accel_cmd[e, i, 0], -max_accel), max_accel) + normals[e, z]
            a1 = _minimum(_maximum(accel_cmd[e, i, 1], -max_accel), max_accel) + normals[e, z + 1]
            a2 = _minimum(_maximum(accel_cmd[e, i, 2], -max_accel), max_accel) + normals[e, z + 2]
            v0, v1, v2 = uav_vel[e, i, 0], uav_vel[e, i, 1], uav_vel[e, i, 2]
            n0, n1, n2, a0, a1, a2 = _speed_limited(v0, v1, v2, a0, a1, a2, dt, max_speed)
            uav_pos[e, i, 0] += half_dt * (v0 + n0)
            uav_pos[e, i, 1] += half_dt * (v1 + n1)
            uav_pos[e, i, 2] += half_dt * (v2 + n2)
            uav_vel[e, i, 0], uav_vel[e, i, 1], uav_vel[e, i, 2] = n0, n1, n2
            uav_acc[e, i, 0], uav_acc[e, i, 1], uav_acc[e, i, 2] = a0, a1, a2
    _commands_rows(e0, e1, u, switch_prob, time, True, hold_until, straight_prob, max_turn,
                   max_climb, turn, climb, pos, band, wind, ground, dt, new_turn, new_climb, y,
                   mid, heading)  # fmt: skip


# Arguments spelled out, not ``*args``: arrays read from a tuple inside a parallel loop lost
# their writes once (rewards._outcome_parallel's note).
@numba.njit(**_JIT)
def _advance(uav_pos, uav_vel, accel_cmd, normals, uav_acc, dt, max_speed, max_accel, u, switch_prob, time, hold_until, straight_prob, max_turn, max_climb, turn, climb, pos, band, wind, ground, new_turn, new_climb, y, mid, heading):  # noqa: ANN001, ANN202, E501  # fmt: skip
    _advance_rows(0, uav_pos.shape[0], uav_pos, uav_vel, accel_cmd, normals, uav_acc, dt, max_speed, max_accel, u, switch_prob, time, hold_until, straight_prob, max_turn, max_climb, turn, climb, pos, band, wind, ground, new_turn, new_climb, y, mid, heading)  # noqa: E501  # fmt: skip


@numba.njit(parallel=True, **_JIT)
def _advance_parallel(uav_pos, uav_vel, accel_cmd, normals, uav_acc, dt, max_speed, max_accel, u, switch_prob, time, hold_until, straight_prob, max_turn, max_climb, turn, climb, pos, band, wind, ground, new_turn, new_climb, y, mid, heading):  # noqa: ANN001, ANN202, E501  # fmt: skip
    n_rows = uav_pos.shape[0]
    for c in numba.prange((n_rows + _ROWS_PER_TASK - 1) // _ROWS_PER_TASK):
        e0 = c * _ROWS_PER_TASK
        _advance_rows(e0, min(e0 + _ROWS_PER_TASK, n_rows), uav_pos, uav_vel, accel_cmd, normals, uav_acc, dt, max_speed, max_accel, u, switch_prob, time, hold_until, straight_prob, max_turn, max_climb, turn, climb, pos, band, wind, ground, new_turn, new_climb, y, mid, heading)  # noqa: E501  # fmt: skip


# fmt: off
@numba.njit(inline="always", **_JIT)
def _sense_rows(e0, e1, time, count, dt, kalman, uav_pos, uav_vel, uav_acc, normals, est_pos,  # noqa: ANN001, ANN202
                est_vel, pos, speed, climb, cos_h, sin_h, wind, active, obstacle_est_pos,  # noqa: ANN001
                obstacle_est_vel, uav_gains, obstacle_gains, min_uav, min_obstacle):  # noqa: ANN001
# fmt: on
    """The clock, both tracks' measurements and Kalman steps, and the running separations."""
    n, m = uav_pos.shape[1], pos.shape[1]
    for e in range(e0, e1):
        time[e] += dt
        if kalman:
            count[e] += 1
        g = min(count[e], uav_gains.shape[0] - 1)
        for i in range(n):
            for a in range(3):
                mp = uav_pos[e, i, a] + normals[e, 3 * n + 6 * i + a]
                mv = uav_vel[e, i, a] + normals[e, 3 * n + 6 * i + 3 + a]
                if kalman:  # the known input: the applied acceleration less its noise
                    known = uav_acc[e, i, a] - normals[e, 3 * i + a]
                    est_pos[e, i, a], est_vel[e, i, a] = _predict_correct(
                        est_pos[e, i, a], est_vel[e, i, a], known, True, mp, mv, g, uav_gains, dt)
                else:
                    est_pos[e, i, a], est_vel[e, i, a] = mp, mv
        g = min(count[e], obstacle_gains.shape[0] - 1)
        for j in range(m):
            # The ground velocity (obstacles.obstacle_velocity), then its measurement.
            v0 = speed[e, j] * cos_h[e, j] + wind[e, 0]
            v1 = speed[e, j] * sin_h[e, j] + wind[e, 1]
            v2 = -climb[e, j] + wind[e, 2]
            for a in range(3):
                mp = pos[e, j, a] + normals[e, 9 * n + 6 * j + a]
                mv = (v0 if a == 0 else v1 if a == 1 else v2) + normals[e, 9 * n + 6 * j + 3 + a]
                if kalman:
                    obstacle_est_pos[e, j, a], obstacle_est_vel[e, j, a] = _predict_correct(
                        obstacle_est_pos[e, j, a], obstacle_est_vel[e, j, a], 0.0, False, mp,
                        mv, g, obstacle_gains, dt)  # fmt: skip
                else:
                    obstacle_est_pos[e, j, a], obstacle_est_vel[e, j, a] = mp, mv
        for i in range(n):
            d_uav, d_obstacle = _nearest(uav_pos, pos, active, e, i)
            min_uav[e, i] = _minimum(min_uav[e, i], d_uav)
            min_obstacle[e, i] = _minimum(min_obstacle[e, i], d_obstacle)


@numba.njit(**_JIT)
def _sense(time, count, dt, kalman, uav_pos, uav_vel, uav_acc, normals, est_pos, est_vel, pos, speed, climb, cos_h, sin_h, wind, active, obstacle_est_pos, obstacle_est_vel, uav_gains, obstacle_gains, min_uav, min_obstacle):  # noqa: ANN001, ANN202, E501  # fmt: skip
    _sense_rows(0, uav_pos.shape[0], time, count, dt, kalman, uav_pos, uav_vel, uav_acc, normals, est_pos, est_vel, pos, speed, climb, cos_h, sin_h, wind, active, obstacle_est_pos, obstacle_est_vel, uav_gains, obstacle_gains, min_uav, min_obstacle)  # noqa: E501  # fmt: skip


@numba.njit(parallel=True, **_JIT)
def _sense_parallel(time, count, dt, kalman, uav_pos, uav_vel, uav_acc, normals, est_pos, est_vel, pos, speed, climb, cos_h, sin_h, wind, active, obstacle_est_pos, obstacle_est_vel, uav_gains, obstacle_gains, min_uav, min_obstacle):  # noqa: ANN001, ANN202, E501  # fmt: skip
    n_rows = uav_pos.shape[0]
    for c in numba.prange((n_rows + _ROWS_PER_TASK - 1) // _ROWS_PER_TASK):
        e0 = c * _ROWS_PER_TASK
        _sense_rows(e0, min(e0 + _ROWS_PER_TASK, n_rows), time, count, dt, kalman, uav_pos, uav_vel, uav_acc, normals, est_pos, est_vel, pos, speed, climb, cos_h, sin_h, wind, active, obstacle_est_pos, obstacle_est_vel, uav_gains, obstacle_gains, min_uav, min_obstacle)  # noqa: E501  # fmt: skip


def physics_step(w, obs, normals, uniforms, p, replay=None, *, n_uniforms: int) -> None:  # noqa: ANN001
    """:func:`uasep_env.sim.physics_step.physics_step`, compiled: same arguments, same bits.

    Three kernels; numpy's sines and cosines between them (of the arcs, then of the new
    headings). The world's arrays are C-contiguous and written in place. ``n_uniforms``:
    :data:`uasep_env.sim.obstacles.N_UNIFORMS`.
    """
    shape = obs.heading.shape
    new_turn, new_climb, y, mid, heading = (np.empty(shape) for _ in range(5))
    dt = float(p.dt)
    normals = np.ascontiguousarray(normals)
    parallel = _parallel(w.uav_pos.shape[0] * w.uav_pos.shape[1])
    advance, sense = (_advance_parallel, _sense_parallel) if parallel else (_advance, _sense)
    advance(w.uav_pos, w.uav_vel, w.accel_cmd, normals, w.uav_acc, dt, float(p.max_speed),
             float(p.max_accel), np.ascontiguousarray(uniforms).reshape(*shape, n_uniforms),
             obs.switch_prob, w.time, obs.hold_until, obs.straight_prob, obs.max_turn_rate,
             obs.max_climb_rate, obs.turn_rate, obs.climb_rate, obs.pos, obs.alt_band, obs.wind,
             obs.ground, new_turn, new_climb, y, mid, obs.heading)  # fmt: skip
    # numpy's sin and cos, not libm's: the numpy form's numbers to the last bit.
    _move(obs.pos, obs.heading, obs.speed, new_climb, obs.active, obs.wind, obs.ground, dt, y,
          np.sin(y), np.cos(mid), np.sin(mid), new_turn, heading)  # fmt: skip
    obs.turn_rate, obs.climb_rate, obs.heading = new_turn, new_climb, heading
    if replay is not None:
        replay.step(obs, w.time)
    sense(w.time, w.kf_count, dt, bool(p.kalman), w.uav_pos, w.uav_vel, w.uav_acc, normals,
           w.est_pos, w.est_vel, obs.pos, obs.speed, obs.climb_rate, np.cos(obs.heading),
           np.sin(obs.heading), obs.wind, obs.active, w.obstacle_est_pos, w.obstacle_est_vel,
           p.uav_gains, p.obstacle_gains, w.min_uav_dist, w.min_obstacle_dist)  # fmt: skip
