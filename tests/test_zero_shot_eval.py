"""uasep-eval flies a checkpoint zero-shot beside the APF: each observes with its own layout."""

import json

from uasep_env.evaluation import main


def _run(tmp_path, name, *argv):
    out = tmp_path / f"{name}.json"
    code = main([*argv, "--episodes", "1", "--quiet", "--json", str(out)])
    assert code == 0
    return json.loads(out.read_text())


def test_a_checkpoint_beside_the_apf_at_eight_uavs(tmp_path, capsys):
    both = _run(tmp_path, "both", "--policy", "ppo_shared,apf", "--config", "n_uavs=8")
    assert capsys.readouterr().err == ""  # --quiet: no note
    # (in the episodes of the version ppo_shared was trained in, the current one)
    alone = _run(tmp_path, "apf", "--policy", "apf", "--config", "n_uavs=8")
    explicit = _run(
        tmp_path, "explicit", "--policy", "ppo_shared", "--config", "n_uavs=8",
        "--config", "observation.k_uavs=2", "--config", "observation.k_obstacles=1",
    )  # fmt: skip
    # The APF observes the environment as given: its figures are those of the APF alone.
    assert both["results"]["apf"] == alone["results"]["apf"]
    assert both["config"] == alone["config"]
    # The checkpoint observes with its training layout: the explicit K run's figures.
    assert both["results"]["ppo_shared"] == explicit["results"]["ppo_shared"]
    assert both["observations"]["ppo_shared"] == explicit["config"]["observation"]
    assert "observations" not in alone and "observations" not in explicit
    assert both["config"]["observation"]["k_uavs"] is None  # the APF's, unchanged


def test_the_note_names_the_layout_on_stderr_only(tmp_path, capsys):
    out = tmp_path / "run.json"
    assert main(["--policy", "ppo_shared", "--config", "n_uavs=4", "--episodes", "1",
                 "--json", str(out)]) == 0  # fmt: skip
    captured = capsys.readouterr()
    assert "ppo_shared observes with its training observation (k_uavs=2, k_obstacles=1)" in (
        captured.err
    )
    assert "observes" not in captured.out
