"""Safe RL outside the package: Safety-Gymnasium's step form and OmniSafe's PPOLag.

:class:`uasep_env.envs.safe.SafeEnv` (no client needed) is tested everywhere. OmniSafe 0.5.0
cannot share an environment with the package's requirements (its safety-gymnasium pins
gymnasium 0.28.1), so it lives in a venv of its own: ``make test-omnisafe`` (part of
``make ci``) installs ``torch==2.13.0``, this package, ``.ci/omnisafe.txt`` and
``omnisafe==0.5.0 --no-deps`` there and runs this file with ``UASEP_REQUIRE_OMNISAFE=1``, which
makes a missing or broken OmniSafe a failure. Elsewhere the OmniSafe tests skip unless
OmniSafe is installed (as ``tests/test_benchmarl.py`` does for BenchMARL; ``make test``'s
``UASEP_REQUIRE_CLIENTS`` is about the ``clients`` extra, which has no OmniSafe).
"""

from __future__ import annotations

import csv
import importlib
import importlib.util
import os
import sys
import types

import gymnasium
import numpy as np
import pytest
from conftest import run_python

import uasep_env
from uasep_env.envs.safe import SafeEnv, safe_make

ID = "uasep/Formation-v3"
#: 10 steps an episode, and every UAV within 100 m of another: a cost of 1 every step.
SHORT = {"episode_duration": 2.0}
ALWAYS_COSTLY = {"uav": {"separation_distance": 100.0}}


def _client() -> types.ModuleType:
    """``uasep_env.clients.omnisafe``; skip without OmniSafe, fail under make test-omnisafe."""
    if (
        os.environ.get("UASEP_REQUIRE_OMNISAFE") != "1"
        and importlib.util.find_spec("omnisafe") is None
    ):
        pytest.skip("OmniSafe is not installed (make test-omnisafe; docs/clients.md)")
    # Not importorskip("omnisafe"): without the client's stand-in OmniSafe does not import.
    return importlib.import_module("uasep_env.clients.omnisafe")


# --- Safety-Gymnasium's step form (no client) ----------------------------------------------------


def test_safe_env_puts_the_info_cost_in_the_step_tuple():
    plain, safe = (
        gymnasium.make(ID, **SHORT, **ALWAYS_COSTLY),
        safe_make(ID, **SHORT, **ALWAYS_COSTLY),
    )
    assert isinstance(safe, SafeEnv)
    o1, _ = plain.reset(seed=4)
    o2, _ = safe.reset(seed=4)
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a = rng.uniform(-1, 1, plain.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = plain.step(a)
        s_obs, s_reward, cost, s_term, s_trunc, s_info = safe.step(a)
        np.testing.assert_array_equal(obs, s_obs)
        assert (reward, terminated, truncated) == (s_reward, s_term, s_trunc)
        assert cost == info["cost"] == s_info["cost"] > 0
        assert isinstance(cost, float)
    assert truncated and not terminated


def test_safe_env_names_a_missing_cost():
    env = SafeEnv(gymnasium.make("CartPole-v1"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"info\['cost'\]"):
        env.step(0)


def test_the_package_imports_without_omnisafe():
    # The client is imported by name only: the package, the envs and SafeEnv do without it.
    r = run_python(
        """
        import sys
        sys.modules["omnisafe"] = None  # as if not installed
        import uasep_env, uasep_env.clients, uasep_env.envs.safe
        try:
            import uasep_env.clients.omnisafe
        except ImportError as exc:
            print("ImportError", exc)
        """
    )
    assert r.returncode == 0, r.stderr
    assert "ImportError" in r.stdout and "omnisafe" in r.stdout


# --- OmniSafe's CMDP -----------------------------------------------------------------------------


def test_every_uasep_id_is_registered_with_omnisafe():
    client = _client()
    from omnisafe.envs.core import support_envs

    assert set(uasep_env.registration.ENV_IDS) <= set(support_envs())
    assert client.UasepCMDP.support_envs() == list(uasep_env.registration.ENV_IDS)
    sg = sys.modules["safety_gymnasium"]
    if getattr(sg, "UASEP_STAND_IN", False):  # OmniSafe's own tasks say why they are missing
        with pytest.raises(ImportError, match="stand-in"):
            sg.make("SafetyPointGoal1-v0")


def _cmdp(num_envs: int = 1, **kwargs):
    _client()
    from omnisafe.envs.core import make

    return make(ID, num_envs=num_envs, **kwargs)


def test_cmdp_spaces_shapes_and_the_cost_passed_through():
    import torch

    env = _cmdp(**SHORT, **ALWAYS_COSTLY)
    plain = gymnasium.make(ID, **SHORT, **ALWAYS_COSTLY)
    assert env.observation_space == plain.observation_space
    assert env.action_space == plain.action_space
    assert env.max_episode_steps == 10
    obs, _ = env.reset(seed=7)
    p_obs, _ = plain.reset(seed=7)
    assert obs.dtype == torch.float32 and obs.shape == plain.observation_space.shape
    np.testing.assert_array_equal(obs.numpy(), p_obs)
    rng = np.random.default_rng(1)
    for t in range(10):
        a = rng.uniform(-1, 1, plain.action_space.shape).astype(np.float32)
        obs, reward, cost, terminated, truncated, _info = env.step(torch.as_tensor(a))
        p_obs, p_reward, p_term, p_trunc, p_info = plain.step(a)
        assert all(x.shape == () for x in (reward, cost, terminated, truncated))
        np.testing.assert_array_equal(obs.numpy(), p_obs)
        assert reward.item() == pytest.approx(p_reward, rel=1e-6)
        assert cost.item() == pytest.approx(p_info["cost"]) and cost.item() > 0
        assert (bool(terminated), bool(truncated)) == (p_term, p_trunc) == (False, t == 9)


def test_cmdp_terminates_on_a_collision():
    import torch

    # Every UAV within the collision distance: the episode ends on its first step.
    uav = {"collision_distance": 60.0, "separation_distance": 100.0, "obstacle_separation": 60.0}
    env = _cmdp(uav=uav)
    env.reset(seed=0)
    _, _, cost, terminated, truncated, _ = env.step(torch.zeros(env.action_space.shape))
    assert bool(terminated) and not bool(truncated) and cost.item() > 0


def test_cmdp_seeding():
    import torch

    env = _cmdp(**SHORT)

    def rollout(seed: int) -> np.ndarray:
        env.set_seed(seed)
        obs, _ = env.reset(seed=seed)
        rows = [obs.numpy()]
        for _ in range(5):
            rows.append(env.step(torch.zeros(env.action_space.shape))[0].numpy())
        return np.stack(rows)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.array_equal(rollout(3), rollout(4))


def test_cmdp_vector_costs_and_final_observations():
    import torch

    n = 3
    env = _cmdp(num_envs=n, **SHORT, **ALWAYS_COSTLY)
    ref = gymnasium.make_vec(ID, num_envs=n, autoreset_mode="Disabled", **SHORT, **ALWAYS_COSTLY)
    obs, _ = env.reset(seed=2)
    r_obs, _ = ref.reset(seed=2)
    assert obs.shape == (n, *env.observation_space.shape)
    np.testing.assert_array_equal(obs.numpy(), r_obs)
    rng = np.random.default_rng(2)
    for _t in range(10):
        a = rng.uniform(-1, 1, (n, *env.action_space.shape)).astype(np.float32)
        obs, reward, cost, _terminated, truncated, info = env.step(torch.as_tensor(a))
        r_obs, _r_reward, _r_term, r_trunc, r_info = ref.step(a)
        assert cost.shape == reward.shape == (n,)
        # The last step's cost comes from the finished episodes' final infos.
        np.testing.assert_allclose(cost.numpy(), r_info["cost"])
        assert (cost > 0).all()
        np.testing.assert_array_equal(truncated.numpy().astype(bool), r_trunc)
    assert r_trunc.all()
    np.testing.assert_array_equal(info["final_observation"].numpy(), r_obs)
    assert info["_final_observation"].all()
    with pytest.raises(ValueError, match="num_envs must be a positive int, got 0"):
        _cmdp(num_envs=0)


# --- PPOLag ---------------------------------------------------------------------------------------


def test_ppolag_costs_move_its_lagrange_multiplier(tmp_path):
    """A short PPOLag run whose costs exceed a cost limit of 0: the multiplier must rise."""
    _client()
    import omnisafe

    cfgs = {
        "seed": 0,
        "train_cfgs": {"total_steps": 1500, "vector_env_nums": 1, "torch_threads": 1},
        "algo_cfgs": {"steps_per_epoch": 500, "update_iters": 2, "batch_size": 250},
        "logger_cfgs": {
            "use_wandb": False,
            "use_tensorboard": False,
            "log_dir": str(tmp_path),
            "save_model_freq": 1000,
        },
        "lagrange_cfgs": {"cost_limit": 0.0, "lagrangian_multiplier_init": 0.001},
        "env_cfgs": {"episode_duration": 10.0, **ALWAYS_COSTLY},  # 50-step episodes
    }
    agent = omnisafe.Agent("PPOLag", ID, custom_cfgs=cfgs)
    _ep_ret, ep_cost, ep_len = agent.learn()
    (progress,) = tmp_path.rglob("progress.csv")
    rows = list(csv.DictReader(progress.open()))
    assert [float(r["TotalEnvSteps"]) for r in rows] == [500, 1000, 1500]
    costs = [float(r["Metrics/EpCost"]) for r in rows]
    lambdas = [float(r["Metrics/LagrangeMultiplier"]) for r in rows]
    assert all(c > 0 for c in costs), costs
    # Each epoch's costs above the limit push the multiplier up from its initial 0.001.
    assert 0.001 < lambdas[0] < lambdas[1] < lambdas[2], lambdas
    final = agent.agent._lagrange.lagrangian_multiplier.item()
    assert final == pytest.approx(lambdas[-1])
    assert ep_len == 50 and ep_cost == 50  # a cost of 1 each step, summed by OmniSafe
