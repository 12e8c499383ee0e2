"""Tests of uasep_env.reachable: reachable sets (eqs. 8-18 with the notes' errata), the enclosing
ellipse/ellipsoid (Monte-Carlo enclosure, tightness) and the point-to-ellipsoid distance."""

import numpy as np
import pytest
from conftest import HealthCheck, given, settings, st

from uasep_env import reachable as R
from uasep_env.reachable.optimal import optimal_shape

PAPER = (4.0, 0.013, 10.0, 3.0)  # v (m/s), w_max (rad/s), t (s), r (m): the paper's example
THIN = (60.0, 0.001, 60.0, 0.0, 0.0)  # thin triangle, r = 0: the least ellipse-like set

SPECIAL = [
    # (v, w_max, t, r, vz_max)
    (*PAPER, 0.5),
    (10.0, 0.2, 10.0, 3.0, 1.0),  # phi = 2
    (5.0, 0.5, 10.0, 2.0, 2.0),  # phi = 5 > pi
    (8.0, 1.0, 20.0, 0.0, 0.0),  # phi = 20 > 2 pi, no radius, no climb
    (6.0, 0.3, 10.0, 1.0, 0.5),  # phi = 3 (just below pi)
    (6.0, 0.35, 9.0, 1.0, 0.5),  # phi = 3.15 (just above pi)
    (12.0, 0.7, 9.0, 4.0, 1.0),  # phi = 6.3 (just above 2 pi)
    (30.0, 0.05, 30.0, 10.0, 3.0),
    (1.0, 0.0, 15.0, 1.0, 0.3),  # straight flight only
    THIN,
    (0.5, 1.0, 1.0, 20.0, 0.0),  # radius dominates
]


def _random_params(rng, n):
    v = rng.uniform(0.5, 60.0, n)
    w = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 1.0, n) ** 2)
    t = rng.uniform(1.0, 60.0, n)
    r = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.0, 20.0, n))
    vz = rng.uniform(0.0, 5.0, n)
    return v, w, t, r, vz


RNG_PARAMS = list(
    zip(*(a.tolist() for a in _random_params(np.random.default_rng(7), 12)), strict=False)
)
ALL_PARAMS = SPECIAL + RNG_PARAMS


# ----------------------------------------------------------------------------- Dubins sampler
def dubins(v, w, vz, t, n_traj, rng, n_steps=160):
    """Exact piecewise-constant 3D Dubins paths, paper frame (x right, y ahead, z down).

    Families: random switching, bang-bang, full turn then straight, straight then full turn,
    full turns, random constant turns. Returns positions ``(n_steps + 1, n_traj, 3)``.
    """
    dt = t / n_steps
    fam = rng.integers(0, 6, n_traj)
    sgn = np.where(rng.random(n_traj) < 0.5, -1.0, 1.0)
    k_sw = rng.integers(0, n_steps + 1, n_traj)
    const = rng.uniform(-w, w, n_traj)
    climb_const = rng.choice([-vz, vz, 0.0], n_traj) if vz > 0 else np.zeros(n_traj)
    pos = np.zeros((n_traj, 3))
    psi = np.zeros(n_traj)
    out = [pos.copy()]
    om = rng.uniform(-w, w, n_traj)
    cz = rng.uniform(-vz, vz, n_traj)
    for k in range(n_steps):
        redraw = rng.random(n_traj) < 0.1
        om = np.where(redraw, rng.uniform(-w, w, n_traj), om)
        cz = np.where(redraw, rng.uniform(-vz, vz, n_traj), cz)
        before = k < k_sw
        omega = np.select(
            [fam == 0, fam == 1, fam == 2, fam == 3, fam == 4],
            [
                om,
                np.where(before, sgn * w, -sgn * w),
                np.where(before, sgn * w, 0.0),
                np.where(before, 0.0, sgn * w),
                sgn * w,
            ],
            const,
        )
        climb = np.where(fam == 0, cz, climb_const)
        half = 0.5 * omega * dt
        chord = v * dt * np.sinc(half / np.pi)
        pos[:, 0] += chord * np.sin(psi + half)
        pos[:, 1] += chord * np.cos(psi + half)
        pos[:, 2] -= climb * dt
        psi += omega * dt
        out.append(pos.copy())
    return np.array(out)


def _circle(m):
    b = np.linspace(0.0, 2.0 * np.pi, m, endpoint=False)
    return np.stack([np.sin(b), np.cos(b)], axis=-1)


def _sphere_dirs():
    d = [np.eye(3)[i] * s for i in range(3) for s in (-1.0, 1.0)]
    d += [np.array([a, b, c]) / np.sqrt(3.0) for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]
    return np.array(d)


def _inside_ellipse(p, c, lat, lon, tol=1e-9):
    """(x lateral, y along heading) points inside the ellipse, scale-free and A = 0 safe."""
    x, y = p[..., 0], p[..., 1] - c
    lhs = (x * lon) ** 2 + (y * lat) ** 2
    return lhs <= (lat * lon) ** 2 * (1.0 + tol) + 1e-30


# ----------------------------------------------------------------------------- 2D enclosure
@pytest.mark.parametrize("params", ALL_PARAMS)
@pytest.mark.parametrize("mode", ["swept", "terminal"])
def test_ellipse_encloses_monte_carlo(params, mode):
    v, w, t, r, _ = params
    rng = np.random.default_rng(1)
    traj = dubins(v, w, 0.0, t, 300, rng)[..., :2]
    pts = traj.reshape(-1, 2) if mode == "swept" else traj[-1]
    pts = (pts[:, None, :] + r * _circle(12)[None]).reshape(-1, 2)
    c, lat, lon = R.ellipse(v, w, t, r, mode=mode)
    assert np.all(_inside_ellipse(pts, c, lat, lon))
    # The set's own extreme points (front curve + radius, corners) are inside too.
    poly = R.boundary(v, w, t, r, n=2001, mode=mode)
    assert np.all(_inside_ellipse(poly, c, lat, lon))


@pytest.mark.parametrize("params", ALL_PARAMS)
@pytest.mark.parametrize("mode", ["swept", "terminal"])
def test_ellipsoid_encloses_monte_carlo_world_frame(params, mode):
    v, w, t, r, vz = params
    rng = np.random.default_rng(2)
    traj = dubins(v, w, vz, t, 200, rng, n_steps=100)
    pts = traj.reshape(-1, 3) if mode == "swept" else traj[-1]
    pts = (pts[:, None, :] + r * _sphere_dirs()[None]).reshape(-1, 3)
    offset, axes = R.ellipsoid(v, w, vz, t, r, mode=mode)
    assert axes.shape == (3,)
    # Place the obstacle in the world (NED) at a random pose: body = (ahead, right, down).
    psi = rng.uniform(-np.pi, np.pi)
    p0 = rng.normal(size=3) * 100.0
    # A denser batch, the radius in a random direction of the sphere at each position (not
    # just the 14 above): it reaches closer to the surface for several of the cases.
    dense = dubins(v, w, vz, t, 3000, rng, n_steps=60)
    dense = dense.reshape(-1, 3) if mode == "swept" else dense[-1]
    u = rng.normal(size=dense.shape)
    pts = np.concatenate([pts, dense + r * u / np.linalg.norm(u, axis=1, keepdims=True)])
    fwd = np.array([np.cos(psi), np.sin(psi), 0.0])
    right = np.array([-np.sin(psi), np.cos(psi), 0.0])
    world = p0 + pts[:, 1:2] * fwd + pts[:, 0:1] * right + pts[:, 2:3] * np.array([0, 0, 1.0])
    center = p0 + offset * fwd
    d = R.distance_to_ellipsoid(world, center, axes, psi)
    assert np.all(d <= 1e-9 * (v * t + vz * t + r + 1.0))
    inside = R.contains(world, center, axes, psi)
    # contains agrees with the sign wherever the point is not within rounding of the surface
    clear = np.abs(d) > 1e-9 * (v * t + r + 1.0)
    assert np.all(inside[clear])


def test_ellipsoid_axes_relation_and_flat_case():
    c2, lat, lon = R.ellipse(10.0, 0.1, 20.0, 2.0)
    c3, axes = R.ellipsoid(10.0, 0.1, 1.5, 20.0, 2.0)
    assert c3 == pytest.approx(c2)
    assert axes[0] == pytest.approx(np.sqrt(1.5) * lon)
    assert axes[1] == pytest.approx(np.sqrt(1.5) * lat)
    assert axes[2] == pytest.approx(np.sqrt(3.0) * (1.5 * 20.0 + 2.0))
    # No climb and no radius: the flat 2D ellipse itself.
    _, axes0 = R.ellipsoid(10.0, 0.1, 0.0, 20.0, 0.0)
    c2, lat, lon = R.ellipse(10.0, 0.1, 20.0, 0.0)
    np.testing.assert_allclose(axes0, [lon, lat, 0.0])
    # Vectorised shapes.
    off, ax = R.ellipsoid(np.full((4, 5), 5.0), 0.1, 0.5, 10.0, np.arange(5.0))
    assert off.shape == (4, 5) and ax.shape == (4, 5, 3)


# ----------------------------------------------------------------------------- S1..S5 and errata
def _point_in_convex_polygon(poly, pts, tol):
    """Signed outside distance (>0 outside) of points w.r.t. a closed convex polygon."""
    a, b = poly[:-1], poly[1:]
    area2 = np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    e = b - a
    ln = np.linalg.norm(e, axis=1)
    keep = ln > 0
    a, e, ln = a[keep], e[keep], ln[keep]
    rel = pts[:, None, :] - a[None]
    cross = (e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0]) / ln
    out = -cross if area2 > 0 else cross  # positive = right of a CCW edge = outside
    return np.max(out, axis=1) <= tol


@pytest.mark.parametrize("params", ALL_PARAMS)
def test_terminal_boundary_contains_monte_carlo(params):
    v, w, t, r, _ = params
    rng = np.random.default_rng(3)
    end = dubins(v, w, 0.0, t, 600, rng)[-1, :, :2]
    pts = (end[:, None, :] + r * _circle(16)[None]).reshape(-1, 2)
    poly = R.boundary(v, w, t, r, n=4001)
    assert poly.shape == (4001, 2)
    np.testing.assert_array_equal(poly[0], poly[-1])
    tol = 2e-6 * (v * t + r) + 1e-9  # the polygon is inscribed: chord error <= R dtheta^2 / 8
    assert np.all(_point_in_convex_polygon(poly, pts, tol))


def test_boundary_support_matches_support_function():
    for v, w, t, r, _ in ALL_PARAMS:
        for mode in ("swept", "terminal"):
            poly = R.boundary(v, w, t, r, n=4001, mode=mode)
            th = np.linspace(-np.pi, np.pi, 91)
            u = np.stack([np.sin(th), np.cos(th)], axis=-1)
            h_poly = np.max(poly @ u.T, axis=0)
            h = R.support(th, v, w, t, r, mode=mode)
            np.testing.assert_allclose(h_poly, h, atol=2e-6 * (v * t + r) + 1e-12)


def _printed_region_min_y(v, w, t, r, n=4001):
    """Lowest point of the region as printed (eqs. 13-14 centred on S1(-phi)/S2(phi))."""
    phi = w * t
    rho = v / w
    th2 = np.linspace(0.0, phi, n)
    s2 = np.stack(
        [
            rho * (1 - np.cos(th2)) + (v * t - rho * th2 + r) * np.sin(th2),
            rho * np.sin(th2) + (v * t - rho * th2 + r) * np.cos(th2),
        ],
        axis=-1,
    )
    th4 = np.linspace(phi, np.pi, n)
    s4 = s2[-1] + r * np.stack([np.sin(th4), np.cos(th4)], axis=-1)
    return min(s2[:, 1].min(), s4[:, 1].min())


def test_printed_eqs_13_14_miss_reachable_points():
    v, w, t, r = PAPER
    # F(phi) is reached by a full-rate turn; with the safety radius the point 3 m behind it
    # belongs to the set. The printed region stops about r above it; the erratum's does not.
    fx, fy = R.front_curve(w * t, v, w, t)
    point_y = fy - r
    assert _printed_region_min_y(v, w, t, r) - point_y > 1.0
    poly = R.boundary(v, w, t, r, n=4001)
    assert poly[:, 1].min() == pytest.approx(point_y, abs=1e-9)
    assert _point_in_convex_polygon(poly, np.array([[fx, point_y]]), 1e-6)[0]
    # Monte Carlo points (full turn, then the radius straight back) fall outside the printed one.
    rng = np.random.default_rng(4)
    end = dubins(v, w, 0.0, t, 400, rng)[-1, :, :2]
    low = (end[:, None, :] + r * _circle(32)[None]).reshape(-1, 2)[:, 1].min()
    assert _printed_region_min_y(v, w, t, r) - low > 1.0
    # Not only straight back: the point r from F(phi) towards (0.5, -sqrt(3)/2) is reachable
    # (a full-rate turn, then the radius outwards and backwards). The printed S4 disc (centre
    # S2(phi), which already includes r) misses it by more than 1 m, and it lies below the
    # bottom of that disc (where the printed S5 runs); the corrected S5 chord
    # (y = rho sin(phi) - r) and the corrected boundary include it.
    rho, phi = v / w, w * t
    f_phi = np.array([rho * (1 - np.cos(phi)), rho * np.sin(phi)])  # F(phi), r = 0
    s2_phi = f_phi + r * np.array([np.sin(phi), np.cos(phi)])  # printed S2(phi), with r
    oblique = f_phi + r * np.array([0.5, -np.sqrt(3) / 2])
    assert np.linalg.norm(oblique - f_phi) <= r + 1e-9
    assert np.linalg.norm(oblique - s2_phi) > r + 1.0
    assert oblique[1] < s2_phi[1] - r - 1.0
    assert oblique[1] >= rho * np.sin(phi) - r - 1e-9
    assert _point_in_convex_polygon(poly, oblique[None], 1e-6)[0]


def test_front_curve_formula_and_limits():
    v, w, t = 7.0, 0.2, 9.0
    rho, phi = v / w, w * t
    th = np.linspace(-phi, phi, 41)
    x, y = R.front_curve(th, v, w, t)
    a = np.abs(th)
    np.testing.assert_allclose(
        x, np.sign(th) * rho * (1 - np.cos(th)) + (v * t - rho * a) * np.sin(th), atol=1e-9
    )
    np.testing.assert_allclose(y, rho * np.sin(a) + (v * t - rho * a) * np.cos(th), atol=1e-9)
    # Clipped to |theta| <= min(phi, pi); straight line for w = 0; tiny w is continuous.
    x_hi, y_hi = R.front_curve(3.0, v, w, t)
    assert (x_hi, y_hi) == (pytest.approx(x[-1]), pytest.approx(y[-1]))
    assert R.front_curve(0.3, v, 0.0, t) == (pytest.approx(0.0), pytest.approx(v * t))
    xs, ys = R.front_curve(1e-12, v, 1e-12, t)
    assert abs(xs) < 1e-9 and ys == pytest.approx(v * t)
    xp, yp = R.front_curve(np.pi, 5.0, 1.0, 10.0)  # phi = 10 > 2 pi
    assert xp == pytest.approx(2 * 5.0) and yp == pytest.approx(-(50.0 - 5.0 * np.pi))


# ----------------------------------------------------------------------------- support function
@pytest.mark.parametrize("params", ALL_PARAMS)
def test_support_matches_brute_force(params):
    v, w, t, r, _ = params
    rng = np.random.default_rng(5)
    traj = dubins(v, w, 0.0, t, 400, rng)[..., :2]
    th = np.linspace(-np.pi, np.pi, 73)
    u = np.stack([np.sin(th), np.cos(th)], axis=-1)
    scale = v * t + r
    for mode, pts in (("swept", traj.reshape(-1, 2)), ("terminal", traj[-1])):
        brute = np.max(pts @ u.T, axis=0) + r
        h = R.support(th, v, w, t, r, mode=mode)
        assert np.all(brute <= h + 1e-9 * scale)
    # The maximisers: turn at full rate towards theta, then straight (|theta| <= phi); else
    # the full turn (terminal) or also the origin (swept). Built exactly, they attain h.
    for thk in th:
        a = abs(thk)
        t_turn = min(a / w, t) if w > 0 else 0.0  # w = 0: straight is the only path
        s = np.sign(thk)
        if w > 0:
            turn = np.array([s * v / w * (1 - np.cos(w * t_turn)), v / w * np.sin(w * t_turn)])
        else:
            turn = np.zeros(2)
        psi = s * w * t_turn
        p = turn + v * (t - t_turn) * np.array([np.sin(psi), np.cos(psi)])
        uk = np.array([np.sin(thk), np.cos(thk)])
        val_t = p @ uk + r
        assert R.support(thk, v, w, t, r, mode="terminal") == pytest.approx(val_t, abs=1e-9 * scale)
        assert R.support(thk, v, w, t, r, mode="swept") == pytest.approx(
            max(val_t, r), abs=1e-9 * scale
        )


def test_support_closed_form_inside_phi():
    v, w, t, r = 9.0, 0.1, 20.0, 2.5
    rho = v / w
    th = np.linspace(-w * t, w * t, 11)
    expect = r + v * t - rho * (np.abs(th) - np.sin(np.abs(th)))
    np.testing.assert_allclose(R.support(th, v, w, t, r), expect, rtol=1e-12)
    np.testing.assert_allclose(R.support(th + 2 * np.pi, v, w, t, r), expect, rtol=1e-12)


# ----------------------------------------------------------------------------- tightness
def _polygon_area(p):
    return 0.5 * abs(np.dot(p[:-1, 0], p[1:, 1]) - np.dot(p[1:, 0], p[:-1, 1]))


def test_area_ratio_paper_example():
    for mode, lo, hi in (("swept", 1.3, 1.6), ("terminal", 1.0, 1.25)):
        _c, lat, lon = R.ellipse(*PAPER, mode=mode)
        true = _polygon_area(R.boundary(*PAPER, n=20001, mode=mode))
        ratio = np.pi * lat * lon / true
        assert lo <= ratio <= hi


def _support_area(v, w, t, r, mode="swept"):
    """Area of the convex set from its support function alone (independent of boundary()):
    the polygon of boundary points h u + h' u' over 2001 directions u = (sin, cos)."""
    th = np.linspace(-np.pi, np.pi, 2001)
    h = R.support(th, v, w, t, r, mode=mode)
    dh = np.gradient(h, th)
    x = h * np.sin(th) + dh * np.cos(th)
    y = h * np.cos(th) - dh * np.sin(th)
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


@pytest.mark.parametrize("params", SPECIAL)
@pytest.mark.parametrize("mode", ["swept", "terminal"])
def test_area_ratio_special_cases(params, mode):
    """The ellipse is at most 1.6 times the set's area for every special case (measured up to
    1.57) but the thin triangle, which gets the general bound for convex sets."""
    v, w, t, r, _ = params
    _c, lat, lon = R.ellipse(v, w, t, r, mode=mode)
    ratio = np.pi * lat * lon / _support_area(v, w, t, r, mode)
    assert 1.0 <= ratio < (2.45 if params == THIN else 1.6), ratio


def test_paper_example_extents():
    v, w, t, r = PAPER
    c, lat, lon = R.ellipse(*PAPER)
    # Along the heading the set reaches v t + r = 43 m ahead and r = 3 m behind.
    assert c + lon >= v * t + r - 1e-9 and c - lon <= -r + 1e-9
    # Laterally: rho (1 - cos phi) + r, about 2.6 + 3 m.
    assert lat >= r + v / w * (1 - np.cos(w * t)) - 1e-6


@pytest.mark.parametrize("mode", ["swept", "terminal"])
def test_area_ratio_against_set_and_optimum(mode):
    rng = np.random.default_rng(6)
    v, w, t, r, _ = _random_params(rng, 120)
    r = np.maximum(r, 0.05)  # keep the true area positive
    _c, lat, lon = R.ellipse(v, w, t, r, mode=mode)
    area = np.pi * lat * lon
    true = np.array(
        [_polygon_area(R.boundary(*p, n=4001, mode=mode)) for p in zip(v, w, t, r, strict=True)]
    )
    ratio_set = area / true
    # Any convex set's minimum enclosing ellipse is at most 4 pi / (3 sqrt 3) = 2.418 times it.
    assert np.all(ratio_set >= 1.0)
    assert np.all(ratio_set <= 2.45)
    L = v * t + r
    _, a_opt, b_opt = optimal_shape(w * t, r / L, mode == "swept", m=240, iters=50)
    ratio_opt = lat * lon / (a_opt * b_opt * L * L)
    assert np.all(ratio_opt >= 1.0 - 1e-3)  # the reference is itself a sampled optimum
    assert np.all(ratio_opt <= (1.03 if mode == "swept" else 1.06))
    assert np.median(ratio_opt) <= 1.005


def test_ellipse_certificate_margin_on_dense_directions():
    """Independent check of the proof: ellipse support >= set support on 20001 directions."""
    rng = np.random.default_rng(8)
    v, w, t, r, _ = _random_params(rng, 200)
    th = np.linspace(0.0, np.pi, 20001)
    for mode in ("swept", "terminal"):
        c, lat, lon = R.ellipse(v, w, t, r, mode=mode)
        h_e = c[:, None] * np.cos(th) + np.sqrt(
            (lat**2)[:, None] * np.sin(th) ** 2 + (lon**2)[:, None] * np.cos(th) ** 2
        )
        h = R.support(th[None], v[:, None], w[:, None], t[:, None], r[:, None], mode=mode)
        assert np.all(h_e - h >= -1e-9 * (v * t + r)[:, None])


def test_special_cases_exact():
    assert R.ellipse(0.0, 0.3, 10.0, 4.0) == (0.0, 4.0, 4.0)  # a disc
    c, lat, lon = R.ellipse(5.0, 0.0, 10.0, 0.0)  # a segment
    assert (c, lat, lon) == (25.0, 0.0, 25.0)
    assert R.ellipse(0.0, 0.0, 0.0, 0.0) == (0.0, 0.0, 0.0)
    c, lat, lon = R.ellipse(5.0, 0.0, 10.0, 1.0)  # a stadium: the optimum is 45 % narrower
    assert lat < 1.5 and lon < 0.75 * 52


def test_ellipse_vectorised_and_scalar_outputs():
    c, lat, _lon = R.ellipse(4.0, 0.013, 10.0, 3.0)
    assert np.ndim(c) == 0 and np.asarray(c).dtype == np.float64
    cs, lats, _lons = R.ellipse(np.full((3, 4), 4.0), 0.013, np.array([10.0, 10, 10, 10]), 3.0)
    assert cs.shape == (3, 4)
    np.testing.assert_allclose(cs, c)
    np.testing.assert_allclose(lats, lat)


# ----------------------------------------------------------------------------- hypothesis
pos = st.floats(0.5, 60.0)
turn = st.one_of(st.just(0.0), st.floats(1e-6, 1.0))
hor = st.floats(1.0, 60.0)
rad = st.floats(0.0, 20.0)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pos, turn, hor, rad, st.floats(1.0, 3.0), st.floats(0.0, 10.0), st.integers(0, 2**31))
def test_monotone_in_horizon_and_radius(v, w, t, r, t_fac, dr, seed):
    """The swept set grows with t and r, so the bigger ellipse holds the smaller set's points."""
    rng = np.random.default_rng(seed)
    traj = dubins(v, w, 0.0, t, 60, rng, n_steps=60)[..., :2].reshape(-1, 2)
    pts = (traj[:, None, :] + r * _circle(8)[None]).reshape(-1, 2)
    c, lat, lon = R.ellipse(v, w, t * t_fac, r + dr)
    assert np.all(_inside_ellipse(pts, c, lat, lon))


@settings(max_examples=40, deadline=None)
@given(
    st.floats(0.0, 100.0),
    st.one_of(st.just(1e-12), st.floats(0.0, 5.0)),
    st.one_of(st.just(1e4), st.floats(0.0, 1e4)),
    st.floats(0.0, 50.0),
    st.sampled_from(["swept", "terminal"]),
)
def test_finite_for_extreme_inputs(v, w, t, r, mode):
    c, lat, lon = R.ellipse(v, w, t, r, mode=mode)
    assert np.isfinite([c, lat, lon]).all()
    assert lat >= 0 and lon >= 0
    assert lon <= v * t + r + 1e-6 * (v * t + r + 1)  # never worse than the fallback circle
    th = np.linspace(0.0, np.pi, 7)
    h = R.support(th, v, w, t, r, mode=mode)
    assert np.isfinite(h).all()
    h_e = c * np.cos(th) + np.sqrt(lat**2 * np.sin(th) ** 2 + lon**2 * np.cos(th) ** 2)
    assert np.all(h_e >= h - 1e-9 * (v * t + r + 1))
    off, axes = R.ellipsoid(v, w, 1.0, t, r, mode=mode)
    assert np.isfinite(axes).all() and np.isfinite(off)


def test_subnormal_turn_angle_is_a_straight_line():
    # Found by hypothesis in CI: w t subnormal made 1 / (w t) overflow and 0 * inf NaN.
    h = R.support(np.linspace(0, np.pi, 7), 0.0, 1.0, 5e-324, 0.0)
    assert np.isfinite(h).all()
    h = R.support(np.array([0.0, np.pi / 2, np.pi]), 4.0, 1e-250, 10.0, 1.0)
    np.testing.assert_allclose(h, [41.0, 1.0, 1.0])


def test_extreme_vectorised_ellipsoid_and_thin_distance_finite():
    off, axes = R.ellipsoid(
        np.array([1e-3, 60.0, 4.0]), np.array([1e-12, 1.0, 0.0]), 5.0, np.array([1e4, 1.0, 10]), 0.0
    )
    assert np.all(np.isfinite(off)) and np.all(np.isfinite(axes)) and np.all(axes >= 0)
    d = R.distance_to_ellipsoid(np.zeros(3), np.zeros(3), np.array([5.0, 1e-3, 2.0]), 0.3)
    assert np.isfinite(d) and d < 0


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "kwargs,bad",
    [
        (dict(speed=-1.5), "-1.5"),
        (dict(max_turn_rate=-0.25), "-0.25"),
        (dict(horizon=-3.0), "-3.0"),
        (dict(radius=-7.0), "-7.0"),
        (dict(speed=float("nan")), "nan"),
        (dict(horizon=np.array([1.0, -2.0])), "-2.0"),
    ],
)
def test_validation_names_bad_value(kwargs, bad):
    args = dict(speed=4.0, max_turn_rate=0.1, horizon=10.0, radius=3.0) | kwargs
    name = next(iter(kwargs))
    with pytest.raises(ValueError, match=rf"{name}.*{bad}"):
        R.ellipse(**args)
    with pytest.raises(ValueError, match=rf"{name}.*{bad}"):
        R.support(0.3, **args)
    with pytest.raises(ValueError, match=rf"{name}.*{bad}"):
        R.ellipsoid(args["speed"], args["max_turn_rate"], 1.0, args["horizon"], args["radius"])


def test_validation_mode_and_climb_and_axes():
    with pytest.raises(ValueError, match="bogus"):
        R.ellipse(4.0, 0.1, 10.0, 3.0, mode="bogus")
    with pytest.raises(ValueError, match="bogus"):
        R.support(0.0, 4.0, 0.1, 10.0, 3.0, mode="bogus")
    with pytest.raises(ValueError, match=r"max_climb_rate.*-1\.0"):
        R.ellipsoid(4.0, 0.1, -1.0, 10.0, 3.0)
    with pytest.raises(ValueError, match=r"semi_axes.*-2\.0"):
        R.distance_to_ellipsoid(np.zeros(3), np.zeros(3), [1.0, -2.0, 1.0], 0.0)
    with pytest.raises(ValueError, match="n must be"):
        R.boundary(4.0, 0.1, 10.0, 3.0, n=3)


# ----------------------------------------------------------------------------- distances
def ref_distance(q, a):
    """Reference nearest-point distance in the body frame: bisection (log scale) on the shifted
    Lagrange multiplier sigma = t + a_min^2, with the degenerate (sigma = 0) case explicit."""
    q = np.abs(np.asarray(q, float))
    a = np.asarray(a, float)
    m = int(np.argmin(a))
    off = a * a - a[m] ** 2

    def big_f(sig):
        s = sig + off
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            wv = np.where(q == 0, 0.0, np.where(s > 0, a * q / s, np.inf))
            return np.sum(wv * wv)

    if big_f(0.0) <= 1.0:
        sig = 0.0
    else:
        lo, hi = -745.0, np.log(np.linalg.norm(a * q) + 1e-300) + 1.0
        while big_f(np.exp(hi)) > 1.0:
            hi += 5.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if big_f(np.exp(mid)) > 1.0:
                lo = mid
            else:
                hi = mid
        sig = np.exp(hi)
    s = sig + off
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(q == 0, 0.0, a * a * q / s)
    if sig == 0.0:
        rest = sum((x[i] / a[i]) ** 2 for i in range(3) if i != m and a[i] > 0)
        x[m] = a[m] * np.sqrt(max(0.0, 1.0 - rest))
    d = np.linalg.norm(q - x)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(a > 0, q / np.where(a > 0, a, 1), np.where(q > 0, np.inf, 0))
    return -d if np.sum(ratio**2) < 1 else d


def _random_cases(rng, n):
    cases = []
    for _ in range(n):
        a = rng.uniform(0.1, 10.0, 3)
        k = rng.integers(0, 5)
        if k == 1:
            a[rng.integers(3)] = rng.choice([0.0, 1e-9, 1e-4])
        elif k == 2:
            a[:] = a[0]
        elif k == 3:
            a[:2] = a[0]
        q = rng.normal(size=3) * rng.choice([0.2, 0.7, 1.0, 1.5, 5.0, 1e6]) * a.max()
        kind = rng.integers(0, 6)
        if kind == 1:
            q[rng.integers(3)] = 0.0
        elif kind == 2:
            q[rng.choice(3, 2, replace=False)] = 0.0
        elif kind == 3:
            q *= 1e-12
        elif kind == 4:
            q[np.argmin(a)] *= rng.choice([1e-12, 1e-8, 1e-4])
        elif kind == 5:  # on or very near the surface
            u = rng.normal(size=3)
            u /= np.linalg.norm(u)
            q = a * u / np.sqrt(np.sum(u * u)) * (1 + rng.choice([0.0, 1e-9, -1e-9]))
        cases.append((q, a))
    return cases


def test_distance_matches_reference_body_frame():
    rng = np.random.default_rng(9)
    cases = _random_cases(rng, 1500)
    q = np.array([c[0] for c in cases])
    a = np.array([c[1] for c in cases])
    d = R.distance_to_ellipsoid(q, np.zeros(3), a, 0.0)
    ref = np.array([ref_distance(qq, aa) for qq, aa in cases])
    scale = np.maximum(a.max(axis=1), np.abs(q).max(axis=1))
    np.testing.assert_array_less(np.abs(d - ref), 1e-9 * scale + 1e-14)
    assert np.all(
        np.sign(d[np.abs(ref) > 1e-9 * scale]) == np.sign(ref[np.abs(ref) > 1e-9 * scale])
    )


def test_distance_random_headings_and_brute_force_surface():
    rng = np.random.default_rng(10)
    n = 60
    a = rng.uniform(0.5, 8.0, (n, 3))
    a[:10, 2] = 1e-6  # nearly flat
    psi = rng.uniform(-4.0, 4.0, n)
    ctr = rng.normal(size=(n, 3)) * 10
    p = ctr + rng.normal(size=(n, 3)) * rng.choice([0.3, 1.0, 3.0], (n, 1)) * a.max(
        1, keepdims=True
    )
    d, normal = R.distance_to_ellipsoid(p, ctr, a, psi, return_normal=True)
    near, d2, n2 = R.nearest_point_on_ellipsoid(p, ctr, a, psi)
    np.testing.assert_allclose(d2, d)
    np.testing.assert_allclose(n2, normal)
    # Dense surface samples in the body frame, mapped to the world.
    uu, vv = np.meshgrid(np.linspace(0, np.pi, 400), np.linspace(-np.pi, np.pi, 800), indexing="ij")
    unit = np.stack([np.sin(uu) * np.cos(vv), np.sin(uu) * np.sin(vv), np.cos(uu)], -1).reshape(
        -1, 3
    )
    for i in range(n):
        body = unit * a[i]
        c, s = np.cos(psi[i]), np.sin(psi[i])
        world = ctr[i] + np.stack(
            [body[:, 0] * c - body[:, 1] * s, body[:, 0] * s + body[:, 1] * c, body[:, 2]], -1
        )
        brute = np.min(np.linalg.norm(world - p[i], axis=1))
        assert abs(d[i]) <= brute + 1e-9  # nothing on the surface is closer
        assert brute - abs(d[i]) <= 0.02 * a[i].max()  # and the sampling gets close to it
        # The nearest point lies on the surface, at the reported distance.
        rel = near[i] - ctr[i]
        bq = np.array([rel[0] * c + rel[1] * s, -rel[0] * s + rel[1] * c, rel[2]])
        assert np.sum((bq / a[i]) ** 2) == pytest.approx(1.0, abs=1e-9 / max(a[i].min(), 1e-6))
        assert np.linalg.norm(p[i] - near[i]) == pytest.approx(abs(d[i]), abs=1e-9)
    # Sign agrees with contains; the normal points from the surface to an outside point and
    # out of the ellipsoid (from the point towards the surface) for an inside one.
    inside = R.contains(p, ctr, a, psi)
    assert np.all(inside == (d < 0))
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
    vec = p - near
    far = np.abs(d) > 1e-6
    unitvec = vec[far] / np.linalg.norm(vec[far], axis=1, keepdims=True)
    expect = np.where((d[far] > 0)[:, None], unitvec, -unitvec)
    np.testing.assert_allclose(normal[far], expect, atol=1e-6)


def test_distance_degenerate_cases():
    a = np.array([5.0, 3.0, 2.0])
    # Centre: distance = smallest semi-axis, deterministic normal along it (vertical, +z body).
    d, n = R.distance_to_ellipsoid(np.zeros(3), np.zeros(3), a, 0.7, return_normal=True)
    assert d == pytest.approx(-2.0)
    np.testing.assert_allclose(n, [0.0, 0.0, 1.0])
    # Ties: the first of the smallest axes; heading rotates the normal.
    d, n = R.distance_to_ellipsoid(
        np.zeros(3), np.zeros(3), [1.0, 1.0, 4.0], np.pi / 2, return_normal=True
    )
    assert d == pytest.approx(-1.0)
    np.testing.assert_allclose(n, [0.0, 1.0, 0.0], atol=1e-12)
    # On the long axis, inside: the nearest point leaves the axis (Lagrange multiplier at -a_min^2).
    d = R.distance_to_ellipsoid([1.0, 0.0, 0.0], np.zeros(3), a, 0.0)
    assert d == pytest.approx(ref_distance([1.0, 0.0, 0.0], a), abs=1e-12)
    # Outside along an axis; a sphere; huge distances; a flat ellipsoid; a point ellipsoid.
    assert R.distance_to_ellipsoid([0.0, 0.0, -7.0], np.zeros(3), a, 0.0) == pytest.approx(5.0)
    assert R.distance_to_ellipsoid([3.0, 4.0, 0.0], np.zeros(3), [2.0] * 3, 1.0) == pytest.approx(
        3.0
    )
    big = R.distance_to_ellipsoid([1e9, 0.0, 0.0], np.zeros(3), a, 0.0)
    assert big == pytest.approx(1e9 - 5.0, rel=1e-15)
    flat = [4.0, 4.0, 0.0]
    assert R.distance_to_ellipsoid([1.0, 1.0, 3.0], np.zeros(3), flat, 0.0) == pytest.approx(3.0)
    assert R.distance_to_ellipsoid([1.0, 1.0, 0.0], np.zeros(3), flat, 0.0) == pytest.approx(0.0)
    d, n = R.distance_to_ellipsoid([0.0, 3.0, 4.0], np.zeros(3), [0.0] * 3, 0.0, return_normal=True)
    assert d == pytest.approx(5.0)
    np.testing.assert_allclose(n, [0.0, 0.6, 0.8])
    d, n = R.distance_to_ellipsoid(np.zeros(3), np.zeros(3), [0.0] * 3, 0.0, return_normal=True)
    assert d == 0.0 and np.all(np.isfinite(n)) and np.linalg.norm(n) == pytest.approx(1.0)


def test_distance_broadcasting_and_no_nans():
    rng = np.random.default_rng(11)
    pts = rng.normal(size=(4, 5, 1, 3)) * 20
    ctr = rng.normal(size=(1, 7, 3))
    ax = rng.uniform(0.0, 10.0, (7, 3))
    hd = rng.uniform(-3, 3, 7)
    d, n = R.distance_to_ellipsoid(pts, ctr, ax, hd, return_normal=True)
    assert d.shape == (4, 5, 7) and n.shape == (4, 5, 7, 3)
    assert np.isfinite(d).all() and np.isfinite(n).all()
    assert R.contains(pts, ctr, ax, hd).shape == (4, 5, 7)
    d1 = R.distance_to_ellipsoid(pts[2, 3, 0], ctr[0, 4], ax[4], hd[4])
    assert d1 == pytest.approx(d[2, 3, 4])


# ----------------------------------------------------------------------------- the paper's fit
@pytest.mark.parametrize("mode", ["swept", "terminal"])
@pytest.mark.parametrize("params", SPECIAL[:8])
def test_paper_fit_axes_are_the_sets_extents(params, mode):
    """Eq. 17 as published: major axis = lateral extent (S3-S4), minor = S5 to the tip of S1,2;
    semi-axes are half of them, centred on the middle of the extents."""
    v, w, t, r, _ = params
    c, lat, lon = R.ellipse(v, w, t, r, mode=mode, fit="paper")
    poly = R.boundary(v, w, t, r, n=4001, mode=mode)
    assert lat == pytest.approx(np.abs(poly[:, 0]).max(), rel=1e-6, abs=1e-9)
    assert c + lon == pytest.approx(poly[:, 1].max(), rel=1e-6, abs=1e-9)
    assert c - lon == pytest.approx(poly[:, 1].min(), rel=1e-6, abs=1e-6)


def _outside_distance(poly, c, lat, lon):
    """Distance (m) by which each boundary point lies outside the flat ellipse (<= 0 inside)."""
    pts = np.stack([poly[:, 1] - c, poly[:, 0], np.zeros(len(poly))], axis=-1)
    return R.distance_to_ellipsoid(pts, np.zeros(3), np.array([lon, lat, 1.0]), 0.0)


@pytest.mark.parametrize(
    ("params", "max_out", "missed"),
    [(PAPER, (0.45, 0.55), (0.08, 0.12)), ((8.0, 0.1, 10.0, 3.0), (5.0, 6.0), (0.10, 0.15))],
)
def test_paper_fit_misses_the_shoulders(params, max_out, missed):
    """The paper's ellipse does not enclose the terminal set: boundary points between the axes
    lie outside it (the measured figures quoted in ``ellipse``'s docstring), the enclosing fit
    leaves none outside."""
    poly = R.boundary(*params, n=721, mode="terminal")
    d = _outside_distance(poly, *R.ellipse(*params, mode="terminal", fit="paper"))
    assert max_out[0] < d.max() < max_out[1]
    assert np.mean(d > 1e-3) > 0.5  # most of the boundary is outside
    enclosing = _outside_distance(poly, *R.ellipse(*params, mode="terminal"))
    assert enclosing.max() <= 1e-9
    # The set's area it misses, by Monte Carlo over the set's bounding box.
    c, lat, lon = R.ellipse(*params, mode="terminal", fit="paper")
    rng = np.random.default_rng(0)
    pts = rng.uniform(poly.min(axis=0), poly.max(axis=0), size=(40_000, 2))
    in_set = _point_in_convex_polygon(poly, pts, 0.0)
    in_ell = _inside_ellipse(pts, c, lat, lon)
    assert missed[0] < np.mean(in_set & ~in_ell) / np.mean(in_set) < missed[1]


def test_paper_fit_ellipsoid_has_a_circular_cross_section():
    """3D as the text says: a circle of diameter a across the heading, whatever vz_max."""
    for vz in (0.0, 0.5, 3.0):
        c, axes = R.ellipsoid(4.0, 0.013, vz, 10.0, 3.0, mode="terminal", fit="paper")
        c2, lat, lon = R.ellipse(4.0, 0.013, 10.0, 3.0, mode="terminal", fit="paper")
        assert c == c2
        np.testing.assert_array_equal(axes, [lon, lat, lat])
    with pytest.raises(ValueError, match="fit must be 'enclosing' or 'paper', got 'exact'"):
        R.ellipsoid(4.0, 0.013, 0.5, 10.0, 3.0, fit="exact")


def test_written_out_helpers_give_numpys_numbers():
    """The fit's shortcuts against what they replace, bit for bit: ``sinc`` against
    ``np.sinc``, the three extents in one call against three, the corner table against the
    four gathers."""
    from uasep_env.reachable import fit
    from uasep_env.reachable.sets import _h_unit
    from uasep_env.sim.obstacles import sinc

    rng = np.random.default_rng(5)
    x = np.concatenate([[0.0, 1e-300, 0.5, 1.0, 3.0], rng.uniform(0.0, 4.0, 500)])
    np.testing.assert_array_equal(sinc(x), np.sinc(x))
    vt, phi, r = rng.uniform(0, 200, 64), rng.uniform(0, 5, 64), rng.uniform(0, 30, 64)
    phi[:4] = 0.0
    for swept in (True, False):
        h0, hpi, hx = fit._extents(vt, phi, r, swept)
        for got, a in ((h0, 0.0), (hpi, np.pi), (hx, 0.5 * np.pi)):
            want = r + vt * _h_unit(np.zeros_like(vt) + a, phi, swept)
            np.testing.assert_array_equal(got, want)
        u = rng.uniform(0.0, 1.0, 200)
        logr = np.concatenate([[np.nan, -np.inf, np.inf, -5.0, 5.0], rng.uniform(-3, 3, 195)])
        tab = fit._TAB[swept]
        na, nl = tab.shape[:2]
        fa = np.clip((u - fit._TAB_U[0]) / (fit._TAB_U[1] - fit._TAB_U[0]), 0.0, na - 1.0)
        fl = np.clip((logr - fit._TAB_LOGR[0]) / (fit._TAB_LOGR[1] - fit._TAB_LOGR[0]), 0, nl - 1)
        fl = np.where(np.isnan(fl), 0.0, fl)
        i0, j0 = np.minimum(fa.astype(np.intp), na - 2), np.minimum(fl.astype(np.intp), nl - 2)
        ta, tl = (fa - i0)[:, None], (fl - j0)[:, None]
        want = (
            tab[i0, j0] * (1 - ta) * (1 - tl)
            + tab[i0 + 1, j0] * ta * (1 - tl)
            + tab[i0, j0 + 1] * (1 - ta) * tl
            + tab[i0 + 1, j0 + 1] * ta * tl
        )
        np.testing.assert_array_equal(fit._interp_table(swept, u, logr), want)


@pytest.mark.parametrize("name", ["speed", "max_turn_rate", "max_climb_rate", "horizon", "radius"])
@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf])
def test_ellipsoid_names_the_bad_parameter(name, bad):
    args = {"speed": [5.0, 6.0], "max_turn_rate": 0.1, "max_climb_rate": 1.0, "horizon": 20.0,
            "radius": [3.0, 4.0]}  # fmt: skip
    args[name] = [1.0, bad] if isinstance(args[name], list) else bad
    with pytest.raises(ValueError, match=f"^{name} must be finite and >= 0"):
        R.ellipsoid(**args)
