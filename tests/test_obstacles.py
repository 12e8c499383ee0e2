"""Obstacle motion: 3D Dubins bounds."""

import numpy as np
from conftest import given, settings, st

from uasep_env.sim.obstacles import N_UNIFORMS, ObstacleState, obstacle_velocity, step_obstacles


def _make(n_envs, m, rng, w_max, vz_max, speed):
    ob = ObstacleState(n_envs, m)
    ob.pos[...] = rng.normal(scale=100, size=ob.pos.shape)
    ob.pos[..., 2] = -100.0
    ob.heading[...] = rng.uniform(-np.pi, np.pi, size=ob.heading.shape)
    ob.speed[...] = speed
    ob.max_turn_rate[...] = w_max
    ob.max_climb_rate[...] = vz_max
    ob.alt_band[..., 0], ob.alt_band[..., 1] = 50.0, 150.0
    ob.active[...] = True
    ob.switch_prob[...] = 0.2
    ob.straight_prob[...] = 0.3
    return ob


@settings(max_examples=40, deadline=None)
@given(
    w_max=st.floats(0.0, 2.0),
    vz_max=st.floats(0.0, 5.0),
    speed=st.floats(0.1, 60.0),
    dt=st.floats(0.01, 2.0),
    seed=st.integers(0, 2**31),
)
def test_bounds_never_exceeded(w_max, vz_max, speed, dt, seed):
    rng = np.random.default_rng(seed)
    ob = _make(4, 3, rng, w_max, vz_max, speed)
    for _ in range(100):
        prev_pos, prev_heading = ob.pos.copy(), ob.heading.copy()
        step_obstacles(ob, rng.random((4, 3, N_UNIFORMS)), dt)
        assert np.all(np.abs(ob.turn_rate) <= w_max + 1e-12)
        assert np.all(np.abs(ob.climb_rate) <= vz_max + 1e-12)
        horiz = np.linalg.norm(ob.pos[..., :2] - prev_pos[..., :2], axis=-1)
        # Constant speed: the arc is v dt long, so the chord is at most v dt.
        assert np.all(horiz <= speed * dt * (1 + 1e-9))
        turn = np.abs(np.angle(np.exp(1j * (ob.heading - prev_heading))))
        assert np.all(turn <= w_max * dt + 1e-9)
        assert np.all(np.abs(ob.pos[..., 2] - prev_pos[..., 2]) <= vz_max * dt + 1e-9)
        alt = -ob.pos[..., 2]
        assert np.all((alt >= 50.0 - 1e-9) & (alt <= 150.0 + 1e-9))
        assert np.all(np.isfinite(ob.pos))


def test_exact_circle_with_constant_turn():
    rng = np.random.default_rng(0)
    ob = _make(1, 1, rng, 0.1, 0.0, 10.0)
    ob.switch_prob[...] = 0.0
    ob.turn_rate[...] = 0.1
    ob.pos[...] = 0.0
    ob.heading[...] = 0.0
    steps = round(2 * np.pi / 0.1 / 0.5)  # one full circle with dt = 0.5
    for _ in range(steps):
        step_obstacles(ob, np.zeros((1, 1, N_UNIFORMS)), 0.5)
    # After a full turn (up to rounding of the step count) the obstacle is back near start.
    assert np.linalg.norm(ob.pos[0, 0, :2]) < 10.0 * 0.5
    # Radius: every point lies on the circle of radius v / w around (0, 100).
    ob.pos[...] = 0.0
    ob.heading[...] = 0.0
    for _ in range(17):
        step_obstacles(ob, np.zeros((1, 1, N_UNIFORMS)), 0.37)
        r = np.linalg.norm(ob.pos[0, 0, :2] - np.array([0.0, 100.0]))
        assert abs(r - 100.0) < 1e-9


def test_velocity_includes_wind():
    rng = np.random.default_rng(0)
    ob = _make(2, 1, rng, 0.1, 1.0, 5.0)
    ob.wind[:] = [1.0, -2.0, 0.0]
    v = obstacle_velocity(ob)
    np.testing.assert_allclose(np.linalg.norm(v[..., :2] - ob.wind[:, None, :2], axis=-1), 5.0)


@settings(max_examples=40, deadline=None)
@given(
    vz_max=st.floats(0.0, 5.0),
    wind_down=st.floats(-5.0, 10.0),
    ground=st.floats(-50.0, 60.0),
    dt=st.floats(0.01, 2.0),
    seed=st.integers(0, 2**31),
)
def test_obstacles_never_fly_below_the_ground(vz_max, wind_down, ground, dt, seed):
    """Descents are bounded near the ground (|c| <= vz_max kept); a downdraft rests them there."""
    rng = np.random.default_rng(seed)
    ob = _make(4, 3, rng, 0.1, vz_max, 8.0)
    ob.alt_band[..., 0] = -1e9  # only the ground holds them up
    ob.pos[..., 2] = -(ground + rng.uniform(0.0, 20.0, size=(4, 3)))
    ob.ground[...] = ground
    ob.wind[:, 2] = wind_down
    ob.switch_prob[...] = 0.5
    for _ in range(200):
        step_obstacles(ob, rng.random((4, 3, N_UNIFORMS)), dt)
        assert np.all(-ob.pos[..., 2] >= ground)
        assert np.all(np.abs(ob.climb_rate) <= vz_max + 1e-12)


def test_the_ground_rule_is_a_no_op_in_the_air():
    """High above the ground the model moves exactly as without it (episodes in the air kept)."""
    rng = np.random.default_rng(3)
    a = _make(4, 3, rng, 0.1, 2.0, 8.0)
    b = _make(4, 3, np.random.default_rng(3), 0.1, 2.0, 8.0)
    b.ground[...] = -1e9
    for _ in range(300):
        u = rng.random((4, 3, N_UNIFORMS))
        step_obstacles(a, u, 0.2)
        step_obstacles(b, u, 0.2)
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.climb_rate, b.climb_rate)


@settings(max_examples=25, deadline=None)
@given(
    vz_max=st.floats(0.1, 3.0),
    wind_down=st.floats(0.0, 6.0),
    height=st.floats(0.0, 15.0),
    seed=st.integers(0, 2**31),
)
def test_the_prediction_still_encloses_obstacles_at_the_ground(vz_max, wind_down, height, seed):
    """Bounded descents and resting on the ground stay inside the enclosing prediction.

    The world's prediction: the obstacle's reachable ellipsoid (swept, enclosing fit) about
    its position and heading, its radius inflated by ``|wind| * horizon``. Start just above
    the ground in a downdraft (stronger than vz_max in some examples) and check every
    position over the horizon.
    """
    from uasep_env import reachable

    rng = np.random.default_rng(seed)
    dt, horizon, steps = 0.2, 10.0, 50
    ob = _make(4, 3, rng, 0.1, vz_max, 6.0)
    ob.alt_band[..., 0] = -1e9
    ob.pos[..., 2] = -height
    ob.ground[...] = 0.0
    ob.wind[:] = [1.0, -0.5, wind_down]
    ob.switch_prob[...] = 0.3
    ob.climb_rate[...] = -vz_max  # descending towards the ground
    p0, psi0 = ob.pos.copy(), ob.heading.copy()
    r = 1.0 + np.linalg.norm(ob.wind[0]) * horizon
    offset, axes = reachable.ellipsoid(6.0, 0.1, vz_max, horizon, r)
    center = p0 + offset * np.stack([np.cos(psi0), np.sin(psi0), np.zeros_like(psi0)], -1)
    for _ in range(steps):
        step_obstacles(ob, rng.random((4, 3, N_UNIFORMS)), dt)
        assert np.all(-ob.pos[..., 2] >= 0.0)
        assert np.all(reachable.contains(ob.pos, center, axes, psi0))
