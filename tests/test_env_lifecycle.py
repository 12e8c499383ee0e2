"""Spaces that tell the truth after reset options, and environments that stay closed."""

import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError

from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.parallel import env as aec_env
from uasep_env.envs.parallel import parallel_env
from uasep_env.envs.vector import FormationVectorEnv


def test_a_reset_option_that_changes_the_observation_width_is_refused():
    env = parallel_env()
    env.reset(seed=0)
    width = env.observation_space("uav_0").shape
    with pytest.raises(ValueError, match=r"changes the observation width from 58 to 61"):
        env.reset(seed=1, options={"config": {"action": {"mode": "residual_apf"}}})
    obs, _ = env.reset(seed=1)
    assert env.observation_space("uav_0").shape == width == obs["uav_0"].shape
    # A change that keeps the spaces is still allowed, and the spaces still hold.
    obs, _ = env.reset(seed=2, options={"config": {"noise": False}})
    assert all(env.observation_space(a).contains(o) for a, o in obs.items())


def _closed_calls():
    par = parallel_env()
    par.reset(seed=0)
    yield (
        "parallel",
        par,
        [
            lambda: par.reset(seed=0),
            lambda: par.step({a: np.zeros(3, np.float32) for a in par.possible_agents}),
        ],
    )
    aec = aec_env()
    aec.reset(seed=0)
    yield "aec", aec, [lambda: aec.reset(seed=0), lambda: aec.step(np.zeros(3, np.float32))]
    gym = FormationEnv()
    gym.reset(seed=0)
    yield "gym", gym, [lambda: gym.reset(seed=0), lambda: gym.step(gym.action_space.sample())]
    vec = FormationVectorEnv(num_envs=2)
    vec.reset(seed=0)
    yield "vector", vec, [lambda: vec.reset(seed=0), lambda: vec.step(vec.action_space.sample())]


def _refuses_after_close(env, calls) -> None:
    env.close()
    env.close()  # twice is harmless
    for call in calls:
        with pytest.raises(ClosedEnvironmentError, match=r"called after close\(\)"):
            call()


def test_every_view_refuses_reset_and_step_after_close():
    for _name, env, calls in _closed_calls():
        _refuses_after_close(env, calls)


def test_the_sb3_adapter_refuses_reset_and_step_after_close():
    pytest.importorskip("stable_baselines3")  # the train extra
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    sb3 = UAVSharedVecEnv(n_envs=1, seed=0)
    sb3.reset()
    _refuses_after_close(
        sb3, [sb3.reset, lambda: sb3.step(np.zeros((sb3.num_envs, 3), np.float32))]
    )
