"""train/reproduce.py: a chosen checkpoint retrained from its seed is the same, bit for bit."""

import json
import os
import subprocess
import sys

import pytest
from conftest import ROOT

from uasep_env import make_config
from uasep_env.evaluation import evaluate
from uasep_env.runtime.jsonio import dumps

pytest.importorskip("stable_baselines3")
sys.path.insert(0, str(ROOT / "train"))
import reproduce
import seeds as seeds_driver

# A tiny recipe run on the `random` scenario (the held-out bank's), checkpoints every 240
# agent-steps; --total-timesteps is the script's to set.
TINY = [
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1",
    "--hidden", "16", "--episode-duration", "10", "--checkpoint-every", "240",
    "--eval-episodes", "1",
]  # fmt: skip
BANK = {"first": 5_000_000, "count": 2}


def _original(tmp_path):
    """Seed 1 of a 'seeds run', trained to 1,200 agent-steps; its middle checkpoint chosen."""
    run = tmp_path / "orig" / "seed_1"
    cmd = reproduce.train_command("shared", run, 1, 1199, TINY, {})
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    subprocess.run(cmd, check=True, env=env, capture_output=True, cwd=ROOT)
    steps = sorted(int(p.name.removeprefix("step_")) for p in run.glob("checkpoints/step_*"))
    chosen = steps[len(steps) // 2]
    policy = run / "checkpoints" / f"step_{chosen}" / "policy.zip"
    # What train/seeds.py records of the recipe: the options in the checkpoint.
    (tmp_path / "orig" / "seed_0").mkdir()
    (tmp_path / "orig" / "seed_0" / "selected.zip").write_bytes(policy.read_bytes())
    seeds = list(range(BANK["first"], BANK["first"] + BANK["count"]))
    result = evaluate({"seed_1": str(policy)}, make_config(scenario="random"), seeds)
    report = {
        "recipe": "shared",
        "recipe_args": seeds_driver.recipe_args(tmp_path / "orig"),
        "held_out_seeds": BANK,
        "per_seed": {"seed_1": json.loads(dumps(result.results["seed_1"].aggregate))},
        "shipped": {"seed": 1, "validation": {"seeds": [
            {"seed": 1, "policy": f"seed_1/checkpoints/step_{chosen}/policy.zip",
             "agent_steps": chosen}]}},
        "training": {"seed_1": {"agent_steps": 1200, "wall_s": 3.0}},
    }  # fmt: skip
    path = tmp_path / "seeds.json"
    path.write_text(json.dumps(report))
    return path, report, chosen


def test_a_chosen_checkpoint_is_retrained_bit_for_bit_and_a_difference_fails(tmp_path, capsys):
    path, report, chosen = _original(tmp_path)
    assert report["recipe_args"]["n_envs"] == 2 and "out_dir" not in report["recipe_args"]
    ship = tmp_path / "ship" / "policy.zip"
    # No recipe flags: the report's recorded options are the recipe's, not today's defaults.
    argv = [str(path), "--out-dir", str(tmp_path / "repro"), "--ship-to", str(ship)]
    record = reproduce.main(argv)
    assert record["held_out"]["identical"] and record["agent_steps"] == chosen
    assert "reproduced: seed 1's checkpoint" in capsys.readouterr().out
    assert ship.read_bytes() == (tmp_path / "repro" / record["checkpoint"]).read_bytes()
    side = json.loads(reproduce.sidecar(ship).read_text())
    assert side["original_training"] == {"agent_steps": 1200, "wall_s": 3.0}
    # Shipping again needs --force.
    with pytest.raises(SystemExit):
        reproduce.main(argv)
    assert "exists (pass --force" in capsys.readouterr().err

    # One published figure off by a hair: not reproduced, nothing shipped (no retraining:
    # the run folder holds the checkpoint).
    report["per_seed"]["seed_1"]["episode.max_deviation"]["sum"] += 1e-9
    path.write_text(json.dumps(report))
    other = tmp_path / "other.zip"
    argv = [str(path), "--out-dir", str(tmp_path / "repro"), "--ship-to", str(other)]
    with pytest.raises(SystemExit) as e:
        reproduce.main(argv)
    assert e.value.code == 1 and not other.exists()
    assert "episode.max_deviation.sum" in capsys.readouterr().out
    saved = json.loads((tmp_path / "repro" / "reproduction.json").read_text())
    assert saved["held_out"]["differences"] and not saved["held_out"]["identical"]


def test_a_folder_without_the_checkpoint_is_not_resumed(tmp_path, capsys):
    report = {"recipe": "shared", "held_out_seeds": BANK, "per_seed": {"seed_0": {}},
              "shipped": {"seed": 0, "validation": {"seeds": [
                  {"seed": 0, "policy": "seed_0/checkpoints/step_96/policy.zip",
                   "agent_steps": 96}]}}}  # fmt: skip
    path = tmp_path / "seeds.json"
    path.write_text(json.dumps(report))
    (tmp_path / "r" / "seed_0").mkdir(parents=True)
    with pytest.raises(SystemExit):
        reproduce.main([str(path), "--out-dir", str(tmp_path / "r")])
    assert "not bit-exact" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        reproduce.main([str(path), "--out-dir", str(tmp_path / "r"), "--seed", "4"])
    assert "--seed 4: the report has seeds [0]" in capsys.readouterr().err
    report["shipped"]["validation"]["seeds"][0]["policy"] = "seed_0/policy.zip"
    path.write_text(json.dumps(report))
    with pytest.raises(SystemExit):
        reproduce.main([str(path), "--out-dir", str(tmp_path / "r")])
    assert "not a step checkpoint" in capsys.readouterr().err
    # Recorded options that are not flag values: refused before anything trains.
    report["shipped"]["validation"]["seeds"][0]["policy"] = "seed_0/checkpoints/step_96/p.zip"
    for bad in ([1], {"n_envs": [1, 2]}):
        path.write_text(json.dumps({**report, "recipe_args": bad}))
        with pytest.raises(SystemExit):
            reproduce.main([str(path), "--out-dir", str(tmp_path / "fresh")])
        assert "recipe_args is not a table" in capsys.readouterr().err
        assert not (tmp_path / "fresh").exists()


def test_the_training_command_writes_out_the_reports_options_and_the_flags_win(tmp_path):
    options = {"n_envs": 7, "norm_obs": False, "learning_rate": 2.5e-4, "seed": 9,
               "out_dir": "elsewhere", "max_minutes": 1.0}  # fmt: skip
    cmd = reproduce.train_command("shared", tmp_path, 1, 99, ["--n-envs", "3"], options)
    text = " ".join(cmd)
    assert "--n-envs 7 --no-norm-obs --learning-rate 0.00025 --n-envs 3" in text
    # The run's own fields and the budget are this script's: seed 1000, no wall budget.
    assert "elsewhere" not in text and cmd.count("--seed") == 1 and "--seed 1000" in text
    assert cmd.count("--max-minutes") == 1 and "--max-minutes 100000" in text
