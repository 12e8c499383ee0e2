"""UAV dynamics (eqs. 1-4) and estimation (Kalman filter)."""

import numpy as np
import pytest
from conftest import arrays, given, settings, st

from uasep_env.sim.dynamics import measure, step_double_integrator, transition_matrices
from uasep_env.sim.estimation import KalmanModel

finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


def test_matches_eq1_state_space_form_when_limits_inactive():
    rng = np.random.default_rng(0)
    dt = 0.2
    a_mat, b_mat = transition_matrices(dt)
    pos = rng.normal(size=(4, 3))
    vel = rng.normal(size=(4, 3))
    acc = rng.uniform(-1, 1, size=(4, 3))
    x = np.concatenate([pos, vel], axis=1)
    expected = x @ a_mat.T + acc @ b_mat.T
    p, v = pos.copy(), vel.copy()
    applied = step_double_integrator(p, v, acc, None, dt, max_speed=100.0, max_accel=10.0)
    np.testing.assert_allclose(np.concatenate([p, v], axis=1), expected, atol=1e-12)
    np.testing.assert_allclose(applied, acc)


def test_acceleration_bounded_per_axis():
    p, v = np.zeros((1, 3)), np.zeros((1, 3))
    applied = step_double_integrator(p, v, np.array([[50.0, -50.0, 0.5]]), None, 0.1, 100.0, 2.0)
    np.testing.assert_allclose(applied, [[2.0, -2.0, 0.5]])


@settings(max_examples=200, deadline=None)
@given(
    vel=arrays(float, (5, 3), elements=st.floats(-50, 50)),
    acc=arrays(float, (5, 3), elements=finite),
    noise=arrays(float, (5, 3), elements=st.floats(-100, 100)),
    dt=st.floats(1e-3, 5.0),
    vmax=st.floats(0.1, 60.0),
)
def test_speed_limit_never_exceeded_after_a_step(vel, acc, noise, dt, vmax):
    # Eq. 3-4: whatever the command, noise and initial velocity, |v| <= V_max after a step.
    pos = np.zeros_like(vel)
    v = vel.copy()
    applied = step_double_integrator(pos, v, acc, noise, dt, vmax, 3.0)
    speed = np.linalg.norm(v, axis=1)
    assert np.all(speed <= vmax * (1 + 1e-12))
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(applied))
    # Position follows the exact double integrator with the applied acceleration.
    np.testing.assert_allclose(pos, vel * dt + 0.5 * applied * dt * dt, rtol=1e-9, atol=1e-6)


def test_measure_adds_noise_and_copies():
    p, v = np.ones((2, 3)), np.zeros((2, 3))
    mp, mv = measure(p, v, np.full((2, 3), 0.5), None)
    np.testing.assert_allclose(mp, 1.5)
    mv[0, 0] = 9.0
    assert v[0, 0] == 0.0


def _simulate_tracks(sigma_p, sigma_v, sigma_a, steps=400, n=200, seed=1):
    rng = np.random.default_rng(seed)
    dt = 0.2
    kf = KalmanModel(dt, sigma_a, sigma_p, sigma_v)
    pos = rng.normal(scale=10, size=(1, n, 3))
    vel = rng.normal(size=(1, n, 3))
    est_p = pos + rng.normal(scale=sigma_p, size=pos.shape)
    est_v = vel + rng.normal(scale=sigma_v, size=vel.shape)
    err_kf, err_raw = [], []
    count = np.zeros(1, dtype=np.int64)
    for _ in range(steps):
        cmd = rng.uniform(-0.5, 0.5, size=pos.shape)
        noise = rng.normal(scale=sigma_a, size=pos.shape)
        applied = step_double_integrator(pos, vel, cmd, noise, dt, 1e9, 10.0)
        mp = pos + rng.normal(scale=sigma_p, size=pos.shape)
        mv = vel + rng.normal(scale=sigma_v, size=vel.shape)
        count += 1
        kf.update(est_p, est_v, applied - noise, mp, mv, count)
        err_kf.append(np.linalg.norm(est_p - pos, axis=-1).mean())
        err_raw.append(np.linalg.norm(mp - pos, axis=-1).mean())
    return np.mean(err_kf[50:]), np.mean(err_raw[50:]), kf


def test_kalman_reduces_position_error_against_raw_measurements():
    kf_err, raw_err, kf = _simulate_tracks(sigma_p=1.0, sigma_v=0.2, sigma_a=0.05)
    assert kf_err < 0.6 * raw_err, (kf_err, raw_err)
    # The filter's own steady-state covariance agrees with the measured error (within 25 %).
    expected = kf.steady_state_position_std() * np.sqrt(8 / np.pi)  # mean of a 3D chi
    assert abs(kf_err - expected) / expected < 0.25


def test_kalman_exact_when_noise_free():
    kf_err, raw_err, _ = _simulate_tracks(sigma_p=0.0, sigma_v=0.0, sigma_a=0.0, steps=60)
    assert kf_err < 1e-9 and raw_err < 1e-12


def test_kalman_gain_table_converges():
    kf = KalmanModel(0.2, 0.05, 0.5, 0.1)
    assert len(kf.gains) < 4096
    np.testing.assert_allclose(kf.gains[-1], kf.gains[-2], atol=1e-9)
    assert np.all(np.linalg.eigvalsh(kf.covariances[-1]) > 0)


@pytest.mark.parametrize("sp,sv", [(0.0, 0.3), (0.5, 0.0)])
def test_kalman_partially_noise_free_is_finite(sp, sv):
    kf_err, _raw_err, _ = _simulate_tracks(sigma_p=sp, sigma_v=sv, sigma_a=0.1, steps=100)
    assert np.isfinite(kf_err)


def test_kalman_converged_tracks_share_one_gain_exactly():
    """Once every track has converged one gain is used; the result is the per-env gather's."""
    kf = KalmanModel(0.2, 0.05, 0.5, 0.1)
    last = len(kf.gains) - 1
    rng = np.random.default_rng(3)
    est = [rng.normal(0, 5, size=(4, 2, 3)) for _ in range(2)]
    acc, mp, mv = (rng.normal(0, 1, size=(4, 2, 3)) for _ in range(3))
    results = []
    for count in (np.array([last, last + 5, last, 10**6]), np.array([last, last + 5, 1, 10**6])):
        p, v = est[0].copy(), est[1].copy()
        kf.update(p, v, acc, mp, mv, count)
        results.append((p, v))
    (p1, v1), (p2, v2) = results
    keep = [0, 1, 3]  # the converged rows of the mixed batch (env 2 still uses an early gain)
    np.testing.assert_array_equal(p1[keep], p2[keep])
    np.testing.assert_array_equal(v1[keep], v2[keep])
    assert not np.array_equal(p1[2], p2[2])
