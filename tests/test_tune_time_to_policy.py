"""benchmarks/tune_time_to_policy.py: the study's trials, budgets, resume and summary."""

import argparse
import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("optuna")
pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import tune_time_to_policy as tune  # noqa: E402

FAST = ["--n-envs", "128", "--n-steps", "64", "--batch-size", "8192", "--n-epochs", "2",
        "--learning-rate", "0.00025"]  # fmt: skip


def test_the_baseline_is_the_fast_flags_of_docs_speed():
    assert tune.to_flags(tune.BASELINE, 3) == FAST
    # n_minibatches splits the rollout, rounded up: 64 x 32 x 3 = 6144 samples in 4.
    flags = tune.to_flags({**tune.BASELINE, "n_envs": 64, "n_steps": 32, "n_minibatches": 4}, 3)
    assert flags[flags.index("--batch-size") + 1] == "1536"
    flags = tune.to_flags({**tune.BASELINE, "n_envs": 64, "n_steps": 32, "n_minibatches": 6}, 5)
    assert flags[flags.index("--batch-size") + 1] == "1707"  # 10240 / 6, rounded up
    # Every searched value is a value its flag accepts.
    for name, p in tune.SPACE.items():
        assert name in tune.BASELINE
        if p.kind != "categorical":
            assert p.values[0] <= tune.BASELINE[name] <= p.values[1]
        else:
            assert tune.BASELINE[name] in p.values


def _fake_run(calls):
    """A time-to-policy run whose outcome is a function of the flags (no training)."""

    def run(recipe, episodes, check_every, max_minutes, run_dir, extra, overwrite=False,
            trainer="default"):  # fmt: skip
        lr = float(extra[extra.index("--learning-rate") + 1])
        minutes = 1.0 + 1e-3 / lr  # faster with a larger step
        hit = minutes <= max_minutes
        calls.append({"budget": max_minutes, "extra": list(extra), "trainer": trainer,
                      "run_dir": run_dir})  # fmt: skip
        return {"reached": hit, "training_minutes": minutes if hit else max_minutes,
                "agent_steps": int(minutes * 1e6), "time_s": {"training": 60.0 * minutes},
                "checks": [{}]}  # fmt: skip

    return run


def _args(tmp_path, *more):
    return ["--recipe", "residual_apf", "--trials", "4", "--max-minutes", "5", "--study-dir",
            str(tmp_path / "study"), "--out", str(tmp_path / "out.json"), "--startup", "2",
            *more]  # fmt: skip


def test_a_study_starts_from_the_baseline_and_caps_trials_at_the_best(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    res = tune.main([*_args(tmp_path), "--", "--torch-threads", "2"])
    assert len(calls) == 4 and all(c["trainer"] == "lean" for c in calls)
    assert calls[0]["extra"] == ["--torch-threads", "2", *FAST]
    assert res["trials"][0]["params"] == tune.BASELINE
    # The baseline reaches in 1 + 1e-3 / 2.5e-4 = 5 minutes; later budgets are the best so far.
    best = 5.0
    for c, t in zip(calls, res["trials"], strict=True):
        assert c["budget"] == min(5.0, best) == t["budget_minutes"]
        assert t["value"] == (t["training_minutes"] if t["reached"] else 10.0)
        if t["reached"]:
            best = min(best, t["value"])
        rec = json.loads((tmp_path / "study" / f"trial_{t['number']:03d}.json").read_text())
        assert rec["tuning"]["params"] == t["params"]
        assert c["run_dir"].name == f"trial_{rec['tuning']['trial']:03d}"
    assert res["best"]["value"] == best == min(t["value"] for t in res["trials"])
    assert json.loads((tmp_path / "out.json").read_text())["best"] == res["best"]
    assert res["settings"]["fixed"] == ["--torch-threads", "2"]
    with pytest.raises(SystemExit):  # no silent overwrite of the summary
        tune.main([*_args(tmp_path), "--", "--torch-threads", "2"])


def test_without_stop_at_best_every_trial_gets_the_whole_budget(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    tune.main(_args(tmp_path, "--no-stop-at-best"))
    assert [c["budget"] for c in calls] == [5.0] * 4


def test_a_study_resumes_and_retries_a_trial_left_running(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    args = _args(tmp_path)
    tune.main([*args[:3], "2", *args[4:]])  # two trials
    assert len(calls) == 2
    # A process killed inside a trial leaves it running: ask without telling.
    a = argparse.Namespace(
        recipe="residual_apf", trainer="lean", episodes=400, check_every=4_000_000,
        max_minutes=5.0, seed=0, startup=2, stop_at_best=True)  # fmt: skip
    study = tune.open_study(tmp_path / "study", tune.settings_of(a, []))
    lost = {
        "n_envs": 256,
        "n_steps": 128,
        "n_minibatches": 6,
        "n_epochs": 4,
        "learning_rate": 1e-3,
    }  # unlike any the sampler draws next
    study.enqueue_trial(lost)
    stale = study.ask()
    assert tune.suggest(stale) == lost
    tune.main([*args, "--force"])  # four trials wanted: two more, the lost one's flags first
    assert len(calls) == 4
    assert calls[2]["extra"] == tune.to_flags(lost, 3)
    res = json.loads((tmp_path / "out.json").read_text())
    states = [t["state"] for t in res["trials"]]
    assert states.count("COMPLETE") == 4 and states[stale.number] == "FAIL"
    # Enough trials finished: nothing runs again.
    tune.main([*args, "--force"])
    assert len(calls) == 4


def test_a_study_of_other_settings_is_refused(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    tune.main(_args(tmp_path, "--trials", "1"))
    with pytest.raises(SystemExit):
        tune.main(_args(tmp_path, "--trials", "2", "--episodes", "100", "--force"))
    assert "other settings (episodes)" in capsys.readouterr().err
    assert len(calls) == 1


@pytest.mark.parametrize(
    ("more", "said"),
    [
        (["--", "--n-envs", "64"], "a trial sets these itself"),
        (["--", "--learning-rate=1e-3"], "a trial sets these itself"),
        (["--recipe", "mappo"], "not a PPO recipe"),  # the lean loop trains it, not a study
        (["--trainer", "default", "--recipe", "mappo"], "not a PPO recipe"),
        (["--max-minutes", "0"], "argument --max-minutes"),
    ],
)
def test_bad_arguments_are_refused_before_any_trial(tmp_path, monkeypatch, capsys, more, said):
    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    with pytest.raises(SystemExit):  # a later flag wins in argparse
        tune.main([*_args(tmp_path), *more])
    assert said in capsys.readouterr().err
    assert not calls and not (tmp_path / "out.json").exists()


@pytest.mark.slow
def test_a_trial_trains_the_recipe_with_its_flags(tmp_path, monkeypatch):
    # One real trial of a tiny space: the lean loop trains under time_to_policy's checker.
    one = {"n_envs": (2,), "n_steps": (32,), "n_minibatches": (3,)}
    space = {k: tune.Param("categorical", v) for k, v in one.items()}
    space["n_epochs"] = tune.Param("int", (1, 1))
    space["learning_rate"] = tune.Param("log_float", (1e-4, 1e-3))
    monkeypatch.setattr(tune, "SPACE", space)
    monkeypatch.setattr(tune, "BASELINE", {"n_envs": 2, "n_steps": 32, "n_minibatches": 3,
                                           "n_epochs": 1, "learning_rate": 3e-4})  # fmt: skip
    tiny = ["--hidden", "16", "--total-timesteps", "1200", "--episode-duration", "20"]
    study = ["--study-dir", str(tmp_path / "s"), "--out", str(tmp_path / "o.json")]
    res = tune.main(["--recipe", "residual_apf", "--trials", "1", "--max-minutes", "5",
                     "--episodes", "2", "--check-every", "384", *study, "--", *tiny])  # fmt: skip
    (t,) = res["trials"]
    rec = json.loads((tmp_path / "s" / "trial_000.json").read_text())
    assert rec["trainer"] == "lean" and rec["recipe"] == "residual_apf"
    got = rec["recipe_args"]
    assert (got["n_envs"], got["n_steps"], got["batch_size"], got["n_epochs"]) == (2, 32, 64, 1)
    assert got["learning_rate"] == 3e-4 and got["hidden"] == "16"
    assert got["out_dir"] == str(tmp_path / "s" / "trial_000")
    assert t["agent_steps"] == rec["agent_steps"] and t["reached"] == rec["reached"]
    assert t["value"] == (rec["training_minutes"] if rec["reached"] else 10.0)
    assert [c["agent_steps"] for c in rec["checks"]][:1] == [384]


@pytest.mark.parametrize("error", [KeyboardInterrupt, RuntimeError])
def test_an_interrupted_trial_is_tried_again_and_a_failed_one_is_not(tmp_path, monkeypatch, error):
    calls = []
    fake = _fake_run(calls)

    def broken(*args, **kwargs):
        fake(*args, **kwargs)
        raise error("stop")

    monkeypatch.setattr(tune.ttp, "run", broken)
    with pytest.raises(error):
        tune.main(_args(tmp_path, "--trials", "2"))
    monkeypatch.setattr(tune.ttp, "run", fake)
    tune.main(_args(tmp_path, "--trials", "2"))
    assert calls[0]["extra"] == FAST  # the baseline, interrupted or failed
    assert len(calls) == 3
    assert (calls[1]["extra"] == FAST) == (error is KeyboardInterrupt)
    res = json.loads((tmp_path / "out.json").read_text())
    assert [t["state"] for t in res["trials"]] == ["FAIL", "COMPLETE", "COMPLETE"]
    tune.main(_args(tmp_path, "--trials", "3", "--force"))  # tried again once, not each resume
    assert len(calls) == 4 and calls[3]["extra"] != FAST


def test_a_study_another_process_runs_is_refused(tmp_path, monkeypatch, capsys):
    import fcntl
    import os

    from uasep_env.runtime.runlock import LOCK_NAME

    calls = []
    monkeypatch.setattr(tune.ttp, "run", _fake_run(calls))
    folder = tmp_path / "study"
    folder.mkdir()
    fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT)  # another claim of the folder
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.pwrite(fd, b"pid 4242 on elsewhere\n", 0)
        with pytest.raises(SystemExit):
            tune.main(_args(tmp_path))
    finally:
        os.close(fd)
    assert "in use by another run (pid 4242" in capsys.readouterr().err
    assert not calls and not (folder / "journal.log").exists()


STUDIES = sorted((ROOT / "benchmarks" / "results").glob("tune_*.json"))


def test_the_residual_recipe_has_a_committed_study():
    assert ROOT / "benchmarks/results/tune_residual_apf_lean.json" in STUDIES


@pytest.mark.parametrize("path", STUDIES, ids=lambda p: p.stem)
def test_a_committed_study_is_consistent(path):
    """A committed study: its values follow its rule, its budgets its best, its best its trials."""
    res = json.loads(path.read_text())
    s = res["settings"]
    done = [t for t in res["trials"] if t["state"] == "COMPLETE"]
    assert done[0]["params"] == s["baseline"]  # the study starts from what it must beat
    best = None
    for t in done:
        assert t["flags"] == tune.to_flags(t["params"], 3)
        capped = s["stop_at_best"] and best is not None
        assert t["budget_minutes"] == (min(s["max_minutes"], best) if capped else s["max_minutes"])
        if t["reached"]:  # stopped at the bar, inside the trial's budget
            assert t["value"] == t["training_minutes"] <= t["budget_minutes"]
            best = t["value"] if best is None else min(best, t["value"])
        else:
            assert t["value"] == 2.0 * s["max_minutes"]
            assert t["training_minutes"] >= t["budget_minutes"]
        parts = sum(t["time_s"][k] for k in ("env", "rollout_other", "learner"))
        assert 0.99 * t["time_s"]["training"] <= parts <= t["time_s"]["training"]
    if best is None:  # no trial reached the bar
        assert res["best"] is None
    else:
        assert res["best"]["value"] == best and res["best"]["reached"]
    assert len(done) == int(res["command"].split("--trials ")[1].split()[0])
