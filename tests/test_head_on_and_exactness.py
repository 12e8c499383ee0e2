"""Head-on sides, MVP's degenerate conflicts and the filter QP's range (issue 54, item 7).

The rules of the air turn both aircraft of a head-on conflict to the right. NED: x north,
y east, z down, so right of a horizontal line of sight ``l`` is ``down x l``.
"""

import numpy as np
import pytest
from scipy.optimize import minimize
from test_cbf import _random_qps

from uasep_env.policies import APFGains, CBFParams
from uasep_env.policies.apf import _obstacle_repulsion
from uasep_env.policies.cbf import CBFFilter
from uasep_env.policies.mvp import mvp_velocity_change
from uasep_env.policies.orca import orca_planes, solve_orca_lp
from uasep_env.policies.qp import solve_filter_qp

DOWN = np.array([0.0, 0.0, 1.0])


def _headings(n=24):
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=-1)  # unit lines of sight


def test_cbf_sidestep_turns_right():
    """The reproducer (north at an obstacle ahead: east) and every horizontal heading."""
    side = CBFFilter.sidestep(np.array([[[-1.0, 0, 0]]]), np.array([[1.0]]),
                              np.array([[True]]), np.zeros((1, 3)))  # fmt: skip
    np.testing.assert_allclose(side, [[0.0, 1.0, 0.0]])
    los = _headings()
    n = -los[:, None, :]  # the barrier normal points from the obstacle to the UAV
    side = CBFFilter.sidestep(n, np.ones((len(los), 1)), np.ones((len(los), 1), bool),
                              np.zeros((len(los), 3)))  # fmt: skip
    np.testing.assert_allclose(side, np.cross(DOWN, los), atol=1e-12)


@pytest.mark.parametrize("offset", [0.0, 1e-15, 1e-12])
def test_mvp_head_on_pairs_both_turn_right(offset):
    los = _headings()
    d = 40.0 * los + offset * np.cross(DOWN, los)
    w = -12.0 * los
    mask = np.ones(len(los), bool)
    own = mvp_velocity_change(d, w, mask, 10.5, 10.0, 1.0)
    other = mvp_velocity_change(-d, -w, mask, 10.5, 10.0, 1.0)
    right = np.cross(DOWN, los)
    assert np.all(np.einsum("ki,ki->k", own, right) > 1.0)
    assert np.all(np.einsum("ki,ki->k", other, -right) > 1.0)  # its line of sight is -los


@pytest.mark.parametrize("offset", [0.0, 1e-14, 1e-11])
@pytest.mark.parametrize("above", [True, False])
def test_mvp_vertical_head_on_is_resolved_vertically(offset, above):
    """Straight above or below: BlueSky's vertical resolution, the pair moving apart.

    The reproducer: an intruder 20 m above descending at 10 m/s relative got no change.
    """
    sign = -1.0 if above else 1.0
    d = np.array([[offset, 0.0, 20.0 * sign]])
    w = np.array([[0.0, 0.0, -10.0 * sign]])
    own = mvp_velocity_change(d, w, np.array([True]), 10.5, 10.0, 1.0, 0.01)[0]
    other = mvp_velocity_change(-d, -w, np.array([True]), 10.5, 10.0, 1.0, 0.01)[0]
    # The whole zone over the time to the CPA (2 s), along w: away from the intruder.
    np.testing.assert_allclose(own, [0.0, 0.0, -sign * 10.5 / 2.0], atol=1e-9)
    np.testing.assert_allclose(other, -own, atol=1e-9)


def test_mvp_diverging_intrusion_takes_the_past_cpa():
    """BlueSky: ``d_cpa = d + w t_cpa`` with ``t_cpa < 0``, spread over ``|t_cpa|``."""
    rng = np.random.default_rng(3)
    radius, t_min = 10.5, 1.0
    d = rng.normal(size=(200, 3))
    d *= rng.uniform(2.0, 9.0, (200, 1)) / np.linalg.norm(d, axis=-1, keepdims=True)
    w = rng.normal(scale=6.0, size=(200, 3))
    w *= np.sign(np.einsum("ki,ki->k", d, w))[:, None]  # diverging: d . w > 0
    dv = mvp_velocity_change(d, w, np.ones(200, bool), radius, 10.0, t_min)
    t = -np.einsum("ki,ki->k", d, w) / np.einsum("ki,ki->k", w, w)
    assert np.all(t < 0.0)
    d_cpa = d + w * t[:, None]
    miss = np.linalg.norm(d_cpa, axis=-1)
    expected = -((radius - miss) / np.maximum(-t, t_min))[:, None] * d_cpa / miss[:, None]
    np.testing.assert_allclose(dv, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-13, 1e-10])
def test_orca_head_on_pairs_both_turn_right(angle):
    """Exactly head-on the cone has no nearest leg: the right one (it had no constraint)."""
    los = _headings()
    right = np.cross(DOWN, los)
    p = 40.0 * (los + angle * right)
    v_i, v_j = 6.0 * los, -6.0 * los
    n, q = orca_planes(p[:, None], (v_i - v_j)[:, None], v_i, 10.0, 5.0, 0.1, 0.5)
    n2, q2 = orca_planes(-p[:, None], (v_j - v_i)[:, None], v_j, 10.0, 5.0, 0.1, 0.5)
    assert np.all(np.einsum("ki,ki->k", n[:, 0], right) > 0.9)
    assert np.all(np.einsum("ki,ki->k", n2[:, 0], -right) > 0.9)
    for k in range(len(los)):
        new_i = solve_orca_lp(n[k], q[k], v_i[k], 10.0)
        new_j = solve_orca_lp(n2[k], q2[k], v_j[k], 10.0)
        assert (new_i - v_i[k]) @ right[k] > 0.5 and (new_j - v_j[k]) @ -right[k] > 0.5


@pytest.mark.parametrize("name", ["apf", "motion-state-apf", "traditional-apf"])
def test_apfs_take_no_side_head_on(name):
    """The APFs push along the line of sight (or the region's normal): head-on they brake,
    and any side comes from the geometry's offset. Documented, not changed (their published
    figures are pinned by tests/test_shipped.py)."""
    from uasep_env.policies import MotionStateAPF, TraditionalAPF

    los = _headings(8)
    k = len(los)
    o = {
        "velocity": 10.0 * los,
        "obstacle_rel_pos": 20.0 * los[:, None],
        "obstacle_rel_vel": -14.0 * los[:, None],
        "obstacle_mask": np.ones((k, 1), bool),
        "obstacle_center": 20.0 * los[:, None],
        "obstacle_axes": np.tile([12.0, 12.0, 8.0], (k, 1, 1)),
        "obstacle_heading_cs": np.stack([-los[:, 0], -los[:, 1]], axis=-1)[:, None],
    }
    # The reference gains (margin scale 1): the obstacle, 20 m off, is inside every margin.
    if name == "apf":
        f = _obstacle_repulsion(o, APFGains())
    else:
        cls = MotionStateAPF if name == "motion-state-apf" else TraditionalAPF
        policy = cls.__new__(cls)
        policy.gains = APFGains()
        from uasep_env import make_config

        policy.config = make_config()
        f = policy.obstacle_repulsion(o)
    assert np.all(np.einsum("ki,ki->k", f, -los) > 0.0)  # it pushes back
    np.testing.assert_allclose(np.einsum("ki,ki->k", f, np.cross(DOWN, los)), 0.0, atol=1e-9)
    assert isinstance(APFGains(), APFGains)


def _scipy_filter_qp(u0, a, b, valid, lo, hi, rho):
    """The filter QP by scipy's SLSQP, well scaled (``x = sqrt(rho) s``), one agent at a time."""
    out, r = np.empty((len(u0), 4)), np.sqrt(rho)
    for i in range(len(u0)):
        cons = [
            {"type": "ineq", "fun": lambda z, n=a[i, j], c=b[i, j]: n @ z[:3] + z[3] / r - c,
             "jac": lambda z, n=a[i, j]: np.r_[n, 1.0 / r]}
            for j in range(a.shape[1]) if valid[i, j]
        ]  # fmt: skip
        start = np.clip(u0[i], lo[i], hi[i])
        best = None
        for x3 in (0.0, r * (max(0.0, np.max(np.where(valid[i], b[i], 0.0))) + 6.0)):
            res = minimize(
                lambda z, i=i: 0.5 * ((z[:3] - u0[i]) @ (z[:3] - u0[i]) + z[3] ** 2),
                np.r_[start, x3], jac=lambda z, i=i: np.r_[z[:3] - u0[i], z[3]],
                constraints=cons, bounds=[*zip(lo[i], hi[i], strict=True), (0.0, None)],
                method="SLSQP", options={"ftol": 1e-14, "maxiter": 1000},
            )  # fmt: skip
            if best is None or res.fun < best.fun:
                best = res
        out[i] = np.r_[best.x[:3], best.x[3] / r]
    return out


@pytest.mark.parametrize("seed,spread", [(0, 3.0), (1, 0.5), (3, 6.0)])
def test_filter_qp_is_exact_up_to_the_largest_slack_penalty(seed, spread):
    """At ``rho`` = 1e6, the top of ``CBFParams.slack_penalty``'s range, as scipy or better.

    (Past it the enumeration's dependence test rejects the true active set: at 1e7 and 1e8
    it returns costlier answers on some instances, hence the cap.)
    """
    rho = 1e6
    u0, a, b, valid, lo, hi = _random_qps(seed, batch=60, spread=spread)
    u, s = solve_filter_qp(u0, a, b, valid, lo, hi, rho)
    ref = _scipy_filter_qp(u0, a, b, valid, lo, hi, rho)

    def cost(uu, ss):
        return 0.5 * ((uu - u0) ** 2).sum(axis=-1) + 0.5 * rho * ss**2

    assert np.all(cost(u, s) <= cost(ref[:, :3], ref[:, 3]) * (1 + 1e-7) + 1e-9)
    np.testing.assert_allclose(u, ref[:, :3], atol=1e-5)
    short = np.einsum("bkj,bj->bk", a, u) + s[:, None] - b
    assert np.all(np.where(valid, short, 0.0) >= -1e-8)  # the slack is sqrt(rho) x: 1e3 x
    with pytest.raises(ValueError, match=r"cbf\.slack_penalty"):
        CBFParams(slack_penalty=1e7)
