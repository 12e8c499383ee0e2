"""MAPPO-Lagrangian (``uasep-train mappo_lagrangian``): outputs, resume, the advantage, flags."""

import csv
import json
import math

import numpy as np
import pytest
from conftest import same_bits

from uasep_env.training import mappo, mappo_lagrangian
from uasep_env.training.cli import main as uasep_train

#: A tiny run: 2 environments x 3 UAVs x 16 steps = 96 agent-steps per rollout.
TINY = ["--n-envs", "2", "--n-steps", "16", "--batch-size", "16", "--episode-duration", "4",
        "--hidden", "16,16", "--no-progress", "--eval-episodes", "1"]  # fmt: skip


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """As the recipes' ``--torch-threads 1`` (``main`` sets it; these call ``train``)."""
    try:
        import torch
    except ImportError:
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# --------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--cost-limit", "-1"], "--cost-limit: must be a number >= 0, 'apf' or 'apf-rate', "),
        (["--cost-limit", "lots"], "argument --cost-limit: must be a number >= 0"),
        (["--pid-kp", "-0.1"], "argument --pid-kp: must be a number >= 0, got '-0.1'"),
        (["--pid-ki", "-1"], "argument --pid-ki: must be a number >= 0, got '-1'"),
        (["--pid-kd", "nan"], "argument --pid-kd: must be a finite number, got 'nan'"),
        (["--pid-ema", "1"], "argument --pid-ema: must be a number in [0, 1), got '1'"),
        (["--cost", "nope"], "argument --cost: cost 'nope' is not reported by the environment"),
        (["--norm-reward"], "argument --norm-reward: rescales the reward but not the cost"),
        (["--budget-episodes", "0"], "argument --budget-episodes: must be an integer >= 1"),
    ],
)
def test_bad_options_are_named(argv, named, capsys, tmp_path):
    assert uasep_train(["mappo_lagrangian", *argv, "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and named in err, err
    assert err.startswith("uasep-train mappo_lagrangian: error:")
    assert not any(tmp_path.iterdir())  # refused before anything ran


def test_defaults_task_reward_and_registration():
    from uasep_env.training import RECIPES

    assert RECIPES["mappo_lagrangian"][0] == mappo_lagrangian.__name__
    args = mappo_lagrangian.parse_args([])
    assert (args.cost, args.cost_limit, args.out_dir) == ("cost", "apf", "runs/mappo_lagrangian")
    cfg = mappo.ppo_shared.make_env_config(args)
    assert cfg.reward == cfg.reward.task()
    # The shared flags keep mappo's defaults.
    plain = mappo.Args()
    assert (args.n_envs, args.value_loss_scale) == (plain.n_envs, plain.value_loss_scale)


# --------------------------------------------------------------------- the advantage


def test_combined_advantage():
    torch = pytest.importorskip("torch")
    gen = torch.Generator().manual_seed(0)
    a_r, a_c = torch.randn(64, 1, generator=gen), torch.randn(64, 1, generator=gen)
    # lambda = 0: the reward's advantage, bit for bit.
    assert torch.equal(mappo_lagrangian.combine_advantages(a_r, a_c, 0.0), a_r)
    # lambda > 0: two actions of equal reward advantage, the one of lower cost is preferred,
    # more so as lambda grows; the scale stays within A_r's and A_c's.
    r, c = np.array([1.0, 1.0]), np.array([0.5, -0.5])
    gaps = []
    for lam in (0.1, 1.0, 10.0):
        out = mappo_lagrangian.combine_advantages(r, c, lam)
        assert out[1] > out[0]
        np.testing.assert_allclose(out, (r - lam * c) / (1 + lam))
        gaps.append(out[1] - out[0])
    assert gaps == sorted(gaps)
    big = mappo_lagrangian.combine_advantages(r, c, 1e9)
    np.testing.assert_allclose(big, -c, atol=1e-8)


def _tiny(tmp_path, name, extra, module=mappo_lagrangian):
    args = module.parse_args([*TINY, "--out-dir", str(tmp_path / name), *extra])
    out = tmp_path / name
    out.mkdir()
    return args, mappo.ppo_shared.make_env_config(args), out


def test_lambda_zero_is_plain_mappo_and_a_multiplier_changes_the_actor(tmp_path):
    pytest.importorskip("skrl")
    torch = pytest.importorskip("torch")
    steps = ["--total-timesteps", "192", "--checkpoint-every", "1000"]  # two updates
    args, cfg, out = _tiny(tmp_path, "plain", [*steps, "--config", "reward=task"], mappo)
    plain, _, _ = mappo.train(args, cfg, out)
    fixed = [*steps, "--pid-ki", "0", "--pid-kp", "0", "--cost-limit", "0"]
    args, cfg, out = _tiny(tmp_path, "lag0", [*fixed, "--multiplier-init", "0"])
    lag0, _, _, hooks = mappo_lagrangian.train(args, cfg, out, 0.0)
    args, cfg, out = _tiny(tmp_path, "lag5", [*fixed, "--multiplier-init", "5"])
    lag5, _, _, _ = mappo_lagrangian.train(args, cfg, out, 0.0)
    uid = "uav_0"
    for role in ("policy", "value"):
        a = plain.models[uid][role].state_dict()
        b = lag0.models[uid][role].state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), role  # weight for weight
    assert hooks.lagrangian.multiplier == 0.0 and hooks.lagrangian.updates == 1  # 1st: no ends
    actor, actor5 = plain.policies[uid].state_dict(), lag5.policies[uid].state_dict()
    assert not all(torch.equal(actor[k], actor5[k]) for k in actor)
    # The cost critic learnt (its targets: the costs' returns), from its own stream.
    init = mappo.build(args, cfg, mappo_lagrangian.agent_class())[2].cost_values[uid]
    trained = lag0.cost_values[uid]
    assert not all(
        torch.equal(p, q) for p, q in zip(init.parameters(), trained.parameters(), strict=True)
    )


# --------------------------------------------------------------------- a run and its files


def _rows(path):
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_tiny_run_writes_policy_cost_progress_and_validation(tmp_path):
    pytest.importorskip("skrl")
    pytest.importorskip("torch")
    from uasep_env.policies import load_policy
    from uasep_env.training.sb3_lagrangian import COST_FIELDS

    out = tmp_path / "run"
    argv = [*TINY, "--out-dir", str(out), "--total-timesteps", "200", "--checkpoint-every",
            "150", "--cost-limit", "apf", "--budget-episodes", "2"]  # fmt: skip
    summary = mappo_lagrangian.main(argv)
    budget = json.loads((out / "budget.json").read_text())
    assert budget["episodes"] == 2 and budget["cost_limit"] == budget["parity_limit"]
    rows = _rows(out / "cost_progress.csv")
    assert tuple(rows[0]) == COST_FIELDS
    assert [int(r["agent_steps"]) for r in rows] == [96, 192, 288]
    assert all(float(r["cost_limit"]) == budget["cost_limit"] for r in rows)
    assert (out / "cost_curves.png").stat().st_size > 1000
    lag = json.loads((out / "validation.json").read_text())["training"]["lagrangian"]
    assert lag == summary["training"]["lagrangian"]
    assert lag["cost"] == "cost" and lag["updates"] >= 1
    assert lag["multiplier"] == float(rows[-1]["multiplier"])
    assert lag["cost_limit"] == budget["cost_limit"]
    policy = load_policy(out / "policy.zip")
    assert policy.meta.algorithm == "MAPPO"  # the actor only, as plain MAPPO's
    state = json.loads((out / "checkpoints" / "latest" / "state.json").read_text())
    assert state["lagrangian"]["multiplier"] == lag["multiplier"]
    assert isinstance(state["lagrangian"]["window"], list)


def test_resume_restores_cost_critic_and_multiplier(tmp_path):
    pytest.importorskip("skrl")
    torch = pytest.importorskip("torch")
    from uasep_env.training.sb3_lagrangian import COST_FIELDS

    # A multiplier that moves (limit 1 above the tiny runs' costs: it falls from 0.7).
    extra = ["--total-timesteps", "200", "--checkpoint-every", "150", "--cost-limit", "1",
             "--multiplier-init", "0.7", "--pid-ki", "0.2", "--pid-kp", "0.5"]  # fmt: skip
    args, cfg, out = _tiny(tmp_path, "run", extra)
    agent, _, _, hooks = mappo_lagrangian.train(args, cfg, out, 1.0)
    latest = out / "checkpoints" / "latest"
    # Everything the cost critic needs comes back bit for bit.
    venv, view, fresh = mappo.build(args, cfg, mappo_lagrangian.agent_class())
    resumed = mappo.load_checkpoint(fresh, venv, latest)
    for uid in agent.possible_agents:
        a, b = agent.cost_values[uid].state_dict(), fresh.cost_values[uid].state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a), uid
        for name in ("cost_optimizers", "_cost_value_preprocessor"):
            a = getattr(agent, name)[uid].state_dict()
            b = getattr(fresh, name)[uid].state_dict()
            assert same_bits(a, b), (uid, name)  # tensors and Adam's moments alike
    assert torch.equal(
        agent._cost_sampler.generator.get_state(), fresh._cost_sampler.generator.get_state()
    )
    again = mappo_lagrangian.LagrangianHooks(args, 1.0)
    again.start(fresh, view, tmp_path, resumed)
    again.close()
    assert again.tracker.state_dict() == hooks.tracker.state_dict()
    assert fresh.multiplier == hooks.lagrangian.multiplier != 0.7
    # --resume from the first checkpoint (at the end of the rollout where 150 falls, 192):
    # cost_progress.csv is rewound to it and continues, and the multiplier continues from
    # the checkpoint's.
    first = json.loads((out / "checkpoints" / "step_192" / "state.json").read_text())
    args.resume, args.total_timesteps = str(out / "checkpoints" / "step_192"), 300
    _, _, info, resumed_hooks = mappo_lagrangian.train(args, cfg, out, 1.0)
    rows = _rows(out / "cost_progress.csv")
    assert tuple(rows[0]) == COST_FIELDS
    assert [int(r["agent_steps"]) for r in rows] == [96, 192, 288, 384]
    # The rows after the checkpoint's (192, kept by the rewind) are the resumed run's updates.
    moved = sum(not math.isnan(float(r["episode_cost_mean"])) for r in rows[2:])
    assert moved >= 1
    assert info["lagrangian"]["updates"] == first["lagrangian"]["updates"] + moved
    assert resumed_hooks.lagrangian.updates == info["lagrangian"]["updates"]


# --------------------------------------------------------------------- seeds.py


def test_seed_driver_targets(monkeypatch):
    from conftest import ROOT

    monkeypatch.syspath_prepend(str(ROOT / "train"))
    import seeds

    assert seeds.RECIPES["mappo_lagrangian"] == "mappo_lagrangian.py"
    assert (ROOT / "train" / "mappo_lagrangian.py").exists()

    def rates(rate, dev):
        agg = {k: {"rate": rate, "ci_low": rate / 2, "ci_high": rate * 2 + 0.01, "n": 100}
               for k in ("episode.collision", "episode.loss_of_separation")}  # fmt: skip
        return {**agg, "episode.max_deviation": {"mean": dev}}

    def measured(dev_iqm, half_width=1.0):
        per_seed = {"apf": rates(0.02, 40.0), "seed_0": rates(0.02, 30.0)}
        agg = {"episode.max_deviation": {"iqm": dev_iqm, "ci_low": dev_iqm - half_width,
                                         "ci_high": dev_iqm + half_width,
                                         "apf_iqm": 40.0}}  # fmt: skip
        return {t: v for t, _, v in seeds.targets("mappo_lagrangian", per_seed, agg)}

    met = measured(35.0)
    assert [t.split(":")[0] for t in met] == [
        "collision", "loss_of_separation", "mean max deviation no larger than the APF's (keeps "
        "the formation; IQM over seeds x families, the APF through the same statistic)"
    ]  # fmt: skip
    assert list(met.values()) == ["met (100 vs 100 episodes)"] * 2 + ["met"]
    assert list(measured(45.0).values())[2] == "not met"  # wider than the APF: not met
    # An interval straddling the APF's deviation decides nothing, whatever the point says.
    assert list(measured(35.0, half_width=10.0).values())[2] == "not shown"


def test_resume_from_a_plain_mappo_checkpoint_is_refused(tmp_path, capsys):
    from uasep_env.training.rundir import CHECKPOINT_FILES

    ckpt = tmp_path / "mappo" / "checkpoints" / "step_96"
    ckpt.mkdir(parents=True)
    for name in CHECKPOINT_FILES:
        (ckpt / name).write_text('{"agent_steps": 96}' if name == "state.json" else "")
    argv = ["mappo_lagrangian", "--resume", str(ckpt), "--out-dir", str(tmp_path / "mappo")]
    assert uasep_train(argv) == 1
    assert "not a MAPPO-Lagrangian checkpoint" in capsys.readouterr().err


def test_resume_under_the_other_value_norm_is_refused(tmp_path, capsys):
    # skrl saves the value preprocessor's statistics under --value-norm only.
    from uasep_env.training.rundir import CHECKPOINT_FILES

    ckpt = tmp_path / "run" / "checkpoints" / "step_96"
    ckpt.mkdir(parents=True)
    state = {"agent_steps": 96, "lagrangian": {}, "args": {"value_norm": True}}
    for name in CHECKPOINT_FILES:
        (ckpt / name).write_text(json.dumps(state) if name == "state.json" else "")
    argv = ["mappo_lagrangian", "--resume", str(ckpt), "--out-dir", str(tmp_path / "run"),
            "--no-value-norm"]  # fmt: skip
    assert uasep_train(argv) == 1
    assert "a checkpoint of --value-norm; resume it with --value-norm" in capsys.readouterr().err
