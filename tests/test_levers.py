"""``baselines/levers.py``: the levers' seed studies side by side, from their JSON."""

import json
import runpy
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOL = runpy.run_path(str(ROOT / "baselines" / "levers.py"))


def _results(tmp_path: Path) -> Path:
    results = tmp_path / "results"
    (results / "bench").mkdir(parents=True)
    shutil.copy(ROOT / "baselines/results/bench/bench.json", results / "bench" / "bench.json")
    for name in ("seeds_residual_apf_lean_v3", "seeds_lagrangian_residual_lean_v3"):
        shutil.copy(ROOT / f"baselines/results/{name}.json", results / f"{name}.json")
    return results


def test_a_lever_is_shown_beside_its_reference_and_the_best_classical_controller(tmp_path):
    results = _results(tmp_path)
    ref = json.loads((results / "seeds_residual_apf_lean_v3.json").read_text())
    lever = json.loads(json.dumps(ref))
    dev = lever["across_seeds"]["episode.max_deviation"]
    dev.update(iqm=dev["iqm"] * 0.5, ci_low=1.0, ci_high=2.0)
    (results / "seeds_lever_mvp_base_v3.json").write_text(json.dumps(lever))
    text = TOOL["render"](results)
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("|")}
    assert "-50%" in rows["residual on MVP (region)"]  # its deviation against its reference's
    assert "--action-mode residual_mvp_region" in rows["residual on MVP (region)"]
    assert "8.5 [1.0, 2.0]" in rows["residual on MVP (region)"]
    assert "21.4 [20.6, 22.1]" in rows["mvp-region (the leaderboard's best classical controller)"]
    # The studies not trained are named, not shown as numbers.
    assert "Not trained yet: seeds_lever_deviation_v3" in text
    assert "seeds_lever_mvp_base_v3" not in text.split("Not trained yet:")[1]


def test_the_apf_under_the_shield_is_changed_at_times():
    n = TOOL["interventions"](2)
    assert 0.0 < n < 1000.0  # interventions per agent-episode of 1,000 steps


def test_a_negative_count_is_refused_in_one_line(capsys):
    with pytest.raises(SystemExit):
        TOOL["main"](["--interventions", "-1"])
    assert "--interventions: must be >= 0, got -1" in capsys.readouterr().err
