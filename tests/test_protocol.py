"""The benchmark protocol: fixed-K checkpoints at any size, the scaling script, seeds, MAPPO."""

import itertools
import json
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.evaluation import evaluate
from uasep_env.interface.observation import ObservationLayout
from uasep_env.metrics.statistics import iqm, stratified_bootstrap_iqm
from uasep_env.policies import CheckpointError, load_policy
from uasep_env.policies.learned import PolicyCheckpoint, save_policy
from uasep_env.rollout import run_episodes
from uasep_env.scenarios import HELD_OUT_SEEDS, SEED_RANGES

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "baselines"))
sys.path.insert(0, str(ROOT / "train"))

import scaling  # noqa: E402
import seeds  # noqa: E402

SHIPPED = ROOT / "baselines" / "checkpoints" / "ppo_residual_apf.zip"


def _checkpoint(path, cfg, seed=0, info=None):
    rng = np.random.default_rng(seed)
    dim = ObservationLayout.from_config(cfg).dim
    sizes = [dim, 8, 3]
    weights = [
        (rng.normal(0, 0.3, (o, i)).astype(np.float32), np.zeros(o, np.float32))
        for i, o in itertools.pairwise(sizes)
    ]
    meta = PolicyCheckpoint(
        config=cfg.to_dict(), obs_dim=dim, activation="tanh", hidden=(8,), obs_norm=False,
        info=info or {},
    )  # fmt: skip
    return save_policy(path, meta, weights)


def test_no_two_seed_ranges_meet():
    ranges = list(SEED_RANGES.items())
    assert scaling.SCALING_SEEDS is SEED_RANGES["scaling"]
    for i, (name, bank) in enumerate(ranges):
        for other_name, other in ranges[i + 1 :]:
            assert set(bank).isdisjoint(other), (name, other_name)


def test_a_3_uav_checkpoint_flies_8_uavs_and_more_obstacles():
    # The shipped checkpoint (K = 2 UAVs, 1 obstacle) zero-shot on 8 UAVs and 2 obstacles.
    entry = scaling.parse_policies([str(SHIPPED)])[0]
    assert entry.trained == (3, 1) and entry.layout == (2, 1)
    assert scaling.parse_policies([f"mine={SHIPPED}"])[0].label == "mine"
    by_name = scaling.parse_policies(["ppo_residual_apf"])[0]
    assert by_name.kind == "checkpoint" and by_name.layout == (2, 1)
    cfg = scaling.cell_config(8, 2, entry=entry, episode_duration=20.0)
    policy = load_policy(SHIPPED, cfg)
    (ep,) = run_episodes(policy, cfg, [scaling.SCALING_SEEDS[0]])
    assert ep.record.uav_pos.shape[1] == 8 and ep.steps > 0
    assert np.isfinite(ep.record.uav_pos).all()


def test_fixed_k_recipe_config_and_mismatched_layout_is_named(tmp_path):
    ppo_shared = pytest.importorskip("ppo_shared")
    cfg = ppo_shared.make_env_config(ppo_shared.Args())
    assert (cfg.observation.k_uavs, cfg.observation.k_obstacles) == (2, 1)
    path = _checkpoint(tmp_path / "k.zip", cfg.replace(action={"mode": "direct"}))
    # Any size, any obstacle count, with the layout it was trained on:
    for n, m in ((3, 1), (16, 4)):
        load_policy(path, cfg.replace(n_uavs=n, n_obstacles=m, action={"mode": "direct"}))
    # Another layout is refused, naming what differs.
    with pytest.raises(CheckpointError, match="k_obstacles: the network reads the 1 nearest"):
        load_policy(path, cfg.replace(observation={"k_obstacles": 2}, action={"mode": "direct"}))
    with pytest.raises(CheckpointError, match="k_uavs: the network reads the 2 nearest UAVs"):
        load_policy(path, make_config(scenario="random", n_uavs=8))


def test_scaling_script_writes_tables_figure_and_targets(tmp_path, capsys):
    out = tmp_path / "sc"
    argv = [
        "--policy",
        f"apf,{SHIPPED},uasep_env.policies:ZeroPolicy",
        "--episodes",
        "2",
        "--uavs",
        "3,8",
        "--obstacles",
        "1,2",
        "--episode-duration",
        "15",
        "--held-out-episodes",
        "2",
        "--out",
        str(out),
    ]
    result = scaling.main(argv)
    assert {tuple(c) for c in result["cells"]} == {(3, 1), (8, 1), (3, 2)}
    assert len(result["rows"]) == 3 * 3
    zero_shot = {(r["n_uavs"], r["n_obstacles"]) for r in result["rows"] if r["zero_shot"]}
    assert zero_shot == {(8, 1), (3, 2)}
    text = out.with_suffix(".md").read_text()
    assert "## By formation size" in text and "## By obstacle count" in text
    assert "## Held-out bank" in text and len(result["held_out"]) == 3
    assert "ppo_residual_apf: collisions at 8 UAVs no worse than the APF's" in text
    data = json.loads(out.with_suffix(".json").read_text())
    assert data["rows"][0]["metrics"]["episode.collision"]["kind"] == "rate"
    assert out.with_suffix(".png").stat().st_size > 10_000
    with pytest.raises(SystemExit):  # no silent overwrite
        scaling.main(argv)
    out.with_suffix(".md").unlink()
    scaling.main(["--render", str(out.with_suffix(".json")), "--no-figure"])
    assert out.with_suffix(".md").read_text() == text
    capsys.readouterr()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--policy", "nope"], "--policy 'nope'"),
        (["--policy", "os:nope"], "cannot import"),
        (["--uavs", "3,65"], "n_uavs"),
        (["--episodes", "0"], "--episodes"),
        (["--policy", "=apf"], "empty label"),
    ],
)
def test_scaling_bad_input_is_named(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit):
        scaling.main([*argv, "--out", str(tmp_path / "x")])
    assert message in capsys.readouterr().err


def test_iqm_and_stratified_bootstrap():
    assert iqm(np.arange(1, 9)) == pytest.approx(4.5)
    point, lo, hi = stratified_bootstrap_iqm([[0.0, 1.0], [0.1, 1.1]])
    # Stratified: every resample keeps two scores of each column, so the IQM (the mean of
    # the middle two) lies in [0.5, 0.6]; unstratified draws would reach 0.05 or 1.05.
    assert point == pytest.approx(0.55)
    assert 0.5 - 1e-9 <= lo <= point <= hi <= 0.6 + 1e-9 and hi - lo > 0.0
    assert stratified_bootstrap_iqm([0.2]) == (0.2, 0.2, 0.2)
    with pytest.raises(ValueError, match="scores"):
        stratified_bootstrap_iqm([[np.nan, 1.0]])


def test_seed_driver_resumes_and_reports(tmp_path):
    out = tmp_path / "run"
    assert "--resume" not in seeds.train_command("shared", out, 0, [])
    latest = seeds.seed_dir(out, 1) / "checkpoints" / "latest"
    latest.mkdir(parents=True)
    cmd = seeds.train_command("shared", out, 1, ["--max-minutes", "1"])
    assert cmd[-2:] == ["--resume", str(latest)] and cmd[cmd.index("--seed") + 1] == "1000"
    stale = seeds.seed_dir(out, 2)
    stale.mkdir()
    (stale / "progress.csv").write_text("x")
    seeds.train_command("shared", out, 2, [])
    assert not stale.exists() and list(out.glob("seed_2.aborted-*"))
    done = seeds.seed_dir(out, 3)
    done.mkdir()
    (done / "policy.zip").write_text("")
    (done / "validation.json").write_text("{}")
    assert seeds.train_command("shared", out, 3, []) is None

    cfg = make_config(scenario="random", episode_duration=15.0)
    paths = [_checkpoint(tmp_path / f"c{k}.zip", cfg, seed=k) for k in range(2)]
    policies = {"apf": "apf", **{f"seed_{k}": str(p) for k, p in enumerate(paths)}}
    result = evaluate(policies, cfg, list(HELD_OUT_SEEDS)[:6])
    shipped = {"seed": 1, "validation": {}}
    text, data = seeds.report("shared", out, 2, result, "python train/seeds.py ...", shipped)
    assert data["recipe_args"] == {}  # no selected checkpoint to read them from
    # The recipe's options as seed 0's selected checkpoint records them, less the run's own.
    args = {"n_envs": 128, "learning_rate": 2.5e-4, "seed": 0, "out_dir": "runs/x/seed_0"}
    _checkpoint(seeds.seed_dir(out, 0) / "selected.zip", cfg, info={"args": args})
    data = seeds.report("shared", out, 2, result, "python train/seeds.py ...", shipped)[1]
    assert data["recipe_args"] == {"n_envs": 128, "learning_rate": 2.5e-4}
    assert "IQM across seeds" in text and "at most 5 % collisions" in text
    assert "Chosen to ship: seed 1's checkpoint" in text and data["shipped"]["seed"] == 1
    assert "apf, the same IQM over families" in text
    text, data = seeds.report("residual_apf", out, 2, result, "python ...", shipped)
    met = {t["target"].split(":")[0]: t for t in data["targets"]}
    assert "every seed as safe as the APF" in met["collision"]["target"]
    dev = data["across_seeds"]["episode.max_deviation"]
    assert (
        f"vs APF {dev['apf_iqm']:.1f} m"
        in met[
            "mean max deviation at least 25 % below "
            "the APF's (IQM over seeds x families, the "
            "APF through the same statistic)"
        ]["measured"]
    )
    agg = data["across_seeds"]["episode.max_deviation"]
    assert agg["ci_low"] <= agg["iqm"] <= agg["ci_high"]
    assert np.array(agg["scores"]).shape[0] == 2
    (seeds.seed_dir(out, 0)).mkdir(parents=True, exist_ok=True)
    (seeds.seed_dir(out, 0) / "progress.csv").write_text(
        "agent_steps,wall_s,episodes,return_mean,collision_rate,loss_of_separation_rate,"
        "max_deviation_mean,episode_length_mean\n100,1,3,5.0,0.1,0.2,30.0,50\n"
        "200,2,6,6.0,0.0,0.1,25.0,50\n"
    )
    assert seeds.plot_curves(out, 2, "shared").stat().st_size > 10_000


def test_mappo_recipe_trains_exports_and_flies(tmp_path):
    pytest.importorskip("skrl")
    torch = pytest.importorskip("torch")
    import mappo

    out = tmp_path / "mappo"
    argv = [
        "--out-dir",
        str(out),
        "--n-envs",
        "2",
        "--n-steps",
        "16",
        "--batch-size",
        "16",
        "--total-timesteps",
        "300",
        "--checkpoint-every",
        "150",
        "--eval-episodes",
        "1",
        "--episode-duration",
        "4",
        "--hidden",
        "16,16",
        "--no-progress",
    ]
    summary = mappo.main(argv)
    assert summary["training"]["agent_steps"] >= 300
    assert (out / "checkpoints" / "latest" / "state.pt").exists()
    assert (out / "progress.csv").read_text().count("\n") >= 2
    policy = load_policy(out / "policy.zip")
    assert policy.meta.algorithm == "MAPPO"
    # The numpy actor is the trained torch actor's mean.
    args = mappo.ppo_shared.parse_args(argv, mappo.Args())
    cfg = mappo.ppo_shared.make_env_config(args)
    venv, view, agent = mappo.build(args, cfg)
    assert agent.training  # skrl agents start in evaluation mode: no storage, no update
    initial = [q.detach().clone() for q in agent.policies["uav_0"].parameters()]
    mappo.load_checkpoint(agent, venv, out / "checkpoints" / "latest")
    trained = list(agent.policies["uav_0"].parameters())
    assert any(not torch.equal(a, b) for a, b in zip(initial, trained, strict=True))
    obs = np.random.default_rng(0).normal(size=(5, policy.meta.obs_dim)).astype(np.float32)
    actor = agent.policies["uav_0"]
    with torch.no_grad():
        mean = actor.net(torch.from_numpy(venv.normalize_obs(obs).astype(np.float32))).numpy()
    np.testing.assert_allclose(policy(obs), np.clip(mean, -1, 1), atol=1e-5)
    # The critic reads the agent-specific global state: global state and own observation.
    view.reset()  # (after the comparison: a reset updates the observation statistics)
    states = view.state()
    assert states["uav_0"].shape[-1] == view.base.core.state().shape[-1] + policy.meta.obs_dim
    assert not torch.equal(states["uav_0"], states["uav_1"])
    # And it flies 8 UAVs (fixed K).
    entry = scaling.parse_policies([str(out / "policy.zip")])[0]
    cfg8 = scaling.cell_config(8, 1, entry=entry, episode_duration=4.0)
    (ep,) = run_episodes(load_policy(out / "policy.zip", cfg8), cfg8, [scaling.SCALING_SEEDS[0]])
    assert ep.steps > 0


def _selection(run, rows, apf=(0.0, 0.0, 0.04, 35.0)):
    run.mkdir(parents=True, exist_ok=True)
    lines = ["policy,agent_steps,terminated,collision,loss_of_separation,max_deviation,safe"]
    for i, r in enumerate(rows):
        lines.append(f"{run}/checkpoints/step_{i}/policy.zip,{i}," + ",".join(map(str, r)) + ",")
    lines.append("apf,," + ",".join(map(str, apf)) + ",")
    (run / "selection.csv").write_text("\n".join(lines) + "\n")


def test_the_shipped_seed_is_chosen_on_validation_by_the_selection_rule(tmp_path):
    import select_checkpoint

    out = tmp_path / "run"
    # seed 0: safe at 33 m; seed 1: safe at 31 m (ships), and an unsafe 20 m checkpoint;
    # seed 2: never as safe as the APF.
    _selection(seeds.seed_dir(out, 0), [(0, 0, 0.03, 33.0), (0, 0, 0.05, 25.0)])
    _selection(seeds.seed_dir(out, 1), [(0, 0.01, 0.02, 20.0), (0, 0, 0.04, 31.0)])
    _selection(seeds.seed_dir(out, 2), [(0.02, 0.02, 0.1, 15.0)])
    shipped = seeds.ship(out, 3)
    assert shipped["seed"] == 1
    picks = shipped["validation"]["seeds"]
    assert [p["max_deviation"] for p in picks] == [33.0, 31.0, 15.0]
    assert picks[1]["policy"] == "seed_1/checkpoints/step_1/policy.zip"  # no machine's folder
    # None as safe as the APF: the lowest in early ends, collisions, losses, in that order.
    rows, apf = select_checkpoint.read_selection(seeds.seed_dir(out, 2))
    assert select_checkpoint.choose(rows, {**apf, "terminated": -1.0})["max_deviation"] == 15.0
    # Seeds selected on other encounters do not compare: refused, naming the seed.
    _selection(seeds.seed_dir(out, 2), [(0, 0, 0.0, 10.0)], apf=(0.0, 0.0, 0.05, 35.0))
    with pytest.raises(ValueError, match="seed 2: its selection's APF figures"):
        seeds.ship(out, 3)
    (seeds.seed_dir(out, 2) / "selection.csv").write_text("policy,agent_steps\nx,1\n")
    with pytest.raises(ValueError, match=r"selection\.csv, line 2: needs a policy"):
        seeds.ship(out, 3)


def test_publish_names_its_files_and_never_overwrites(tmp_path, capsys):
    prefix = tmp_path / "results" / "seeds_shared"
    names = [q.name for q in seeds.published(prefix, scaling=True)]
    assert names == ["seeds_shared.md", "seeds_shared.json", "seeds_shared_curves.png",
                     "seeds_shared_scaling.md", "seeds_shared_scaling.json",
                     "seeds_shared_scaling.png"]  # fmt: skip
    prefix.parent.mkdir()
    prefix.with_name("seeds_shared_curves.png").write_bytes(b"mine")
    with pytest.raises(SystemExit):
        seeds.main(["--recipe", "shared", "--out-dir", str(tmp_path / "r"), "--publish",
                    str(prefix)])  # fmt: skip
    assert "seeds_shared_curves.png exists (pass --force" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()  # refused before anything ran
    with pytest.raises(SystemExit):  # --ship-to never overwrites either
        seeds.main(["--recipe", "shared", "--out-dir", str(tmp_path / "r"), "--ship-to",
                    str(prefix.with_name("seeds_shared_curves.png"))])  # fmt: skip
    assert "exists (pass --force" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="give a file name prefix"):
        seeds.published(Path("."), scaling=False)
    # A sweep counts as done only whole, and with the episodes asked for.
    run = tmp_path / "run"
    run.mkdir()
    (run / "scaling.json").write_text(json.dumps({"seeds": {"count": 50}}))
    assert not seeds.scaling_done(run, 50)  # the .md and .png were never written
    (run / "scaling.md").write_text("x")
    (run / "scaling.png").write_bytes(b"x")
    assert seeds.scaling_done(run, 50) and not seeds.scaling_done(run, 100)


def _fake_seeds_run(folder, recipe, steps, collisions):
    metric = {"iqm": 0.0, "ci_low": 0.0, "ci_high": 0.0}
    agg = {key: dict(metric) for key, _, _ in seeds.METRICS}
    agg["episode.collision"] = {"iqm": collisions, "ci_low": 0.0, "ci_high": 2 * collisions}
    agg["episode.max_deviation"] = {"iqm": 20.0, "ci_low": 18.0, "ci_high": 22.0}
    data = {"recipe": recipe, "seeds": 2, "across_seeds": agg,
            "held_out_seeds": {"first": 5_000_000, "count": 500},
            "training": {f"seed_{k}": {"agent_steps": steps * (k + 1), "wall_s": 3300.0}
                         for k in range(2)}}  # fmt: skip
    for k in range(2):
        d = seeds.seed_dir(folder, k)
        d.mkdir(parents=True)
        (d / "progress.csv").write_text(
            "agent_steps,wall_s,episodes,return_mean,collision_rate,loss_of_separation_rate,"
            "max_deviation_mean,episode_length_mean\n100,60,3,5.0,0.1,0.2,30.0,50\n"
            "200,3300,6,6.0,0.0,0.1,25.0,50\n"
        )
    (folder / "seeds.json").write_text(json.dumps(data))


def test_compare_recipes_at_equal_wall_time(tmp_path, capsys):
    import compare_recipes

    _fake_seeds_run(tmp_path / "shared", "shared", 40_000_000, 0.04)
    _fake_seeds_run(tmp_path / "mappo", "mappo", 100_000_000, 0.02)
    out = tmp_path / "cmp"
    argv = [str(tmp_path / "shared"), str(tmp_path / "mappo"), "--out", str(out)]
    text = compare_recipes.main(argv)
    rows = {r[0]: r[1:] for r in (
        [c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
        if line.startswith("| shared") or line.startswith("| mappo"))}  # fmt: skip
    assert rows["shared"][:4] == ["2", "60.0M (40.0-80.0M)", "55.0 (55.0-55.0)",
                                  "4.0% [0.0%, 8.0%]"]  # fmt: skip
    assert rows["mappo"][1] == "150.0M (100.0-200.0M)"
    assert "longest run: shared 55.0 min, mappo 55.0 min" in text
    assert out.with_suffix(".png").stat().st_size > 10_000
    with pytest.raises(SystemExit):  # no silent overwrite
        compare_recipes.main(argv)
    with pytest.raises(SystemExit):
        compare_recipes.main([str(tmp_path / "nope"), "--out", str(tmp_path / "x")])
    assert "nope/seeds.json: not found" in capsys.readouterr().err
    # Budgets are read from the checkpoints: unequal ones are not "equal wall time".
    cfg = make_config(scenario="random")
    for run, minutes in (("shared", 55.0), ("mappo", 30.0)):
        for k in range(2):
            path = seeds.seed_dir(tmp_path / run, k) / "policy.zip"
            weights = [(np.zeros((3, ObservationLayout.from_config(cfg).dim), np.float32),
                        np.zeros(3, np.float32))]  # fmt: skip
            meta = PolicyCheckpoint(config=cfg.to_dict(), obs_dim=weights[0][0].shape[1],
                                    activation="tanh", hidden=(), obs_norm=False,
                                    info={"args": {"max_minutes": minutes}})  # fmt: skip
            save_policy(path, meta, weights)
    assert compare_recipes.budget_minutes(tmp_path / "shared", {"seeds": 2}) == 55.0
    with pytest.raises(SystemExit):
        compare_recipes.main([*argv, "--force"])
    assert "different --max-minutes" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("recipe", "name"), [("residual_apf", "fast"), ("residual_apf", "lean"), ("shared", "lean")]
)
def test_a_fast_report_is_what_its_command_and_checkpoints_say(recipe, name):
    """``seeds_<recipe>_<name>``: its recorded options are its command's flags over the
    recipe's defaults, every kept checkpoint was trained with them, and its APF row is the
    main report's (the same held-out encounters)."""
    from uasep_env.policies.checkpoint_reader import read_checkpoint
    from uasep_env.training import ppo_shared
    from uasep_env.training.args import PER_RUN, Args
    from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS

    defaults = RESIDUAL_DEFAULTS if recipe == "residual_apf" else Args()
    results = ROOT / "baselines" / "results"
    fast = json.loads((results / f"seeds_{recipe}_{name}.json").read_text())
    main = json.loads((results / f"seeds_{recipe}.json").read_text())
    flags = shlex.split(fast["command"].split(" -- ", 1)[1])  # the driver quotes its command
    args = vars(ppo_shared.parse_args(flags, defaults))
    now = {k: v for k, v in args.items() if k not in PER_RUN}
    # Options the recipes gained after a report (--device, --trainer, --arch, --shield,
    # --formation-sizes): at their defaults.
    added = set(now) - set(fast["recipe_args"])
    assert added <= {"device", "trainer", "arch", "shield", "formation_sizes"}
    assert all(now[k] == getattr(defaults, k) for k in added)
    assert fast["recipe_args"] == {k: now[k] for k in fast["recipe_args"]}
    for k in range(3):
        path = ROOT / f"baselines/seeds/{recipe}_{name}/seed_{k}/selected.zip"
        meta = read_checkpoint(path)[0]
        trained = {n: v for n, v in meta.info["args"].items() if n not in PER_RUN}
        assert trained == fast["recipe_args"] and meta.info["args"]["seed"] == 1000 * k
        lean = meta.info.get("implementation") == "uasep_env.training.ppo_lean"
        assert lean == (fast["recipe_args"].get("trainer") == "lean")
    assert fast["held_out_seeds"] == main["held_out_seeds"]
    assert fast["per_seed"]["apf"] == main["per_seed"]["apf"]
