"""Reference controllers: interface, bounds, repulsion direction, paper-scenario behaviour."""

import numpy as np
import pytest
from conftest import given, settings, st
from safety import COLLISION_COURSES, no_avoidance, separation_losses

from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.interface.observation import ObservationLayout
from uasep_env.metrics import episode_metrics
from uasep_env.policies import (
    APF,
    POLICIES,
    APFGains,
    MotionStateAPF,
    Policy,
    TraditionalAPF,
    make_policy,
)
from uasep_env.rollout import run_episodes

APFS = (APF, MotionStateAPF, TraditionalAPF)


@pytest.mark.parametrize("name", sorted(POLICIES))
def test_every_policy_batched_and_in_bounds(name):
    cfg = make_config(scenario="random", n_obstacles=2, n_uavs=4)
    core = EnvCore(cfg, n_envs=6)
    obs = core.reset(seed=0)
    policy = make_policy(name, cfg)
    assert isinstance(policy, Policy)
    for _ in range(30):
        act = policy(obs)
        assert act.shape == (6, 4, 3) and np.all(np.abs(act) <= 1.0) and np.all(np.isfinite(act))
        # The same policy on a single agent's observation gives that agent's action.
        np.testing.assert_allclose(
            policy(obs[2, 1]), act[2, 1], atol=1e-6
        ) if name != "random" else None
        obs = core.step(act).obs


def _inner_obs(layout, rel_pos, rel_vel, vel=(5.0, 0.0, 0.0)):
    """An observation with one neighbour and nothing else going on."""
    obs = np.zeros(layout.dim, dtype=np.float32)
    names = layout.feature_names()
    idx = {n: i for i, n in enumerate(names)}

    def put(name, values, scale):
        for c, v in enumerate(values):
            obs[idx[f"{name}[{c}]"]] = v / scale

    put("velocity", vel, layout.vel_scale)
    put("plan_velocity", vel, layout.vel_scale)
    put("formation_velocity", vel, layout.vel_scale)
    put("uav0.rel_pos", rel_pos, layout.pos_scale)
    put("uav0.rel_vel", rel_vel, layout.vel_scale)
    obs[idx["uav0.dist"]] = np.linalg.norm(rel_pos) / layout.pos_scale
    obs[idx["uav0.mask"]] = 1.0
    return obs


@settings(max_examples=150, deadline=None)
@given(
    rel=st.tuples(*[st.floats(-12, 12)] * 3).filter(lambda r: np.linalg.norm(r) > 0.2),
    relv=st.tuples(*[st.floats(-8, 8)] * 3),
)
def test_inner_repulsion_always_pushes_apart(rel, relv):
    cfg = make_config(n_uavs=2, n_obstacles=0)
    layout = ObservationLayout.from_config(cfg)
    obs = _inner_obs(layout, rel, relv)
    for cls in APFS:
        f = cls(cfg).forces(obs)["inner"]
        away = -np.asarray(rel) / np.linalg.norm(rel)
        assert float(f @ away) >= -1e-9, cls.__name__
        if np.linalg.norm(rel) < 2 * APFGains().inner_safe_min - 0.5:
            assert float(f @ away) > 0.0


def test_inner_safe_distance_grows_with_approach_speed():
    cfg = make_config(n_uavs=2, n_obstacles=0)
    layout = ObservationLayout.from_config(cfg)
    apf = APF(cfg)
    rel = (0.0, 11.0, 0.0)  # beyond the static 2 r_min = 10 m
    static = apf.forces(_inner_obs(layout, rel, (0.0, 0.0, 0.0)))["inner"]
    closing = apf.forces(_inner_obs(layout, rel, (0.0, -3.0, 0.0)))["inner"]
    assert np.allclose(static, 0.0)
    assert closing[1] < 0.0  # pushed away from the neighbour (which is at +y)


def test_obstacle_repulsion_points_out_of_the_region_and_only_when_entering():
    # The enclosing ellipsoid (its axes are the lateral extent used below) and the reference
    # gains (6 m of safe distance: the UAV below is 10 m out, beyond it).
    cfg = make_config(scenario="paper", noise=False, prediction={"fit": "enclosing"})
    core = EnvCore(cfg, n_envs=1)
    core.reset(seed=0)
    w = core.world
    apf = APF(cfg, APFGains())
    heading = w.pred_heading[0, 0]
    lateral = np.array([-np.sin(heading), np.cos(heading), 0.0])
    center = w.pred_center[0, 0]
    axes = w.pred_axes[0, 0]
    # A UAV 10 m outside the region, laterally, flying towards it: repelled outwards.
    w.est_pos[0, 2] = center + lateral * (axes[1] + 10.0)
    w.est_vel[0, 2] = -lateral * 5.0
    f = apf.forces(core.observations()[0, 2])["obstacle"]
    assert f @ lateral > 0.0
    # Same place, flying away: not predicted to enter, no force (the paper's rule).
    w.est_vel[0, 2] = lateral * 5.0
    f = apf.forces(core.observations()[0, 2])["obstacle"]
    np.testing.assert_allclose(f, 0.0)


def test_speed_bound_eq4():
    cfg = make_config(n_uavs=2, n_obstacles=0)
    layout = ObservationLayout.from_config(cfg)
    vmax = cfg.uav.max_speed
    obs = _inner_obs(layout, (50.0, 0, 0), (0, 0, 0), vel=(vmax - 0.01, 0.0, 0.0))
    apf = APF(cfg)
    a = apf(obs) * cfg.uav.max_accel
    assert (vmax - 0.01) + a[0] * cfg.step_duration <= vmax + 1e-6


def test_gains_validated():
    with pytest.raises(ValueError, match="k_obstacle=-1"):
        APFGains(k_obstacle=-1.0)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        make_policy("nope", make_config())


@pytest.mark.parametrize("scenario", COLLISION_COURSES)
def test_collision_courses_collide_without_avoidance(scenario):
    """The safety tests' encounters can fail: plan tracking alone collides on every seed."""
    r = separation_losses(no_avoidance, scenario)
    assert all(r["collision"]), r


def test_apf_resolves_collision_courses_under_noise():
    """The APF avoids a straight-flying obstacle aimed at a UAV at its altitude."""
    head_on = separation_losses(APF, "collision_head_on")
    assert not any(head_on["collision"]) and not any(head_on["lost"]), head_on
    crossing = separation_losses(APF, "collision_crossing")
    assert not any(crossing["collision"]), crossing
    # Measured: at right angles the APF comes within 9.9 m of the 10 m obstacle separation on
    # one seed of six (seed 4); a documented weakness, bounded here so it cannot grow.
    assert sum(crossing["lost"]) <= 1 and crossing["distance"] > 9.0, crossing


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_apf_keeps_separation_on_paper_scenario_under_noise(seed):
    # The paper's experiment, reproduced: its obstacle passes 10 m below the formation, so
    # this cannot show avoidance on its own (plan tracking passes it too); the collision
    # courses above do.
    cfg = make_config(scenario="paper")
    ep = run_episodes(APF(cfg), cfg, [seed])[0]
    m = episode_metrics(ep.record).episode
    assert not ep.terminated and not m.collision
    assert m.min_uav_separation > cfg.uav.collision_distance
    assert m.min_obstacle_distance > cfg.uav.collision_distance
    assert m.max_deviation < 40.0  # it comes back to the plan
