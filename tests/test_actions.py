"""The residual action modes: a zero correction flies the base controller exactly, in every view."""

import gymnasium
import numpy as np
import pytest

import uasep_env
from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.interface.actions import ResidualAPF
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import APF, MVP, MVPParams

RESIDUAL = {"action": {"mode": "residual_apf"}}


def test_layout_adds_the_apf_command_at_the_end():
    direct = ObservationLayout.from_config(make_config())
    residual = ObservationLayout.from_config(make_config(**RESIDUAL))
    assert residual.dim == direct.dim + 3 == residual.world_dim + 3
    assert residual.feature_names()[-3:] == ["base_action[0]", "base_action[1]", "base_action[2]"]
    assert len(residual.feature_names()) == residual.dim


_BASES = {
    "residual_apf": APF,
    "residual_mvp_region": lambda c: MVP(c, MVPParams(obstacle_model="region")),
}


@pytest.mark.parametrize("mode", list(_BASES))
def test_core_zero_residual_is_the_base_bit_for_bit(mode):
    cfg = make_config(scenario="random", n_obstacles=2)
    a, b = EnvCore(cfg, 6), EnvCore(cfg.replace(action={"mode": mode}), 6)
    apf = _BASES[mode](cfg)  # the base controller, flown directly
    oa, ob = a.reset(seed=5), b.reset(seed=5)
    for _ in range(200):
        np.testing.assert_array_equal(ob[..., :-3], oa)
        np.testing.assert_array_equal(ob[..., -3:], apf(oa))  # the observed base command
        ra, rb = a.step(apf(oa)), b.step(np.zeros((6, 3, 3)))
        np.testing.assert_array_equal(ra.rewards, rb.rewards)
        np.testing.assert_array_equal(a.world.uav_pos, b.world.uav_pos)
        oa, ob = ra.obs, rb.obs
    assert mode != "residual_mvp_region" or not np.array_equal(a.world.uav_pos, _apf_flight(cfg))


def _apf_flight(cfg):
    """Where the APF's formation is after the test's 200 steps (another base flies elsewhere)."""
    core, apf = EnvCore(cfg, 6), APF(cfg)
    obs = core.reset(seed=5)
    for _ in range(200):
        obs = core.step(apf(obs)).obs
    return core.world.uav_pos


def test_an_unknown_residual_base_is_named():
    with pytest.raises(ValueError, match=r"action\.mode.*residual_orca"):
        make_config(action={"mode": "residual_orca"})
    with pytest.raises(ValueError, match="mode='direct'"):
        ResidualAPF(make_config())  # a direct config names no base
    with pytest.raises(ValueError, match="only the residual_apf mode's base has APF gains"):
        ResidualAPF(make_config(action={"mode": "residual_mvp_region"}), APF.default_gains)


def test_residual_is_bounded_and_added():
    cfg = make_config(action={"mode": "residual_apf", "residual_scale": 0.25})
    core = EnvCore(cfg, 2)
    obs = core.reset(seed=1)
    base = obs[..., -3:].astype(float)
    core.step(np.full((2, 3, 3), 1.0))
    expected = np.clip(base + 0.25, -1, 1) * cfg.uav.max_accel
    np.testing.assert_allclose(core.world.accel_cmd, expected, rtol=1e-12)


def test_residual_obs_after_partial_reset_track_the_new_episode():
    cfg = make_config(scenario="random", formation_spacing=0.5, **RESIDUAL)
    core = EnvCore(cfg, 4)
    core.reset(seed=2)
    res = core.step(np.zeros((4, 3, 3)))
    done = res.terminated | res.truncated
    assert done.any()  # 0.5 m spacing: collisions at once
    fresh = core.reset_some(done)
    np.testing.assert_array_equal(fresh[..., -3:], ResidualAPF(cfg).base(fresh[..., :-3]))
    # The next step corrects the APF command of the *new* episodes.
    np.testing.assert_array_equal(core._base[done], fresh[..., -3:])


def _apf_returns_pettingzoo(cfg, seed, steps):
    env = uasep_env.parallel_env(cfg)
    obs, _ = env.reset(seed=seed)
    apf = APF(cfg.replace(action={"mode": "direct"}))
    out = []
    for _ in range(steps):
        if cfg.action.mode == "direct":
            act = {a: apf(obs[a]) for a in env.agents}
        else:
            act = {a: np.zeros(3, np.float32) for a in env.agents}
        obs, rew, *_ = env.step(act)
        out.append([rew[a] for a in env.possible_agents])
    return np.array(out)


def test_every_view_offers_the_mode():
    cfg = make_config(scenario="crossing", episode_duration=20.0)
    res = cfg.replace(**RESIDUAL)
    # PettingZoo
    np.testing.assert_array_equal(
        _apf_returns_pettingzoo(cfg, 3, 50), _apf_returns_pettingzoo(res, 3, 50)
    )
    # gymnasium.make
    g = gymnasium.make("uasep/Formation-v3", **RESIDUAL)
    obs, _ = g.reset(seed=0)
    n = g.unwrapped.config.n_uavs
    assert obs.shape == (n * ObservationLayout.from_config(g.unwrapped.config).dim,)
    assert g.observation_space.contains(obs)
    obs, *_ = g.step(np.zeros(n * 3, np.float32))
    assert g.observation_space.contains(obs)
    # make_vec
    v = gymnasium.make_vec("uasep/Formation-v3", num_envs=3, **RESIDUAL)
    obs, _ = v.reset(seed=0)
    obs, *_ = v.step(np.zeros(v.action_space.shape, np.float32))
    assert v.observation_space.contains(obs)
    v.close()


def test_sb3_adapter_offers_the_mode():
    pytest.importorskip("stable_baselines3")
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    cfg = make_config(scenario="crossing", episode_duration=20.0, **RESIDUAL)
    venv = UAVSharedVecEnv(n_envs=2, config=cfg, seed=0)
    obs = venv.reset()
    assert obs.shape == (6, ObservationLayout.from_config(cfg).dim)
    venv.step_async(np.zeros((6, 3), np.float32))
    obs, rew, _done, _ = venv.step_wait()
    assert np.isfinite(rew).all() and venv.observation_space.contains(obs[0])


@pytest.mark.parametrize(
    ("override", "field"),
    [
        ({"action": {"mode": "residual"}}, "action.mode"),
        ({"action": {"residual_scale": 0.0}}, "action.residual_scale"),
        ({"action": {"residual_scale": float("nan")}}, "action.residual_scale"),
        ({"action": {"mode": "residual_apf"}, "observation": {"clip": 0.5}}, "observation.clip"),
    ],
)
def test_action_config_is_validated(override, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make_config(**override)


@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_default_observations_are_never_clipped(scenario):
    # Nothing a default episode observes reaches the clip bound (issue 13: waypoint_dist
    # read 1,000 m where the truth was up to 1,012 m with the former clip of 10).
    cfg = make_config(scenario=scenario)
    layout = ObservationLayout.from_config(cfg)
    wp = layout.feature_names().index("waypoint_dist")
    core = EnvCore(cfg, 8)
    obs = core.reset(seed=11)
    apf = APF(cfg)
    largest = np.abs(obs).max()
    first_wp = obs[..., wp].max() * layout.pos_scale
    for _ in range(cfg.max_steps):
        res = core.step(apf(obs))
        obs = res.obs
        largest = max(largest, np.abs(obs).max())
        if (res.terminated | res.truncated).all():
            break
    assert first_wp > 1000.0  # the case that used to clip
    assert largest < cfg.observation.clip
