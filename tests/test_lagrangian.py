"""The PID Lagrange multiplier (uasep_env.training.lagrangian) and its SB3 callback."""

import csv
import itertools
import json
import math
import re

import numpy as np
import pytest

from uasep_env.training.lagrangian import PIDLagrangian

# --------------------------------------------------------------------- the multiplier


def _run(pid: PIDLagrangian, costs) -> list[float]:
    return [pid.update(c) for c in costs]


def test_multiplier_rises_above_the_limit_and_falls_below():
    for gains in ({"ki": 0.1}, {"kp": 0.5, "ki": 0.1, "kd": 0.2, "ema_p": 0.5, "ema_d": 0.5}):
        pid = PIDLagrangian(cost_limit=2.0, **gains)
        up = _run(pid, [5.0] * 20)  # above the limit: rises
        assert up[0] > 0.0
        assert all(b > a for a, b in itertools.pairwise(up[2:])), (gains, up)
        down = _run(pid, [0.0] * 200)  # below: falls, to 0 and no lower
        assert all(b <= a for a, b in itertools.pairwise(down[3:])), (gains, down)
        assert down[-1] == 0.0 and min(down) >= 0.0
        assert _run(pid, [2.0] * 5) == [0.0] * 5  # at the limit from 0: stays


def test_plain_gradient_ascent_is_the_special_case():
    rng = np.random.default_rng(0)
    costs = rng.uniform(0.0, 6.0, 50)
    pid = PIDLagrangian(cost_limit=3.0, ki=0.05, init=0.4)
    lam = 0.4
    for c, got in zip(costs, _run(pid, costs), strict=True):
        lam = max(0.0, lam + 0.05 * (c - 3.0))
        assert got == pytest.approx(lam, abs=1e-12)


def test_proportional_and_derivative_terms():
    # P alone: the multiplier is Kp times the excess, at once, and 0 below the limit.
    pid = PIDLagrangian(cost_limit=1.0, kp=2.0, ki=0.0)
    assert _run(pid, [3.0, 1.5, 0.5]) == pytest.approx([4.0, 1.0, 0.0])
    # D alone reacts to a rising cost only (its positive part), not to a high steady one.
    pid = PIDLagrangian(cost_limit=100.0, ki=0.0, kd=1.0)
    assert _run(pid, [1.0, 4.0, 4.0, 2.0]) == pytest.approx([0.0, 3.0, 0.0, 0.0])
    # The bound.
    pid = PIDLagrangian(cost_limit=0.0, ki=10.0, max_multiplier=5.0)
    assert _run(pid, [1.0, 1.0]) == [5.0, 5.0]


def test_state_round_trips():
    a = PIDLagrangian(cost_limit=1.0, kp=0.3, ki=0.2, kd=0.1, ema_p=0.5, ema_d=0.5, delay=3)
    _run(a, [2.0, 5.0, 0.5, 3.0])
    b = PIDLagrangian(cost_limit=1.0, kp=0.3, ki=0.2, kd=0.1, ema_p=0.5, ema_d=0.5, delay=3)
    b.load_state_dict(a.state_dict())
    assert _run(a, [4.0, 0.0, 2.0]) == _run(b, [4.0, 0.0, 2.0])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cost_limit": -1.0}, r"cost_limit=-1\.0: must be >= 0"),
        ({"cost_limit": math.nan}, r"cost_limit=nan"),
        ({"cost_limit": 1.0, "ki": -0.1}, r"ki=-0\.1"),
        ({"cost_limit": 1.0, "ema_p": 1.0}, r"ema_p=1\.0"),
        ({"cost_limit": 1.0, "delay": 0}, r"delay=0"),
        ({"cost_limit": 1.0, "max_multiplier": 0.0}, r"max_multiplier=0\.0"),
    ],
)
def test_bad_values_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PIDLagrangian(**kwargs)


def test_bad_cost_measurement_is_named():
    pid = PIDLagrangian(cost_limit=1.0)
    with pytest.raises(ValueError, match=r"episode_cost=-2"):
        pid.update(-2)


# --------------------------------------------------------------------- SB3


def _ppo(venv, seed=0):
    from stable_baselines3 import PPO

    batch = 16 * venv.num_envs
    return PPO("MlpPolicy", venv, n_steps=16, batch_size=batch, n_epochs=1, seed=seed,
               device="cpu", policy_kwargs={"net_arch": [8]})  # fmt: skip


# Three UAVs 5 m apart (inside the 8 m separation): every step costs each of them.
CLOSE = {"scenario": "crossing", "noise": False, "episode_duration": 4.0,
         "formation": ((0.0, 0.0, 0.0), (5.0, 0.0, 0.0), (10.0, 0.0, 0.0))}  # fmt: skip


@pytest.mark.parametrize(("limit", "init"), [(0.5, 0.0), (1e6, 5.0)])
def test_sb3_callback_moves_the_multiplier_from_the_env_cost(tmp_path, limit, init):
    pytest.importorskip("stable_baselines3")
    import csv

    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.training.sb3_lagrangian import LagrangianCallback

    class EpisodeCosts(BaseCallback):  # the env's costs summed per episode, independently
        def _on_training_start(self):
            self.running, self.done = np.zeros(3), []

        def _on_step(self):
            self.running += [i["cost"] for i in self.locals["infos"]]
            for k in np.flatnonzero(self.locals["dones"]):
                self.done.append(self.running[k])
                self.running[k] = 0.0
            return True

    venv = UAVSharedVecEnv(n_envs=1, seed=0, **{**CLOSE, "episode_duration": 2.0})  # 10 steps
    pid = PIDLagrangian(cost_limit=limit, ki=0.05, init=init)
    cb, ref = LagrangianCallback(pid, csv_path=tmp_path / "cost.csv"), EpisodeCosts()
    _ppo(venv).learn(total_timesteps=48 * 4, callback=CallbackList([cb, ref]))  # 4 rollouts
    assert list(cb.window) == ref.done and cb.episodes == len(ref.done) >= 6
    with (tmp_path / "cost.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 and pid.updates == 4  # an episode ended in every rollout
    lam = init
    for row in rows:  # gradient ascent on the rollouts' mean episode cost
        cost = float(row["episode_cost_mean"])
        assert cost >= 1.0  # the first step of an episode is inside the separation
        lam = max(0.0, lam + 0.05 * (cost - limit))
        assert float(row["multiplier"]) == pytest.approx(lam, rel=1e-12)
        assert float(row["cost_limit"]) == limit
    if limit < 1.0:
        assert pid.multiplier > 4 * 0.05 * (1.0 - limit)  # rose at every update
    else:
        assert pid.multiplier < init - 1.0  # fell at every update


def test_sb3_callback_shapes_the_stored_reward():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.training.sb3_lagrangian import LagrangianCallback

    class Record(BaseCallback):
        def __init__(self):
            super().__init__()
            self.rows = []

        def _on_step(self):
            self.rows.append(self.locals["rewards"].copy())
            return True

    before, after = Record(), Record()
    lam = 1.5
    pid = PIDLagrangian(cost_limit=0.0, ki=0.0, init=lam)  # a constant multiplier
    cost = Record()
    cost._on_step = lambda: cost.rows.append([i["cost"] for i in cost.locals["infos"]]) or True
    venv = UAVSharedVecEnv(n_envs=1, seed=0, **CLOSE)
    model = _ppo(venv)
    model.learn(16 * 3, callback=CallbackList([before, cost, LagrangianCallback(pid), after]))
    r, c, shaped = (np.array(x.rows) for x in (before, cost, after))
    assert (c > 0).mean() > 0.5  # mostly inside the separation: the shaping matters
    np.testing.assert_allclose(shaped, (r - lam * c) / (1 + lam), rtol=1e-6)
    # What PPO stored is the shaped reward (the last step of the last rollout, no timeout).
    np.testing.assert_array_equal(model.rollout_buffer.rewards[-1], shaped[-1])


def test_a_cost_the_env_does_not_report_is_named():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from uasep_env.envs.gym_env import FormationEnv
    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.training.sb3_lagrangian import LagrangianCallback

    with pytest.raises(ValueError, match="'colision'"):
        LagrangianCallback(PIDLagrangian(cost_limit=1.0), cost="colision")
    # The Gymnasium view reports flat cost_<term> keys, not cost_terms: named, not a KeyError.
    venv = DummyVecEnv([lambda: FormationEnv(**CLOSE)])
    cb = LagrangianCallback(PIDLagrangian(cost_limit=1.0), cost="separation_uav")
    with pytest.raises(ValueError, match=r"does not report the cost 'separation_uav'"):
        _ppo(venv).learn(32, callback=cb)
    norm = VecNormalize(UAVSharedVecEnv(n_envs=1, **CLOSE), norm_reward=True)
    with pytest.raises(ValueError, match="norm_reward"):
        _ppo(norm).learn(32, callback=LagrangianCallback(PIDLagrangian(cost_limit=1.0)))


# --------------------------------------------------------------------- the recipe


@pytest.fixture
def recipe():
    from uasep_env.training import ppo_lagrangian

    return ppo_lagrangian


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--cost-limit", "-1"], r"--cost-limit: must be a number >= 0, .*got '-1'"),
        (["--cost-limit", "lots"], r"--cost-limit: .*got 'lots'"),
        (["--cost", "colision"], r"--cost: cost 'colision' is not reported"),
        (["--pid-ki", "-0.5"], r"--pid-ki: must be a number >= 0, got '-0.5'"),
        (["--norm-reward"], "--norm-reward"),
        (["--budget-episodes", "0"], "--budget-episodes"),
    ],
)
def test_recipe_bad_options_are_named(recipe, argv, match, capsys):
    with pytest.raises(SystemExit) as exc:
        recipe.parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert re.search(match, err) and len(err.strip().splitlines()) == 1, err


def test_recipe_defaults(recipe, capsys):
    from uasep_env.training import ppo_shared

    args = recipe.parse_args([])
    assert args.cost == "cost" and args.cost_limit == "apf"
    assert args.action_mode == "direct"
    cfg = ppo_shared.make_env_config(args)
    assert cfg.reward == cfg.reward.task()
    residual = recipe.parse_args([], recipe.RESIDUAL_LAGRANGIAN_DEFAULTS)
    assert residual.action_mode == "residual_apf" and residual.critic_warmup > 0
    assert ppo_shared.make_env_config(residual).reward == cfg.reward.task()
    # The shared training parser checks --config values up front, in one line.
    with pytest.raises(SystemExit):
        recipe.parse_args(["--config", "cost.separation_obstacle=-2"])
    assert "cost.separation_obstacle=-2: must be >= 0" in capsys.readouterr().err


TINY = [
    "--scenario", "collision_head_on", "--n-uavs", "2", "--episode-duration", "20",
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--hidden", "16",
    "--checkpoint-every", "256", "--eval-episodes", "1", "--no-progress", "--cost-limit", "0.5",
    "--pid-ki", "0.5", "--multiplier-init", "0.25",
]  # fmt: skip


def _cost_rows(out):
    with (out / "cost_progress.csv").open() as f:
        return list(csv.DictReader(f))


def test_recipe_resumes_the_multiplier_and_its_cost_log(recipe, tmp_path, capsys):
    """A resumed run continues the multiplier of its checkpoint, not --multiplier-init."""
    out = tmp_path / "run"
    recipe.main([*TINY, "--total-timesteps", "700", "--out-dir", str(out)])
    rows = _cost_rows(out)
    assert [int(r["agent_steps"]) for r in rows] == [128 * k for k in range(1, 7)]
    assert int(rows[-1]["agent_episodes"]) > 0  # each UAV's episodes, named so
    # The log: the rounding of the budget said once, then one line a checkpoint with the
    # summary figures (never the 200-episode windows), one for the validation.
    log = capsys.readouterr().out.splitlines()
    notice = "--total-timesteps 700 rounded up to 768: whole rollouts of 128 agent-steps"
    assert sum(notice in line for line in log) == 1
    ticks = [line for line in log if line.startswith("step_")]
    assert [t.split(":")[0] for t in ticks] == ["step_256", "step_512", "step_768"]
    assert all("episode cost" in t and "(limit 0.5), λ " in t for t in ticks), ticks
    assert sum(line.startswith("validation on 1 encounters") for line in log) == 1
    assert all(len(line) < 300 and "[" not in line for line in log), log
    # On a collision course the cost exceeds the limit: the multiplier moved off its start.
    assert any(float(r["multiplier"]) != 0.25 for r in rows)
    ckpt = out / "checkpoints" / "step_256"
    saved = json.loads((ckpt / "state.json").read_text())["lagrangian"]["state"]
    from uasep_env.training.sb3_lagrangian import LagrangianCallback

    expect = LagrangianCallback(recipe.make_lagrangian(recipe.parse_args(TINY), 0.5))
    expect.load_state_dict(saved)
    seen = {}
    real = LagrangianCallback.load_state_dict

    def spy(self, state, **kwargs):  # running=: the episodes' costs continue too
        real(self, state, **kwargs)
        seen.update(self.state_dict())

    LagrangianCallback.load_state_dict = spy
    try:
        summary = recipe.main([*TINY, "--total-timesteps", "512", "--out-dir", str(out),
                               "--resume", str(ckpt), "--multiplier-init", "7"])  # fmt: skip
    finally:
        LagrangianCallback.load_state_dict = real
    assert seen == expect.state_dict() and seen["multiplier"] != 7.0
    rows = _cost_rows(out)
    # The rows of the abandoned continuation are gone; the resumed run's follow on.
    steps = [int(r["agent_steps"]) for r in rows]
    assert steps[:2] == [128, 256] and steps == sorted(steps) and len(steps) == 4
    lag = summary["training"]["lagrangian"]
    assert lag["cost_limit"] == 0.5 and lag["multiplier"] == float(rows[-1]["multiplier"])
    assert (out / "budget.json").exists() and (out / "cost_curves.png").exists()


def test_a_checkpoint_is_one_line_of_figures_not_its_windows():
    from uasep_env.training.curves import checkpoint_line

    window = [(1.0, 0.0, 1.0, 20.0, 1000.0)] * 200
    info = {"agent_steps": 2_000_000, "wall_s": 600.0, "episodes": 321, "return_mean": 812.25,
            "collision_rate": 0.01, "loss_of_separation_rate": 0.25, "max_deviation_mean": 20.0}
    ppo = {"lagrangian": {"cost_limit": 0.5, "multiplier": 1.843,
                          "state": {"episode_cost_window": 0.857, "window": [1.0] * 200}}}
    mappo = {"lagrangian": {"cost_limit": 0.5, "multiplier": 1.843,
                            "episode_cost_window": 0.857, "window": [1.0] * 200}}  # fmt: skip
    for lag in (ppo, mappo):
        line = checkpoint_line("step_2000000", {**info, **lag}, window)
        assert line == (
            "step_2000000: 2,000,000 agent-steps, 10.0 min, 321 episodes; the last 200: "
            "return 812.2, collisions 1.0%, loss of separation 25.0%, deviation 20.0 m; "
            "episode cost 0.857 (limit 0.5), λ 1.84"
        )


def test_rewinding_an_older_cost_log_names_its_agent_episodes(tmp_path):
    """``cost_progress.csv`` once called its agent-episodes ``episodes``: resume renames it."""
    pytest.importorskip("stable_baselines3")
    from uasep_env.training.rundir import read_progress, rewind_csv
    from uasep_env.training.sb3_lagrangian import COST_FIELDS

    path = tmp_path / "cost_progress.csv"
    path.write_text(
        "agent_steps,episodes,episode_cost_mean,episode_cost_window,cost_limit,multiplier\n"
        "128,4,1.0,1.0,0.5,1.2\n256,8,0.5,0.75,0.5,1.3\n384,12,0.0,0.5,0.5,1.1\n"
    )
    rewind_csv(path, COST_FIELDS, 256)
    rows = read_progress(path)
    assert tuple(rows[0]) == COST_FIELDS and "agent_episodes" in COST_FIELDS
    assert [r["agent_episodes"] for r in rows] == ["4", "8"]
