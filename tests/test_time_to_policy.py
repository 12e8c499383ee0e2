"""benchmarks/time_to_policy.py: the bar, the stop rule and the record."""

import hashlib
import json
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import time_to_policy as ttp  # noqa: E402


def _agg(collision, los, los_hi, dev, dev_hi):
    return {
        "episode.collision": {"rate": collision},
        "episode.loss_of_separation": {"rate": los, "ci_high": los_hi},
        "episode.max_deviation": {"mean": dev, "ci_high": dev_hi},
    }


def test_the_bar_is_the_shipped_intervals_upper_ends():
    bar = ttp.make_bar(_agg(0.0, 0.02, 0.05, 33.0, 35.0), 100)
    assert (bar.loss_of_separation, bar.max_deviation) == (0.05, 35.0)
    assert ttp.reached(ttp.figures(_agg(0.0, 0.05, 0, 35.0, 0)), bar)
    assert not ttp.reached(ttp.figures(_agg(0.01, 0.0, 0, 20.0, 0)), bar)  # any collision
    assert not ttp.reached(ttp.figures(_agg(0.0, 0.06, 0, 30.0, 0)), bar)
    assert not ttp.reached(ttp.figures(_agg(0.0, 0.0, 0, 35.1, 0)), bar)
    # A shipped policy that collides: no more collisions than it (never a bar it fails).
    bar = ttp.make_bar(_agg(0.0125, 0.25, 0.29, 29.5, 30.5), 400)
    assert bar.collision == 0.0125 and ttp.reached(ttp.figures(_agg(0.0125, 0.2, 0, 30, 0)), bar)
    assert not ttp.reached(ttp.figures(_agg(0.015, 0.2, 0, 30.0, 0)), bar)


@pytest.mark.parametrize(
    ("recipe", "trainer"),
    [
        ("residual_apf", "default"),
        ("mappo", "default"),
        ("residual_apf", "lean"),
        ("mappo", "lean"),
        ("lagrangian_residual", "lean"),
    ],
)
def test_a_run_stops_at_the_bar_and_records_where_the_time_went(
    tmp_path, recipe, trainer, monkeypatch, capsys
):
    if recipe == "mappo":
        pytest.importorskip("skrl")
    out = tmp_path / "ttp.json"
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "1200", "--episode-duration", "20"]  # fmt: skip
    flags = ["--recipe", recipe, "--trainer", trainer, "--episodes", "2", "--check-every", "384"]
    monkeypatch.chdir(tmp_path)  # a relative run folder is recorded absolute (for --of)
    rec = ttp.main([*flags, "--out", str(out), "--run-dir", "run", "--held-out", "2", "--", *tiny])
    assert json.loads(out.read_text())["agent_steps"] == rec["agent_steps"]
    assert rec["trainer"] == trainer and rec["recipe_args"]["trainer"] == trainer
    assert rec["recipe_args"]["out_dir"] == str(tmp_path.resolve() / "run")
    # --held-out plays a reached policy, or says that there is none.
    said = "no policy to play" in capsys.readouterr().out
    assert ("held_out" in rec) == rec["reached"] == (not said)
    checks = rec["checks"]
    assert checks, "no check ran"
    # A check every --check-every agent-steps (a rollout is 2 envs x 3 UAVs x 32 steps).
    assert [c["agent_steps"] for c in checks] == [384 * (k + 1) for k in range(len(checks))]
    # It stopped at the first check that cleared the bar, or ran out of steps without one.
    hits = [c["reached"] for c in checks]
    assert hits.count(True) <= 1 and (not any(hits) or hits[-1])
    assert rec["reached"] == any(hits)
    t = rec["time_s"]
    assert t["env"] > 0 and t["learner"] > 0 and t["rollout_other"] > 0 and t["evaluation"] > 0
    assert rec["machine"] == ttp.machine(rec["machine"]["torch"])  # where it was measured
    # The checks are evaluation time, not training time.
    assert t["env"] + t["rollout_other"] + t["learner"] <= t["training"] + 1e-6
    _check_held_out(out, rec)
    with pytest.raises(SystemExit):  # no silent overwrite
        ttp.main(["--recipe", recipe, "--out", str(out)])
    other = tmp_path / "other.json"  # nor of the run folder: refused before any episode
    with pytest.raises(SystemExit, match="is not empty"):
        ttp.main([*flags, "--out", str(other), "--run-dir", str(tmp_path / "run"), "--", *tiny])
    assert not other.exists()


def test_the_recipes_trainer_flag_is_the_scripts(tmp_path):
    # --trainer lean after -- (the recipe's flag) trains on the lean loop, as the script's
    # own --trainer lean does: the record never says one trainer and trains with another.
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "400", "--trainer", "lean"]  # fmt: skip
    rec = ttp.main(["--recipe", "residual_apf", "--episodes", "2", "--check-every", "384",
                    "--out", str(tmp_path / "r.json"), "--run-dir", str(tmp_path / "run"),
                    "--", *tiny])  # fmt: skip
    assert rec["trainer"] == "lean" and rec["recipe_args"]["trainer"] == "lean"


def test_mappo_on_the_lean_loop_trains_mappos_centralised_critic(tmp_path):
    from uasep_env.policies.learned import read_checkpoint

    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "400"]  # fmt: skip
    rec = ttp.main(["--recipe", "mappo", "--trainer", "lean", "--episodes", "2",
                    "--check-every", "384", "--out", str(tmp_path / "r.json"),
                    "--run-dir", str(tmp_path / "run"), "--", *tiny])  # fmt: skip
    assert rec["trainer"] == "lean" and rec["shipped"].endswith("mappo.zip")
    meta = read_checkpoint(tmp_path / "run" / "check.zip")[0]
    assert meta.algorithm == "MAPPO" and "centralised critic" in meta.info["implementation"]


def test_of_names_a_file_that_is_not_a_record(tmp_path):
    missing = tmp_path / "missing.json"
    with pytest.raises(SystemExit):
        ttp.main(["--held-out", "2", "--of", str(missing)])
    for text in ("not json", "[1, 2]", json.dumps({"recipe": "residual_apf", "reached": True})):
        bad = tmp_path / "bad.json"
        bad.write_text(text)
        with pytest.raises(SystemExit):
            ttp.main(["--held-out", "2", "--of", str(bad)])
        assert bad.read_text() == text  # left as it was


def _check_held_out(out, rec):
    """``--of``: the reached policy, the APF and the shipped one on the held-out bank."""
    from uasep_env import make_config
    from uasep_env.evaluation import evaluate
    from uasep_env.scenarios import HELD_OUT_SEEDS, VALIDATION_SEEDS

    if not rec["reached"]:
        with pytest.raises(SystemExit):
            ttp.main(["--held-out", "2", "--of", str(out)])
        assert "held_out" not in json.loads(out.read_text())
        return
    got = ttp.main(["--held-out", "2", "--of", str(out)])["held_out"]
    assert json.loads(out.read_text())["held_out"] == got
    policy = Path(rec["recipe_args"]["out_dir"]) / "check.zip"
    assert got["policy_sha256"] == hashlib.sha256(policy.read_bytes()).hexdigest()
    assert set(got["figures"]) == {"apf", "shipped", "reached"}
    from uasep_env.policies.env_version import current_version

    assert got["env_version"] == current_version()  # the figures of this env
    # The held-out bank, not the validation encounters the checks played.
    assert not set(HELD_OUT_SEEDS[:2]) & set(VALIDATION_SEEDS)
    # The seeds reports' held-out config (train/seeds.py), so that the figures compare.
    cfg = make_config(scenario="random")
    mine = evaluate({"p": str(policy)}, cfg, list(HELD_OUT_SEEDS)[:2])
    dev = mine.results["p"].aggregate["episode.max_deviation"]
    assert got["figures"]["reached"]["max_deviation"]["value"] == dev["mean"]
    assert got["figures"]["reached"]["max_deviation"]["ci_high"] == dev["ci_high"]


RESIDUAL = ("residual_apf", "residual_apf_set", "lagrangian_residual")
RECORDS = sorted((ROOT / "benchmarks" / "results").glob("time_to_policy_*.json"))


def test_every_recipe_has_a_committed_record():
    """Each recipe's time to its shipped policy is measured (``time_to_policy_<recipe>.json``)."""
    for recipe in ttp.RECIPES:
        path = ROOT / f"benchmarks/results/time_to_policy_{recipe}.json"
        assert path in RECORDS, f"no record for {recipe}"
        assert json.loads(path.read_text())["recipe"] == recipe


def test_the_set_recipe_trains_its_shipped_flags_and_is_checked_at_3_uavs(tmp_path, monkeypatch):
    """The set network trains at 3-8 UAVs with its shipped run's flags; every check (and the
    bar) plays the validation encounters at 3 UAVs, where the APF does not clear the bar."""
    from uasep_env.policies.learned import read_checkpoint

    played = []
    evaluate = ttp._evaluate

    def spy(policy, config, seeds):
        played.append(config.n_uavs)
        return evaluate(policy, config, seeds)

    monkeypatch.setattr(ttp, "_evaluate", spy)
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--hidden", "8,8",
            "--total-timesteps", "1024", "--episode-duration", "20"]  # fmt: skip
    rec = ttp.main(["--recipe", "residual_apf_set", "--episodes", "2", "--check-every", "512",
                    "--out", str(tmp_path / "r.json"), "--run-dir", str(tmp_path / "run"),
                    "--", *tiny])  # fmt: skip
    a = rec["recipe_args"]
    assert (a["arch"], a["n_uavs"], a["k_uavs"], a["trainer"]) == ("set", 8, 7, "lean")
    assert a["formation_sizes"] == "3,4,5,6,7,8"
    assert (a["n_envs"], a["hidden"]) == (2, "8,8")  # the caller's flags after the shipped run's
    assert rec["trainer"] == "lean" and rec["shipped"].endswith("ppo_residual_apf_set.zip")
    assert rec["checks_played_with"] == {"n_uavs": 3, "k_uavs": 2}
    assert rec["checks"] and played == [3] * (2 + len(rec["checks"]))  # bar, APF, checks
    meta = read_checkpoint(tmp_path / "run" / "check.zip")[0]
    assert meta.architecture == "set"  # the policy checked is the set network


def test_the_lagrangian_recipe_trains_under_its_multiplier(tmp_path, monkeypatch, capsys):
    from uasep_env.training import constraint

    shaped = []
    shape = constraint.LeanCost.shape

    def spy(self, *args, **kwargs):
        shaped.append(1)
        return shape(self, *args, **kwargs)

    monkeypatch.setattr(constraint.LeanCost, "shape", spy)
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "400", "--cost-limit", "0.5"]  # fmt: skip
    flags = ["--recipe", "lagrangian_residual", "--episodes", "2", "--check-every", "192"]
    rec = ttp.main([*flags, "--trainer", "lean", "--out", str(tmp_path / "r.json"),
                    "--run-dir", str(tmp_path / "run"), "--", *tiny])  # fmt: skip
    assert rec["trainer"] == "lean" and rec["shipped"].endswith("ppo_lagrangian.zip")
    rollouts = rec["agent_steps"] // (2 * 3 * 32)  # 2 envs x 3 UAVs x 32 steps
    assert rollouts >= 2 and len(shaped) == 32 * rollouts  # every step of every rollout
    rows = (tmp_path / "run" / "cost_progress.csv").read_text().splitlines()
    assert len(rows) == 1 + rollouts  # the header and a row a rollout: the multiplier moved
    capsys.readouterr()
    shield = ["--", "--shield", "cbf", "--trainer", "lean"]
    for bad, named in ((["--trainer", "default"], "--trainer: trainer 'default'"),
                       (shield, "--shield: 'cbf'")):  # fmt: skip
        with pytest.raises(SystemExit) as err:
            ttp.main([*flags, "--out", str(tmp_path / "b.json"),
                      "--run-dir", str(tmp_path / "new"), *bad])  # fmt: skip
        said = f"{capsys.readouterr().err}\n{err.value.code}".splitlines()
        errors = [line for line in said if "error:" in line]  # one line, naming the flag
        assert len(errors) == 1 and named in errors[0]
    assert not (tmp_path / "new").exists() and not (tmp_path / "b.json").exists()


@pytest.mark.parametrize("path", RECORDS, ids=lambda p: p.stem)
def test_a_committed_record_is_consistent(path):
    """A committed result file: its stop is the first check that clears its own bar."""
    rec = json.loads(path.read_text())
    _check_record(rec)
    if "side_by_side" not in rec:
        return
    sbs = rec["side_by_side"]
    runs = sbs["runs"]
    for run in runs:  # each seed's own record, checked as any record
        _check_record(run)
    assert [r["recipe_args"]["seed"] for r in runs] == sbs["seeds"]
    k = ttp.first_to_reach(runs)
    assert sbs["reached_by"] == (None if k is None else sbs["seeds"][k])
    assert rec["reached"] == (k is not None)
    if k is not None:  # the record is the first run's to reach; the others were stopped
        assert rec["checks"] == runs[k]["checks"] and rec["recipe_args"] == runs[k]["recipe_args"]
        assert all(r["reached"] or r["stopped_by_another"] for r in runs)
    assert {r["bar"]["loss_of_separation"] for r in runs} == {rec["bar"]["loss_of_separation"]}


def _check_record(rec):
    b = rec["bar"]
    bar = ttp.Bar(**b)  # records before the collision field asked for none (its default)
    if "collision" in b:
        assert b["collision"] == b["shipped"]["collision"]
    t = rec["time_s"]
    verdicts = [ttp.reached(c, bar) for c in rec["checks"]]
    assert [c["reached"] for c in rec["checks"]] == verdicts
    assert rec["reached"] == any(verdicts)
    assert verdicts.count(True) <= 1 and (not any(verdicts) or verdicts[-1])  # stops there
    last = rec["checks"][-1]
    if rec["reached"]:  # the figures at the check that cleared the bar
        assert (rec["agent_steps"], rec["training_minutes"]) == pytest.approx(
            (last["agent_steps"], last["training_minutes"])
        )
    else:  # the whole budget, past the last check
        assert rec["agent_steps"] >= last["agent_steps"]
        assert rec["training_minutes"] >= last["training_minutes"]
        assert rec["training_minutes"] == pytest.approx(t["training"] / 60.0)
    parts = t["env"] + t["rollout_other"] + t["learner"]  # the rest: checkpoints, logging
    assert 0.99 * t["training"] <= parts <= t["training"]
    if rec["recipe"] in RESIDUAL:  # it starts at the APF: else the bar measures nothing
        assert not rec["apf_clears_bar"]
    # A GPU figure names its GPU, and only a run with its learner there has one.
    on_gpu = rec["recipe_args"].get("device", "cpu") != "cpu"
    assert bool(rec["machine"].get("gpu")) == on_gpu
    assert ("--device cuda" in rec["command"]) == on_gpu


def test_held_out_figures_are_played_on_the_same_encounters():
    """Every record's held-out APF row is the same (the same bank, config and count), and
    the APF's row in the residual seeds report where the counts agree."""
    rows = {}
    for path in RECORDS:
        h = json.loads(path.read_text()).get("held_out")
        if h is not None:
            assert set(h["figures"]) == {"apf", "shipped", "reached"}
            # Records before the field were played in -v2.
            key = (h["episodes"], h.get("env_version", 2))
            rows.setdefault(key, []).append(h["figures"]["apf"])
    report = json.loads((ROOT / "baselines/results/seeds_residual_apf.json").read_text())
    apf = report["per_seed"]["apf"]  # a -v2 report
    for (n, version), apf_rows in rows.items():
        assert all(r == apf_rows[0] for r in apf_rows)
        if apf["episode.max_deviation"]["n"] == n and version == 2:
            assert apf_rows[0]["max_deviation"]["value"] == apf["episode.max_deviation"]["mean"]
            assert apf_rows[0]["loss_of_separation"]["ci_high"] == pytest.approx(
                apf["episode.loss_of_separation"]["ci_high"]
            )


def test_the_machine_is_named_by_its_processor_model(tmp_path):
    """Speed figures compare on one processor model: the record names it, not "x86_64"."""
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: GenuineIntel\n"
                    "model name\t: Intel(R) Xeon(R) Processor\nflags\t\t: fpu\n")  # fmt: skip
    assert ttp.cpu_model(info) == "Intel(R) Xeon(R) Processor"
    info.write_text("processor\t: 0\n")  # no model: Python's guess, never empty
    assert ttp.cpu_model(info) and ttp.cpu_model(tmp_path / "missing")
    got = ttp.machine("x")
    assert got["cpu_model"] == ttp.cpu_model() and got["numpy"] == np.__version__


def _run(seed, reached_at=None, stopped=False, minutes=5.0):
    """A run's record, as much of it as merge_runs reads."""
    hit = reached_at is not None
    check = {"agent_steps": 4_000_000, "training_minutes": minutes, "reached": hit,
             "unix_time": reached_at or 0.0}  # fmt: skip
    return {"recipe": "shared", "reached": hit, "stopped_by_another": stopped,
            "training_minutes": minutes, "agent_steps": 4_000_000 if hit else 4_100_000,
            "checks": [check], "recipe_args": {"seed": seed},
            "command": f"seed {seed}"}  # fmt: skip


def test_side_by_side_the_record_is_the_first_run_to_reach():
    # Two runs clear the bar at about the same time (each sees the stop file only at its
    # next step): the one whose check came first by the wall clock is the record.
    runs = [_run(0, stopped=True, minutes=6.0), _run(1000, reached_at=200.0, minutes=5.5),
            _run(2000, reached_at=100.0, minutes=5.8)]  # fmt: skip
    rec = ttp.merge_runs(runs, [0, 1000, 2000], 420.0)
    assert rec["reached"] and rec["side_by_side"]["reached_by"] == 2000
    assert rec["training_minutes"] == 5.8 and rec["recipe_args"] == {"seed": 2000}
    assert rec["side_by_side"]["agent_steps_all"] == 4_100_000 + 2 * 4_000_000
    assert rec["side_by_side"]["wall_minutes"] == 7.0 and rec["side_by_side"]["runs"] == runs
    assert "command" not in rec  # the script's own command, not a run's
    # None reached: the record is the longest-trained run's, and says so.
    runs = [_run(0, minutes=6.0), _run(1000, minutes=6.2), _run(2000, minutes=6.1)]
    rec = ttp.merge_runs(runs, [0, 1000, 2000], 420.0)
    assert not rec["reached"] and rec["side_by_side"]["reached_by"] is None
    assert rec["recipe_args"] == {"seed": 1000}


def test_a_run_stops_when_the_stop_file_appears(tmp_path, monkeypatch):
    """A check that clears the bar creates the stop file; the file stops every other run."""
    import uasep_env.policies

    stop = tmp_path / "stop"
    bar = ttp.make_bar(_agg(0.0, 0.02, 0.05, 33.0, 35.0), 2)
    checker = ttp.Checker(bar=bar, seeds=[1, 2], eval_cfg=None, check_every=10,
                          max_minutes=60.0, clock=ttp.Clock(), stop_file=stop)  # fmt: skip
    monkeypatch.setattr(uasep_env.policies, "load_policy", lambda path, cfg: path)
    figs = iter([_agg(0.01, 0.0, 0, 20.0, 0), _agg(0.0, 0.04, 0, 34.0, 0)])
    monkeypatch.setattr(ttp, "_evaluate", lambda policy, cfg, seeds: next(figs))
    checker.maybe_check(10, lambda: "p.zip")  # a collision: not reached, no stop file
    assert not checker.spent() and not stop.exists()
    checker.maybe_check(20, lambda: "p.zip")
    assert checker.done and stop.exists() and checker.spent()
    other = ttp.Checker(bar=bar, seeds=[1], eval_cfg=None, check_every=10, max_minutes=60.0,
                        clock=ttp.Clock(), stop_file=stop)  # fmt: skip
    assert other.spent() and other.stopped_by_another and not other.done  # not reached
    assert not checker.stopped_by_another  # its own bar stopped it
    assert [c["reached"] for c in checker.checks] == [False, True]
    assert checker.checks[0]["unix_time"] <= checker.checks[1]["unix_time"]


@pytest.mark.parametrize("trainer", ["default", "lean"])
def test_a_run_under_an_existing_stop_file_stops_at_once(tmp_path, trainer):
    """Another run cleared the bar before this one trained a rollout: it stops, says why."""
    stop = tmp_path / "stop"
    stop.touch()
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "9999", "--episode-duration", "20"]  # fmt: skip
    rec = ttp.run("residual_apf", 2, 192, 60.0, tmp_path / "run", tiny, trainer=trainer,
                  stop_file=stop)  # fmt: skip
    assert rec["stopped_by_another"] and not rec["reached"] and not rec["checks"]
    assert rec["agent_steps"] <= 2 * 3 * 32  # at most the rollout it was in


def test_a_record_command_reads_back_as_the_arguments_it_ran_with():
    """A recipe flag whose value holds a space (``--config "a=1 b=2"``) is quoted."""
    argv, extra = ["--recipe", "mappo", "--seeds", "2"], ["--config", "reward.a=1 reward.b=2"]
    line = ttp.seeds_driver().command_line("benchmarks/time_to_policy.py", argv, extra)
    assert shlex.split(line) == ["python", "benchmarks/time_to_policy.py", *argv, "--", *extra]
    assert shlex.split(ttp.seeds_driver().command_line("x.py", argv, [])) == [
        "python",
        "x.py",
        *argv,
    ]


def test_seeds_side_by_side_train_each_seed_in_its_own_process(tmp_path, capsys):
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "768", "--episode-duration", "20",
            "--config", "reward.collision=4 reward.progress=1"]  # fmt: skip
    out, run_dir = tmp_path / "sbs.json", tmp_path / "run"
    flags = ["--recipe", "residual_apf", "--trainer", "lean", "--episodes", "2",
             "--check-every", "384", "--seeds", "2", "--run-dir", str(run_dir)]  # fmt: skip
    rec = ttp.main([*flags, "--out", str(out), "--", *tiny])
    said = capsys.readouterr().out
    assert "[seed 0] bar" in said and "[seed 1000] bar" in said  # each run's lines, relayed
    sbs = rec["side_by_side"]
    assert sbs["seeds"] == [0, 1000] and json.loads(out.read_text()) == rec
    runs = sbs["runs"]
    assert [r["recipe_args"]["seed"] for r in runs] == [0, 1000]
    assert [r["recipe_args"]["out_dir"] for r in runs] == [
        str(run_dir / f"seed_{k}") for k in (0, 1)
    ]
    assert all(r["trainer"] == "lean" for r in runs)
    # The recipe's flags reach each run whole, and the record's command reads back as them.
    assert {r["recipe_args"]["config"] for r in runs} == {"reward.collision=4 reward.progress=1"}
    assert shlex.split(rec["command"])[2:] == [*flags, "--out", str(out), "--", *tiny]
    assert rec["reached"] == any(r["reached"] for r in runs)
    k = ttp.first_to_reach(runs)
    assert sbs["reached_by"] == (None if k is None else sbs["seeds"][k])
    # Refused before anything runs: a used folder, a --seed of the caller's.
    with pytest.raises(SystemExit):
        ttp.main([*flags, "--out", str(tmp_path / "again.json"), "--", *tiny])
    with pytest.raises(SystemExit):
        ttp.main([*flags[:-1], str(tmp_path / "new"), "--out", str(tmp_path / "b.json"),
                  "--", *tiny, "--seed", "5"])  # fmt: skip
    assert not (tmp_path / "new").exists() and not (tmp_path / "again.json").exists()
    capsys.readouterr()
    for bad, named in (
        (["--seeds", "101"], "--seeds: at most 100"),
        (["--seeds", "2", "--stop-file", str(tmp_path / "s")], "--stop-file: not with --seeds"),
    ):
        with pytest.raises(SystemExit):  # a used folder too: a missed check trains nothing
            ttp.main(["--recipe", "shared", "--out", str(tmp_path / "c.json"),
                      "--run-dir", str(run_dir), *bad])  # fmt: skip
        assert named in capsys.readouterr().err
    with pytest.raises(SystemExit):  # --of adds held-out figures to a record: no training
        ttp.main(["--held-out", "2", "--of", str(out), "--seeds", "2"])
    assert "takes --held-out N" in capsys.readouterr().err
    assert not (tmp_path / "c.json").exists()
