"""Formation geometry (eqs. 5-7) and the planned trajectory."""

import numpy as np
import pytest
from conftest import arrays, given, settings, st

from uasep_env.config import FORMATION_PATTERNS
from uasep_env.sim.formation import (
    PlannedTrajectory,
    formation_center,
    pattern_slots,
    rotation_from_velocity,
)


def test_center_is_mean_state_eq5():
    pos = np.arange(18.0).reshape(2, 3, 3)
    vel = -pos
    c, v = formation_center(pos, vel)
    np.testing.assert_allclose(c, pos.mean(axis=1))
    np.testing.assert_allclose(v, vel.mean(axis=1))


@settings(max_examples=200, deadline=None)
@given(arrays(float, (3,), elements=st.floats(-50, 50)))
def test_rotation_is_proper_and_y_axis_on_velocity_eq6(vel):
    speed = np.linalg.norm(vel)
    c = rotation_from_velocity(vel, fallback=np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(c.T @ c, np.eye(3), atol=1e-9)
    assert np.linalg.det(c) == pytest.approx(1.0, abs=1e-9)
    assert abs(c[2, 0]) < 1e-12  # X_f is horizontal
    if speed >= 0.5:
        np.testing.assert_allclose(c[:, 1], vel / speed, atol=1e-9)  # Y_f along v_o
    else:
        np.testing.assert_allclose(c[:, 1], [0.0, 1.0, 0.0], atol=1e-9)  # planned heading


def test_level_flight_north_frame():
    c = rotation_from_velocity(np.array([5.0, 0.0, 0.0]))
    np.testing.assert_allclose(c[:, 0], [0, 1, 0], atol=1e-12)  # X_f starboard = east
    np.testing.assert_allclose(c[:, 2], [0, 0, -1], atol=1e-12)  # Z_f up


def test_slots_eq7_paper_pattern_flying_east():
    slots = pattern_slots("paper", 3, 20.0)
    np.testing.assert_allclose(slots, [[-20, 0, 0], [20, 0, 0], [0, 0, 0]])
    c = rotation_from_velocity(np.array([0.0, 5.0, 0.0]))  # flying east
    p_o = np.array([100.0, 50.0, -100.0])
    desired = slots @ c.T + p_o
    # Starboard of east is south (-x): the -20 slot is 20 m north.
    np.testing.assert_allclose(desired[0], [120.0, 50.0, -100.0], atol=1e-9)
    np.testing.assert_allclose(desired[2], p_o, atol=1e-9)


@pytest.mark.parametrize("pattern", FORMATION_PATTERNS)
@pytest.mark.parametrize("n", [2, 3, 5, 8, 32])
def test_patterns_centred_distinct_and_spaced(pattern, n):
    slots = pattern_slots(pattern, n, 15.0)
    assert slots.shape == (n, 3)
    np.testing.assert_allclose(slots.mean(axis=0), 0.0, atol=1e-9)
    d = np.linalg.norm(slots[:, None] - slots[None], axis=-1) + np.eye(n) * 1e9
    assert d.min() >= 15.0 - 1e-9


def test_planned_trajectory_flown_at_cruise_speed():
    wp = np.array([[[0, 0, -100], [100, 0, -100], [100, 100, -100], [100, 100, -100]]], float)
    plan = PlannedTrajectory(wp, 5.0)
    pos, vel = plan.center(np.array([10.0]))
    np.testing.assert_allclose(pos[0], [50, 0, -100])
    np.testing.assert_allclose(vel[0], [5, 0, 0])
    pos, vel = plan.center(np.array([30.0]))
    np.testing.assert_allclose(pos[0], [100, 50, -100])
    np.testing.assert_allclose(vel[0], [0, 5, 0])
    pos, vel = plan.center(np.array([100.0]))  # past the end: stays at the last way-point
    np.testing.assert_allclose(pos[0], [100, 100, -100])
    np.testing.assert_allclose(vel[0], 0.0)
    assert plan.finished(np.array([40.0]))[0] and not plan.finished(np.array([39.0]))[0]
    slots = pattern_slots("paper", 3, 20.0)[None]
    upos, _ = plan.uav_positions(np.array([10.0]), slots)
    np.testing.assert_allclose(upos[0, 1], [50, 20, -100])  # +20 slot is starboard (east)


def test_center_and_direction_agree_with_the_separate_queries():
    rng = np.random.default_rng(4)
    wp = np.cumsum(rng.normal(0, 50, size=(5, 4, 3)), axis=1)
    plan = PlannedTrajectory(wp, rng.uniform(5, 15, size=5))
    for t in (0.0, 3.0, 40.0, 1e4):
        times = np.full(5, t)
        pos, vel, d = plan.center_and_direction(times)
        np.testing.assert_array_equal(pos, plan.center(times)[0])
        np.testing.assert_array_equal(vel, plan.center(times)[1])
        np.testing.assert_array_equal(d, plan.heading_velocity(times))


def test_segment_offsets_give_uav_positions_bit_for_bit():
    """The world's lookup of rotated slots per segment is uav_positions' rotation, exactly."""
    from uasep_env.sim.formation import segment_offsets

    rng = np.random.default_rng(9)
    wp = np.cumsum(rng.normal(0, 50, size=(6, 5, 3)), axis=1)
    wp[0, 3:] = wp[0, 2]  # padding segments at the end
    wp[1, 1:, :2] = wp[1, 0, :2]  # vertical segments
    plan = PlannedTrajectory(wp, rng.uniform(5, 15, size=6))
    slots = rng.normal(0, 20, size=(6, 3, 3))
    offsets = segment_offsets(plan.direction, slots)
    assert offsets.shape == (6, 4, 3, 3)
    seen = set()
    for t in np.linspace(0.0, 80.0, 161):
        times = np.full(6, t)
        _, idx = plan.locate(times)
        seen.update(idx.tolist())
        center, _ = plan.center(times)
        want, _ = plan.uav_positions(times, slots)
        np.testing.assert_array_equal(center[:, None] + offsets[np.arange(6), idx], want)
    assert seen == {0, 1, 2, 3}


def test_usual_case_shortcuts_give_the_general_paths_numbers():
    """The frame and the plan's directions of a batch with no odd row (every velocity
    level and fast, no padding segment) are the general path's numbers, bit for bit: the
    same rows computed inside a batch that takes the general path."""
    rng = np.random.default_rng(11)
    vel = rng.normal(0, 8, size=(40, 3))
    vel[:, :2] += 3.0  # level enough everywhere
    odd = np.array([[0.0, 0.0, 5.0], [0.1, 0.0, 0.0]])  # vertical; below MIN_FRAME_SPEED
    fallback = rng.normal(0, 5, size=(42, 3))
    usual = rotation_from_velocity(vel, fallback[:40])
    general = rotation_from_velocity(np.concatenate([vel, odd]), fallback)
    np.testing.assert_array_equal(usual, general[:40])
    assert not np.array_equal(general[40], usual[0])  # the odd rows took the other path

    wp = np.cumsum(rng.normal(0, 50, size=(6, 5, 3)), axis=1)
    padded = wp.copy()
    padded[-1, 3:] = padded[-1, 2]  # a padding segment sends the batch down the loop
    plain = PlannedTrajectory(wp[:-1], 10.0)
    looped = PlannedTrajectory(padded, 10.0)
    np.testing.assert_array_equal(plain.direction, looped.direction[:-1])
    np.testing.assert_array_equal(plain.cum, looped.cum[:-1])
    np.testing.assert_array_equal(looped.direction[-1, 3], looped.direction[-1, 2])
    np.testing.assert_array_equal(plain.cruise_speed, np.full(5, 10.0))
