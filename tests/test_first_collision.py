"""Every view ends the episode at the step of the first collision (issue 53, item 6).

An episode that ended only once EVERY UAV had collided was noticed by the reward tests
alone. Here an obstacle is flown into one UAV of the formation (``collision_head_on``,
plan tracking without avoidance: ``tests/safety.py``); the step of the first collision is
read off the world's own per-step distances (not off the outcome's flags), and every view
(the core, the PettingZoo parallel env and its AEC view, the Gymnasium env, the vector env,
the SB3 adapter) must end the episode exactly there, with its lifecycle signals (agents
gone, autoreset, ``terminal_observation``). Once with the numba kernels and once on the
numpy reference path: ``_kernels/rewards.py`` computes the same collision flags.
"""

import numpy as np
import pytest
from safety import collision_config, no_avoidance

from uasep_env import _numba
from uasep_env.envs.core import EnvCore
from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.parallel import env as aec_env
from uasep_env.envs.parallel import parallel_env
from uasep_env.envs.vector import FormationVectorEnv

SEED = 0
CONFIG = collision_config("collision_head_on")
N = CONFIG.n_uavs


@pytest.fixture(params=["numba", "numpy"])
def path(request, monkeypatch):
    """Run the test with the compiled kernels, then on the numpy reference."""
    if request.param == "numba":
        if not _numba.available():
            pytest.skip("numba not installed or UASEP_NUMBA=0")
    else:
        monkeypatch.setitem(_numba._state, "numba", None)
        assert not _numba.available()
    return request.param


def _first_collision() -> int:
    """The 1-based step at which a UAV first comes within the collision distance (world)."""
    core, policy = EnvCore(CONFIG, n_envs=1), no_avoidance(CONFIG)
    obs = core.reset(seed=SEED)
    d_col = CONFIG.uav.collision_distance
    for step in range(1, core._max_steps + 1):
        obs = core.step(policy(obs)).obs
        w = core.world
        hit = (w.min_uav_dist[0] < d_col) | (w.min_obstacle_dist[0] < d_col)
        if hit.any():
            # The case tells "first" from "every": one UAV is hit, the others are not.
            assert 0 < hit.sum() < N, hit
            return step
    raise AssertionError("no collision: the encounter is not on a collision course")


@pytest.fixture(scope="module")
def first_collision() -> int:
    return _first_collision()


def test_the_core_ends_at_the_first_collision(path, first_collision):
    core, policy = EnvCore(CONFIG, n_envs=1), no_avoidance(CONFIG)
    obs = core.reset(seed=SEED)
    for step in range(1, first_collision + 1):
        res = core.step(policy(obs))
        obs = res.obs
        assert bool(res.terminated[0]) == (step == first_collision), step
        assert not res.truncated[0]
    assert res.safety["collision"][0].sum() < N  # not every UAV collided


def test_the_parallel_env_ends_at_the_first_collision(path, first_collision):
    env, policy = parallel_env(CONFIG), no_avoidance(CONFIG)
    obs, _ = env.reset(seed=SEED)
    for step in range(1, first_collision + 1):
        assert env.agents == env.possible_agents
        obs, _, term, trunc, _ = env.step({a: policy(o) for a, o in obs.items()})
        assert all(t == (step == first_collision) for t in term.values()), step
        assert not any(trunc.values())
    assert env.agents == []  # everyone's episode is over


def test_the_aec_view_ends_at_the_first_collision(path, first_collision):
    env, policy = aec_env(CONFIG), no_avoidance(CONFIG)
    env.reset(seed=SEED)
    steps = 0
    for agent in env.agent_iter(max_iter=N * (first_collision + 2)):
        obs, _, term, trunc, _ = env.last()
        if term or trunc:
            assert term and not trunc and steps == first_collision, (agent, steps)
            env.step(None)
            continue
        env.step(policy(obs))
        steps += agent == env.possible_agents[-1]  # the joint step is taken after the last
        if steps < first_collision:
            assert not any(env.terminations.values()), steps
    assert steps == first_collision and env.agents == []


def test_the_gymnasium_env_ends_at_the_first_collision(path, first_collision):
    env, policy = FormationEnv(CONFIG), no_avoidance(CONFIG)
    obs, _ = env.reset(seed=SEED)
    for step in range(1, first_collision + 1):
        obs, _, term, trunc, _ = env.step(policy(obs.reshape(N, -1)).reshape(-1))
        assert term == (step == first_collision) and not trunc, step


def test_the_vector_env_ends_at_the_first_collision(path, first_collision):
    env, policy = FormationVectorEnv(2, CONFIG), no_avoidance(CONFIG)
    obs, _ = env.reset(seed=[SEED, SEED])
    shape = (2, N, -1)
    for step in range(1, first_collision + 1):
        obs, _, term, trunc, _ = env.step(policy(obs.reshape(shape)).reshape(2, -1))
        assert term.tolist() == [step == first_collision] * 2 and not trunc.any(), step
    # Next-step autoreset: the following step starts both episodes afresh.
    obs, rewards, term, trunc, _ = env.step(np.zeros((2, N * 3), np.float32))
    assert not term.any() and not trunc.any() and (rewards == 0).all()
    env.close()


def test_the_sb3_adapter_ends_at_the_first_collision(path, first_collision):
    pytest.importorskip("stable_baselines3")  # the floors' job has no SB3
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    env, policy = UAVSharedVecEnv(1, CONFIG, seed=SEED), no_avoidance(CONFIG)
    obs = env.reset()
    for step in range(1, first_collision + 1):
        obs, _, dones, infos = env.step(policy(obs))
        assert dones.tolist() == [step == first_collision] * N, step
    assert all("terminal_observation" in i and not i["TimeLimit.truncated"] for i in infos)
    env.close()
