"""Reachable-set prediction (eqs. 8-18 with the notes' errata): enclosure by Monte Carlo,
tightness, and the point-to-ellipsoid distance against brute force."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uasep_env import reachable as R

PARAMS = [
    # (v m/s, w_max rad/s, t s, r m, vz_max m/s)
    (4.0, 0.013, 10.0, 3.0, 0.5),  # the paper's example
    (10.0, 0.2, 10.0, 3.0, 1.0),
    (5.0, 0.5, 10.0, 2.0, 2.0),  # w t = 5 > pi
    (8.0, 1.0, 20.0, 0.0, 0.0),  # w t = 20 > 2 pi, no radius
    (30.0, 0.05, 30.0, 10.0, 3.0),
    (1.0, 0.0, 15.0, 1.0, 0.3),  # straight only
]


def _dubins_samples(v, w, vz, t, n, rng, n_steps=60):
    """Positions of random 3D Dubins trajectories over [0, t] (obstacle frame: x forward)."""
    dt = t / n_steps
    pos = np.zeros((n, 3))
    heading = np.zeros(n)
    out = [pos.copy()]
    kind = rng.integers(0, 4, n)
    turn = rng.uniform(-w, w, n)
    climb = rng.uniform(-vz, vz, n)
    switch_at = rng.uniform(0, t, n)
    bang = np.where(rng.random(n) < 0.5, -w, w)
    for k in range(n_steps):
        tk = k * dt
        om = np.select(
            [kind == 0, kind == 1, kind == 2, kind == 3],
            [
                rng.uniform(-w, w, n),  # random switching every step
                np.where(tk < switch_at, bang, -bang),  # bang-bang
                np.where(tk < switch_at, bang, 0.0),  # turn then straight
                np.where(tk < switch_at, 0.0, turn),  # straight then turn
            ],
        )
        cz = np.where(kind == 0, rng.uniform(-vz, vz, n), np.sign(climb) * vz)
        half = 0.5 * om * dt
        chord = v * dt * np.sinc(half / np.pi)
        pos[:, 0] += chord * np.cos(heading + half)
        pos[:, 1] += chord * np.sin(heading + half)
        pos[:, 2] -= cz * dt
        heading += om * dt
        out.append(pos.copy())
    return np.array(out)  # (steps+1, n, 3)


def _sphere(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.mark.parametrize("v,w,t,r,vz", PARAMS)
@pytest.mark.parametrize("mode", ["swept", "terminal"])
def test_ellipsoid_encloses_monte_carlo_reachable_positions(v, w, t, r, vz, mode):
    rng = np.random.default_rng(0)
    traj = _dubins_samples(v, w, vz, t, 3000, rng)
    pts = traj.reshape(-1, 3) if mode == "swept" else traj[-1]
    pts = pts + r * _sphere(rng, len(pts))  # the safety radius around each position
    offset, axes = R.ellipsoid(v, w, vz, t, r, mode=mode)
    center = np.array([float(offset), 0.0, 0.0])
    d = R.distance_to_ellipsoid(pts, center, axes, 0.0)
    assert d.max() <= 1e-6 * (v * t + r), d.max()


@pytest.mark.parametrize("v,w,t,r,vz", PARAMS)
def test_2d_ellipse_encloses_and_is_tight(v, w, t, r, vz):
    rng = np.random.default_rng(1)
    traj = _dubins_samples(v, w, 0.0, t, 4000, rng)
    pts = traj.reshape(-1, 3)[:, :2]
    ang = rng.uniform(0, 2 * np.pi, len(pts))
    pts = pts + r * np.stack([np.cos(ang), np.sin(ang)], 1)
    c, lat, lon = R.ellipse(v, w, t, r)
    q = ((pts[:, 0] - c) / lon) ** 2 + (pts[:, 1] / lat) ** 2
    assert q.max() <= 1 + 1e-9
    # Tightness: the ellipse is not much larger than the set (area of the set's convex hull
    # from its support function).
    th = np.linspace(-np.pi, np.pi, 2001)
    h = R.support(th, v, w, t, r)
    # Polygon of support-line intersections approximates the convex set's area from above.
    dh = np.gradient(h, th)
    x = h * np.sin(th) + dh * np.cos(th)  # boundary point of support direction (sin, cos)
    y = h * np.cos(th) - dh * np.sin(th)
    area_set = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    ratio = np.pi * lat * lon / area_set
    assert 1.0 <= ratio < 1.6, ratio


def test_paper_example_values():
    c, lat, lon = R.ellipse(4.0, 0.013, 10.0, 3.0)
    # Extent along the heading: the set reaches v t + r = 43 m ahead and r = 3 m behind.
    assert c + lon >= 43.0 - 1e-9 and c - lon <= -3.0 + 1e-9
    # Laterally: rho (1 - cos phi) + r, about 2.6 + 3 m.
    assert lat >= 3.0 + 307.69 * (1 - np.cos(0.13)) - 1e-6


def test_printed_eqs_13_14_miss_reachable_points():
    # The notes' erratum: S3/S4 centred on S1(-phi)/S2(phi) (which already include r) miss
    # true reachable points; the corrected boundary does not.
    v, w, t, r = 4.0, 0.013, 10.0, 3.0
    rho, phi = v / w, w * t
    th = phi
    f_phi = np.array([rho * (1 - np.cos(th)), rho * np.sin(th)])  # F(phi), r = 0
    s2_phi = f_phi + r * np.array([np.sin(th), np.cos(th)])  # S2(phi) with r
    # Reachable: a full-rate turn, then the safety radius outwards and backwards.
    point = f_phi + r * np.array([0.5, -np.sqrt(3) / 2])
    assert np.linalg.norm(point - f_phi) <= r + 1e-9
    # The printed S4 disc (centre S2(phi)) misses it by more than 1 m, and it lies below the
    # printed region's lowest point (the bottom of that disc, where the printed S5 runs).
    assert np.linalg.norm(point - s2_phi) > r + 1.0
    assert point[1] < s2_phi[1] - r - 1.0
    # The corrected S5 chord (y = rho sin(phi) - r) does include it.
    assert point[1] >= rho * np.sin(phi) - r - 1e-9


def _brute_distance(p, axes, n=400):
    u = np.linspace(0, np.pi, n)
    v = np.linspace(0, 2 * np.pi, 2 * n)
    uu, vv = np.meshgrid(u, v)
    surf = np.stack(
        [
            axes[0] * np.sin(uu) * np.cos(vv),
            axes[1] * np.sin(uu) * np.sin(vv),
            axes[2] * np.cos(uu),
        ],
        -1,
    ).reshape(-1, 3)
    d = np.linalg.norm(surf - p, axis=1).min()
    inside = np.sum((p / axes) ** 2) < 1
    return -d if inside else d


@settings(max_examples=60, deadline=None)
@given(
    p=st.tuples(*[st.floats(-40, 40)] * 3),
    axes=st.tuples(st.floats(1, 30), st.floats(1, 30), st.floats(1, 30)),
    heading=st.floats(-np.pi, np.pi),
    center=st.tuples(*[st.floats(-100, 100)] * 3),
)
def test_distance_matches_brute_force(p, axes, heading, center):
    axes = np.array(axes)
    center = np.array(center)
    body = np.array(p)
    c, s = np.cos(heading), np.sin(heading)
    world = center + np.array([c * body[0] - s * body[1], s * body[0] + c * body[1], body[2]])
    d, normal = R.distance_to_ellipsoid(world, center, axes, heading, return_normal=True)
    ref = _brute_distance(body, axes)
    tol = 0.02 * max(axes) + 1e-6  # the brute-force grid resolution
    assert abs(float(d) - ref) <= tol
    assert np.isfinite(normal).all() and abs(np.linalg.norm(normal) - 1) < 1e-9
    # The normal points from the nearest surface point towards the point (outside).
    if d > 0.5:
        moved = R.distance_to_ellipsoid(world + 0.1 * normal, center, axes, heading)
        assert moved > d
    if abs(float(d)) > 1e-9:  # on the surface either answer is right
        assert bool(R.contains(world, center, axes, heading)) == (float(d) < 0)


def test_subnormal_turn_angle_is_a_straight_line():
    # Found by hypothesis in CI: w t subnormal made 1 / (w t) overflow and 0 * inf NaN.
    h = R.support(np.linspace(0, np.pi, 7), 0.0, 1.0, 5e-324, 0.0)
    assert np.isfinite(h).all()
    h = R.support(np.array([0.0, np.pi / 2, np.pi]), 4.0, 1e-250, 10.0, 1.0)
    np.testing.assert_allclose(h, [41.0, 1.0, 1.0])


def test_extreme_inputs_finite():
    off, axes = R.ellipsoid(
        np.array([1e-3, 60.0, 4.0]), np.array([1e-12, 1.0, 0.0]), 5.0, np.array([1e4, 1.0, 10]), 0.0
    )
    assert np.all(np.isfinite(off)) and np.all(np.isfinite(axes)) and np.all(axes >= 0)
    d = R.distance_to_ellipsoid(np.zeros(3), np.zeros(3), np.array([5.0, 1e-3, 2.0]), 0.3)
    assert np.isfinite(d) and d < 0


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"speed": -1.0}, "speed"),
        ({"max_turn_rate": -0.1}, "turn"),
        ({"horizon": -5.0}, "horizon"),
        ({"radius": -1.0}, "radius"),
        ({"mode": "soon"}, "soon"),
    ],
)
def test_validation_names_bad_value(kwargs, match):
    args = {"speed": 4.0, "max_turn_rate": 0.1, "horizon": 10.0, "radius": 3.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        R.ellipse(**args)
