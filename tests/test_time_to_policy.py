"""benchmarks/time_to_policy.py: the bar, the stop rule and the record."""

import json
import sys
from pathlib import Path

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


def test_a_run_stops_at_the_bar_and_records_where_the_time_went(tmp_path):
    out = tmp_path / "ttp.json"
    tiny = ["--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
            "--hidden", "16", "--total-timesteps", "1200", "--episode-duration", "20"]  # fmt: skip
    flags = ["--recipe", "residual_apf", "--episodes", "2", "--check-every", "384"]
    rec = ttp.main([*flags, "--out", str(out), "--run-dir", str(tmp_path / "run"), "--", *tiny])
    assert json.loads(out.read_text())["agent_steps"] == rec["agent_steps"]
    checks = rec["checks"]
    # It stopped at the first check that cleared the bar, or ran out of steps without one.
    hits = [c["reached"] for c in checks]
    assert hits.count(True) <= 1 and (not any(hits) or hits[-1])
    assert rec["reached"] == any(hits)
    t = rec["time_s"]
    assert t["env"] > 0 and t["learner"] > 0 and t["rollout_other"] > 0 and t["evaluation"] > 0
    # The checks are evaluation time, not training time.
    assert t["env"] + t["rollout_other"] + t["learner"] <= t["training"] + 1e-6
    with pytest.raises(SystemExit):  # no silent overwrite
        ttp.main(["--recipe", "residual_apf", "--out", str(out)])
    other = tmp_path / "other.json"  # nor of the run folder: refused before any episode
    with pytest.raises(SystemExit, match="is not empty"):
        ttp.main([*flags, "--out", str(other), "--run-dir", str(tmp_path / "run"), "--", *tiny])
    assert not other.exists()


RECORDS = sorted((ROOT / "benchmarks" / "results").glob("time_to_policy_*.json"))


def test_the_residual_recipe_has_a_committed_record():
    assert ROOT / "benchmarks/results/time_to_policy_residual_apf.json" in RECORDS


@pytest.mark.parametrize("path", RECORDS, ids=lambda p: p.stem)
def test_a_committed_record_is_consistent(path):
    """A committed result file: its stop is the first check that clears its own bar."""
    rec = json.loads(path.read_text())
    b = rec["bar"]
    bar = ttp.Bar(
        episodes=b["episodes"],
        loss_of_separation=b["loss_of_separation"],
        max_deviation=b["max_deviation"],
        shipped=b["shipped"],
    )
    verdicts = [ttp.reached(c, bar) for c in rec["checks"]]
    assert [c["reached"] for c in rec["checks"]] == verdicts
    assert rec["reached"] == any(verdicts)
    assert verdicts.count(True) <= 1 and (not any(verdicts) or verdicts[-1])  # stops there
    last = rec["checks"][-1]
    assert (rec["agent_steps"], rec["training_minutes"]) == pytest.approx(
        (last["agent_steps"], last["training_minutes"])
    )
    t = rec["time_s"]
    parts = t["env"] + t["rollout_other"] + t["learner"]  # the rest: checkpoints, logging
    assert 0.99 * t["training"] <= parts <= t["training"]
    assert not rec["apf_clears_bar"]  # else the bar measures nothing
