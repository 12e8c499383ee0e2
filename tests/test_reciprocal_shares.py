"""ORCA's and MVP's reciprocal share, against two-UAV cases computed by hand (issue 53, item 6).

Changing either default share from 1/2 to 1 passed every other test: these pin it. The
expected numbers come from the published definitions, worked out here, not from the code:

* ORCA (van den Berg, Guy, Lin and Manocha 2011): ``u`` is the smallest change of the
  relative velocity ``v_A - v_B`` that puts it on the boundary of the velocity obstacle
  truncated at ``tau``; each UAV takes half: ``ORCA_A = {v : (v - (v_A + u / 2)) . n >= 0}``.
* MVP (Hoekstra et al. 2002, BlueSky's resolution): each UAV of a pair takes half of the
  change that makes the pair's relative path graze the protected zone of radius ``R``.
"""

import math

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.policies import MVP, ORCA, MVPParams, ORCAParams

CONFIG = make_config(n_uavs=2, n_obstacles=1)
SEP = CONFIG.uav.separation_distance  # 8 m: ORCA's combined radius, MVP's zone before margin


def _decoded(rel_pos, rel_vel, velocity=(0.0, 0.0, 0.0)):
    """One UAV's decoded observation with one neighbour UAV and no obstacle in sight."""
    return {
        "velocity": np.array([velocity], dtype=float),
        "uav_rel_pos": np.array([[rel_pos]], dtype=float),  # p_j - p_i
        "uav_rel_vel": np.array([[rel_vel]], dtype=float),  # v_j - v_i
        "uav_mask": np.array([[True]]),
        "obstacle_rel_pos": np.zeros((1, 1, 3)),
        "obstacle_rel_vel": np.zeros((1, 1, 3)),
        "obstacle_mask": np.array([[False]]),
    }


def test_orca_each_uav_takes_half_of_u_head_on():
    # A at the origin flying +x at 1.5 m/s, B 20 m ahead flying -x at 1.5 m/s.
    tau, radius = 5.0, SEP
    assert ORCAParams().time_horizon == tau and radius == 8.0  # the case's premises
    p, v_a, v_b = 20.0, 1.5, -1.5
    v_rel = v_a - v_b  # 3 m/s closing along the line of centres
    # Along the line of centres the VO truncated at tau starts at the slowest closing speed
    # that still meets within tau: (|p| - R) / tau = 2.4 m/s (the cut-off sphere's front,
    # nearer than the cone's sides: 3 sin(asin(8/20)) = 1.2 m/s away). So u = -0.6 e_x.
    u = (p - radius) / tau - v_rel
    assert u == pytest.approx(-0.6)
    orca = ORCA(CONFIG, ORCAParams(margin_scale=1.0))  # radii at the separation distance
    o = _decoded((p, 0.0, 0.0), (v_b - v_a, 0.0, 0.0), (v_a, 0.0, 0.0))
    normals, points, _ = orca.planes(o)
    np.testing.assert_allclose(normals[0, 0], [-1.0, 0.0, 0.0], atol=1e-12)  # n = u / |u|
    np.testing.assert_allclose(points[0, 0], [v_a + u / 2, 0.0, 0.0], atol=1e-12)
    # Preferring its current velocity, A slows by |u| / 2; B, seeing the mirror case, alike:
    # together they take exactly u, the pair's relative velocity lands on the VO's boundary.
    new_a = orca.new_velocity(o, o["velocity"])[0]
    mirror = _decoded((-p, 0.0, 0.0), (v_a - v_b, 0.0, 0.0), (v_b, 0.0, 0.0))
    new_b = orca.new_velocity(mirror, mirror["velocity"])[0]
    np.testing.assert_allclose(new_a, [v_a + u / 2, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(new_b, [v_b - u / 2, 0.0, 0.0], atol=1e-9)
    assert new_a[0] - new_b[0] == pytest.approx((p - radius) / tau)


def test_mvp_each_uav_takes_half_of_the_resolution():
    # B 20 m ahead and 2 m to the left of A, closing at 4 m/s along x: CPA in 5 s at 2 m.
    params = MVPParams(margin_scale=1.0)  # BlueSky's zone: 1.05 times the separation
    radius = params.margin_factor * SEP  # 8.4 m
    d, w_x = np.array([20.0, 2.0, 0.0]), -4.0  # d = p_B - p_A, w = v_B - v_A
    # Both UAVs resolve (B sees the mirror case), so the pair's new relative velocity is
    # (w_x, s) with s = -2 dv_A,y; the resolution makes the relative path graze the zone:
    # |d x w'| / |w'| = R, i.e. (20 s - 2 w_x)^2 = R^2 (w_x^2 + s^2), a quadratic in s whose
    # positive root turns the path away from the side B already passes on (+y).
    a = d[0] ** 2 - radius**2
    b = -2.0 * d[0] * d[1] * w_x
    c = (d[1] * w_x) ** 2 - radius**2 * w_x**2
    s = (-b + math.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    assert s == pytest.approx(1.3767, abs=1e-4)
    mvp = MVP(CONFIG, params)
    dv_a = mvp.velocity_change(_decoded(d, (w_x, 0.0, 0.0)))[0]
    dv_b = mvp.velocity_change(_decoded(-d, (-w_x, 0.0, 0.0)))[0]
    np.testing.assert_allclose(dv_a, [0.0, -s / 2.0, 0.0], atol=1e-9)  # half each
    np.testing.assert_allclose(dv_b, [0.0, s / 2.0, 0.0], atol=1e-9)
