"""The CBF: its QP against a maintained solver, the barriers on collision courses, the shield."""

import dataclasses

import numpy as np
import pytest
from safety import COLLISION_COURSES, no_avoidance, separation_losses

from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.evaluation import evaluate
from uasep_env.evaluation.cli import main as eval_main
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import (
    APF,
    CBFQP,
    CBFFilter,
    CBFParams,
    Policy,
    Shielded,
    ZeroPolicy,
    check_policy_name,
    make_policy,
    split_shield,
)
from uasep_env.policies.qp import solve_filter_qp


def _random_qps(seed: int, batch: int = 200, k: int = 4, spread: float = 3.0):
    """Random filter QPs: unit normals, bounds that often cannot all hold (slack active)."""
    rng = np.random.default_rng(seed)
    u0 = rng.normal(0.0, 2.0, (batch, 3))
    a = rng.normal(size=(batch, k, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b = rng.normal(0.0, spread, (batch, k))
    valid = rng.random((batch, k)) < 0.8
    half = rng.uniform(0.5, 3.0, (batch, 3))
    centre = rng.uniform(-0.5, 0.5, (batch, 3))
    return u0, a, b, valid, centre - half, centre + half


def _reference(u0, a, b, valid, lo, hi, rho):
    """The same QP by qpsolvers (Clarabel, an interior-point solver), one agent at a time."""
    qpsolvers = pytest.importorskip("qpsolvers")
    if "clarabel" not in qpsolvers.available_solvers:
        pytest.skip("qpsolvers has no Clarabel backend")
    out = np.empty((len(u0), 4))
    for i in range(len(u0)):
        rows = [np.r_[a[i, j], 1.0] for j in range(a.shape[1]) if valid[i, j]]
        rhs = [b[i, j] for j in range(a.shape[1]) if valid[i, j]]
        g = -np.array([*rows, [0.0, 0.0, 0.0, 1.0]])  # qpsolvers: G z <= h
        h = -np.array([*rhs, 0.0])
        z = qpsolvers.solve_qp(
            np.diag([1.0, 1.0, 1.0, rho]),
            np.r_[-u0[i], 0.0],
            g,
            h,
            lb=np.r_[lo[i], -np.inf],
            ub=np.r_[hi[i], np.inf],
            solver="clarabel",
            tol_gap_abs=1e-10,
            tol_gap_rel=1e-10,
            tol_feas=1e-10,
        )
        assert z is not None
        out[i] = z
    return out


@pytest.mark.filterwarnings("ignore::UserWarning")  # qpsolvers' dense-to-sparse notice
@pytest.mark.parametrize("seed,spread,rho", [(0, 3.0, 1e4), (1, 0.5, 1e4), (2, 6.0, 10.0)])
def test_qp_equals_a_maintained_solver(seed, spread, rho):
    """Random instances, feasible and not (the slack active), against Clarabel."""
    u0, a, b, valid, lo, hi = _random_qps(seed, spread=spread)
    u, s = solve_filter_qp(u0, a, b, valid, lo, hi, rho)
    ref = _reference(u0, a, b, valid, lo, hi, rho)
    # Clarabel (interior point) stops about 1e-6 inside the bounds; the enumeration is exact
    # to round-off, so it is as near as Clarabel and never costs more.
    np.testing.assert_allclose(u, ref[:, :3], atol=1e-5)
    np.testing.assert_allclose(s, ref[:, 3], atol=1e-5)

    def cost(uu, ss):
        return 0.5 * ((uu - u0) ** 2).sum(axis=-1) + 0.5 * rho * ss**2

    # (Clarabel's answer may break a constraint by ~1e-8 and so cost a hair less.)
    ref_cost = cost(ref[:, :3], ref[:, 3])
    assert np.all(cost(u, s) <= ref_cost * (1 + 1e-6) + 1e-9)
    assert (s > 1e-3).sum() >= 10 and (s < 1e-9).sum() >= 10  # both kinds were tested
    assert np.all(u >= lo - 1e-9) and np.all(u <= hi + 1e-9)
    short = np.einsum("bkj,bj->bk", a, u) + s[:, None] - b
    assert np.all(np.where(valid, short, 0.0) >= -1e-9)


def test_qp_leaves_a_safe_command_alone_and_is_minimal():
    """A command meeting every constraint is returned as is; else the soft projection."""
    u0 = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    a = np.array([[[1.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]]])
    b = np.array([[0.5], [0.5]])
    lo, hi = np.full((2, 3), -2.0), np.full((2, 3), 2.0)
    u, s = solve_filter_qp(u0, a, b, np.ones((2, 1), bool), lo, hi, 1e4)
    np.testing.assert_array_equal(u[0], u0[0])  # bit for bit: no solve at all
    # Closed form: the shortfall 1.5 splits as rho : 1 between u and the slack.
    rho = 1e4
    np.testing.assert_allclose(u[1], [-1.0 + 1.5 * rho / (1 + rho), 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(s, [0.0, 1.5 / (1 + rho)], atol=1e-12)
    # Out of reach of the bounds: the slack takes the shortfall, u sits on the bound.
    u, s = solve_filter_qp(u0[1:], a[1:], np.array([[3.0]]), np.ones((1, 1), bool),
                           lo[1:], hi[1:], 1e4)  # fmt: skip
    assert u[0, 0] == pytest.approx(2.0) and s[0] == pytest.approx(1.0, abs=1e-9)


def test_qp_batched_equals_per_agent_bit_for_bit():
    u0, a, b, valid, lo, hi = _random_qps(3, batch=40)
    u, s = solve_filter_qp(u0, a, b, valid, lo, hi, 1e4)
    for i in range(len(u0)):
        ui, si = solve_filter_qp(u0[i], a[i], b[i], valid[i], lo[i], hi[i], 1e4)
        np.testing.assert_array_equal(ui, u[i])
        np.testing.assert_array_equal(si, s[i])
    # Any leading shape.
    u2, _ = solve_filter_qp(
        *(x.reshape(4, 10, *x.shape[1:]) for x in (u0, a, b, valid, lo, hi)), 1e4
    )
    np.testing.assert_array_equal(u2.reshape(-1, 3), u)


@pytest.mark.parametrize("scenario", COLLISION_COURSES)
def test_cbf_qp_resolves_collision_courses_under_noise(scenario):
    """CBF-QP keeps separation where plan tracking alone collides on every seed.

    Measured (6 seeds each): closest obstacle 14.0 m head-on and 13.7 m crossing, against
    the 10 m obstacle separation; closest UAV pair 10.0 m against 8 m. Without the sidestep
    (``deadlock_gain=0``) one head-on seed is held in front of the obstacle until the UAV
    is lost (over 300 m off its plan): ``terminated``.
    """
    r = separation_losses(CBFQP, scenario)
    assert not any(r["collision"]) and not any(r["lost"]), r
    assert not any(r["terminated"]), r


@pytest.mark.parametrize("scenario", COLLISION_COURSES)
def test_shield_makes_a_non_avoiding_policy_safe(scenario):
    """The shield's point: plan tracking alone collides; shielded, it keeps separation."""
    bare = separation_losses(no_avoidance, scenario)
    assert all(bare["collision"]), bare
    shielded = separation_losses(lambda cfg: Shielded(no_avoidance(cfg), cfg), scenario)
    assert not any(shielded["collision"]) and not any(shielded["lost"]), shielded


def test_shield_leaves_the_policy_alone_far_from_conflicts():
    cfg = make_config(scenario="paper")
    core = EnvCore(cfg, n_envs=3)
    obs = core.reset(seed=0)  # the obstacle starts hundreds of metres away
    apf = APF(cfg)
    np.testing.assert_array_equal(Shielded(apf, cfg)(obs), apf(obs))


def _rollout_obs(cfg, n_envs=4, steps=300, seed=0):
    """Observations along a CBF-QP rollout (so some constraints are active)."""
    core = EnvCore(cfg, n_envs=n_envs)
    obs = core.reset(seed=seed)
    policy = CBFQP(cfg)
    out = []
    for _ in range(steps):
        out.append(obs)
        obs = core.step(policy(obs)).obs
    return np.stack(out)


def test_cbf_batched_equals_per_agent_and_is_deterministic():
    cfg = make_config(scenario="collision_head_on", episode_duration=100.0)
    obs = _rollout_obs(cfg)[150::6]  # (T, E, N, D), around the meeting
    policy = CBFQP(cfg)
    batched = policy(obs)
    o = policy.cbf.layout.decode(obs)
    assert (np.abs(batched - policy.nominal(o)) > 1e-3).any()  # some barriers acted
    again = CBFQP(cfg)(obs)
    np.testing.assert_array_equal(again, batched)  # deterministic, fresh instance
    for idx in np.ndindex(obs.shape[:3]):
        np.testing.assert_array_equal(policy(obs[idx]), batched[idx])
    shield = Shielded(ZeroPolicy(cfg), cfg)
    shielded = shield(obs)
    for idx in list(np.ndindex(obs.shape[:3]))[::7]:
        np.testing.assert_array_equal(shield(obs[idx]), shielded[idx])


def test_shield_in_residual_mode_filters_the_flown_command():
    """In ``residual_apf`` mode the action corrects the APF: the command flown is filtered."""
    cfg = make_config(scenario="collision_head_on", episode_duration=100.0)
    res_cfg = cfg.replace(action={"mode": "residual_apf"})
    obs = _rollout_obs(cfg)[150::6]
    layout = ObservationLayout.from_config(res_cfg)
    # The residual observation: the world part and the APF's command.
    from uasep_env.interface.actions import ResidualAPF

    residual = ResidualAPF(res_cfg)
    res_obs = residual.observe(obs, residual.base(obs))
    assert res_obs.shape[-1] == layout.dim
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (*obs.shape[:-1], 3)).astype(np.float32)
    out = CBFFilter(res_cfg).filter(res_obs, actions)
    flown = residual.command(residual.base(obs), out).astype(float)
    # The same command as the direct-mode filter with the residual mode's tighter bounds.
    cbf = CBFFilter(res_cfg)
    o = cbf.layout.decode(res_obs)
    lo, hi = cbf.bounds(o)
    u = flown * cfg.uav.max_accel
    assert np.all(u >= lo - 1e-4) and np.all(u <= hi + 1e-4)
    want = cbf.filter_command(o, residual.command(residual.base(obs), actions))
    np.testing.assert_allclose(flown, want, atol=1e-5)  # float32 actions
    assert np.abs(out - actions).max() > 0.1  # it did change some


def test_params_are_validated_naming_the_field():
    for field, bad in [
        ("alpha1", -1.0),
        ("alpha2", 0.0),
        ("margin_scale", float("nan")),
        ("uav_buffer", -0.5),
        ("max_constraints", 0),
        ("max_constraints", 2.5),
        ("uav_share", 1.5),
        ("slack_penalty", 0.0),
        ("deadlock_gain", -1.0),
    ]:
        with pytest.raises(ValueError, match=rf"cbf\.{field}="):
            CBFParams(**{field: bad})
    with pytest.raises(TypeError):
        CBFParams(alpha=1.0)  # unknown keyword
    with pytest.raises(TypeError):
        CBFParams(0.5)  # keyword-only
    with pytest.raises(dataclasses.FrozenInstanceError):
        CBFParams().alpha1 = 2.0
    with pytest.raises(TypeError, match="CBFParams"):
        CBFQP(make_config(), params={"alpha1": 1.0})


def test_margin_scale_scales_the_radii():
    cfg = make_config()
    one = CBFFilter(cfg, CBFParams(margin_scale=1.0))
    two = CBFFilter(cfg, CBFParams(margin_scale=2.0))
    assert two.uav_radius == pytest.approx(2 * one.uav_radius)
    assert two.obstacle_radius == pytest.approx(2 * one.obstacle_radius)
    assert one.obstacle_radius == cfg.uav.obstacle_separation + CBFParams().obstacle_buffer
    # The default is the knee of CBF-QP's front (2 in -v3), not 1.
    assert CBFFilter(cfg).obstacle_radius == pytest.approx(two.obstacle_radius)


def test_shield_by_name():
    cfg = make_config()
    assert split_shield("ppo_shared+cbf") == ("ppo_shared", "cbf")
    assert split_shield("apf") == ("apf", None)
    assert split_shield("a+b") == ("a+b", None)  # not a shield: the whole name
    policy = make_policy("apf+cbf", cfg)
    assert isinstance(policy, Shielded) and isinstance(policy, Policy)
    assert isinstance(policy.policy, APF) and policy.name == "apf+cbf"
    assert isinstance(make_policy("cbf-qp", cfg), CBFQP)
    assert check_policy_name("ppo_shared+cbf") == "ppo_shared+cbf"
    with pytest.raises(ValueError, match="unknown policy 'apff'"):
        check_policy_name("apff+cbf")
    with pytest.raises(ValueError, match="unknown policy 'apf\\+cfb'"):
        check_policy_name("apf+cfb")


def test_eval_cli_shield_flag(tmp_path, capsys):
    out = tmp_path / "r.json"
    args = ["--policy", "apf,zero", "--shield", "cbf", "--scenario", "collision_head_on",
            "--config", "episode_duration=60", "--json", str(out), "--quiet"]  # fmt: skip
    assert eval_main(args) == 0
    import json

    data = json.loads(out.read_text())
    assert data["policies"] == ["apf+cbf", "zero+cbf"]
    assert eval_main(["--policy", "apf", "--shield", "cfb"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--shield" in err and "'cfb'" in err


def test_evaluate_labels_shielded_paths(tmp_path):
    from uasep_env.evaluation.runner import _policy_label

    assert _policy_label("runs/x/policy.zip+cbf", []) == "policy+cbf"
    assert _policy_label("apf+cbf", ["apf"]) == "apf+cbf"
    cfg = make_config(scenario="paper", episode_duration=10.0)
    result = evaluate(["apf", "apf+cbf"], cfg, [0])
    assert list(result.results) == ["apf", "apf+cbf"]
