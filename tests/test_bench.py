"""Tests of ``uasep-bench`` (uasep_env.benchmark): rows, equal safety, bad input, resume, workers.

Tiny suites: 2-4 episodes per bank, 20 s episodes (``--config episode_duration=20``).
"""

import json
import math
import sys
import textwrap

import numpy as np
import pytest

import uasep_env.evaluation
from uasep_env import make_config
from uasep_env.benchmark import main
from uasep_env.benchmark.front import deviation_at_budget
from uasep_env.benchmark.methods import METHODS
from uasep_env.policies import POLICIES, make_policy, shipped_policy_path

SHORT = ["--config", "episode_duration=20", "--no-figure", "--quiet"]


def _board(out):
    board = json.loads((out / "bench.json").read_text())
    board.pop("command")  # names the output folder
    return board


def test_row_equals_uasep_eval(tmp_path):
    """A row's numbers are uasep-eval's on the same seeds and config."""
    ev = tmp_path / "eval.json"
    args = ["--policy", "apf,zero", "--scenario", "random", "--seed", "5000000"]
    rc = uasep_env.evaluation.main([*args, "--episodes", "3", "--config", "episode_duration=20",
                                    "--json", str(ev), "--quiet"])  # fmt: skip
    assert rc == 0
    out = tmp_path / "bench"
    rc = main(["--policy", "apf,zero", "--banks", "held_out", "--episodes", "3", "--no-front",
               "--out", str(out), *SHORT])  # fmt: skip
    assert rc == 0
    evaluated = json.loads(ev.read_text())
    board = _board(out)
    assert board["banks"]["held_out"]["seeds"] == {"first": 5_000_000, "count": 3}
    assert board["banks"]["held_out"]["config"] == evaluated["config"]
    for label in ("apf", "zero"):
        agg = evaluated["results"][label]["aggregate"]
        row = board["results"]["held_out"][label]["default"]
        for col, key in (("collision", "collision"), ("loss_of_separation", "loss_of_separation")):
            for f in ("rate", "ci_low", "ci_high", "successes", "n"):
                assert row[col][f] == agg[f"episode.{key}"][f], (label, col, f)
        for col, key in (("max_deviation", "max_deviation"),
                         ("conflict_time", "max_conflict_duration"), ("cost", "cost")):  # fmt: skip
            for f in ("mean", "ci_low", "ci_high", "n_valid"):
                assert row[col][f] == agg[f"episode.{key}"][f], (label, col, f)


def _pt(value, los, dev, collision=0.0):
    return {"value": value, "loss_of_separation": los, "max_deviation": dev, "collision": collision}


FRONT = [
    _pt(0.5, 0.4, 2.0),
    _pt(1.0, 0.2, 4.0),
    _pt(1.5, 0.2, 5.0),  # dominated by 1.0: same rate, more deviation
    _pt(2.0, 0.1, 6.0),
    _pt(3.0, 0.0, 9.0, collision=0.05),  # the only setting within 0 collides: not eligible
]


@pytest.mark.parametrize(
    ("budget", "deviation", "setting"),
    [
        (0.15, 5.0, [1.0, 2.0]),  # half way from 4 m (rate 0.2) to 6 m (rate 0.1)
        (0.1, 6.0, 2.0),
        (0.3, 3.0, [0.5, 1.0]),
        (0.5, 2.0, 0.5),  # every setting within: the cheapest
    ],
)
def test_equal_safety_interpolates_along_the_front(budget, deviation, setting):
    eq = deviation_at_budget(FRONT, budget)
    assert eq["deviation"] == pytest.approx(deviation)
    assert eq["setting"] == setting


def test_equal_safety_needs_a_collision_free_setting_within_the_budget():
    eq = deviation_at_budget(FRONT, 0.0)
    assert eq["deviation"] is None and "0.1 is over the budget" in eq["reason"]
    eq = deviation_at_budget([_pt(1.0, 0.0, 3.0, collision=0.1)], 0.5)
    assert eq["deviation"] is None and "collision" in eq["reason"]
    assert deviation_at_budget([_pt(None, 0.2, 3.0)], 0.2) == {"deviation": 3.0, "setting": None}


def _nan_module(tmp_path, monkeypatch):
    (tmp_path / "nan_ctrl.py").write_text(
        textwrap.dedent("""
        import numpy as np

        class NaNPolicy:
            def __call__(self, obs):
                return np.full((*np.shape(obs)[:-1], 3), np.nan)

            def reset(self):
                pass

        def make(config):
            return NaNPolicy()
    """)
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "nan_ctrl", raising=False)


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--policy", "apff"], "'apff'"),
        (["--policy", "nosuchmodule:make"], "'nosuchmodule:make'"),
        (["--policy", "apf+nosuchshield"], "'apf+nosuchshield'"),
        (["--banks", "held_out,moon"], "'moon'"),
        (["--budget", "1.5"], "'1.5'"),
        (["--budget", "-0.1"], "'-0.1'"),
        (["--budget", "nan"], "'nan'"),
        (["--config", "episode_duration=-1"], "episode_duration"),
        (["--policy", "nan_ctrl:make"], "'nan_ctrl:make'"),
    ],
)
def test_bad_input_is_one_line_naming_it(tmp_path, monkeypatch, capsys, args, named):
    _nan_module(tmp_path, monkeypatch)
    argv = ["--banks", "held_out", "--episodes", "2", "--no-front", "--out", str(tmp_path / "o")]
    rc = main([*argv, *SHORT, *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and named in err, err
    if "nan_ctrl" in named:
        assert "non-finite" in err


def test_interrupted_suite_resumes_to_the_same_json(tmp_path, monkeypatch):
    argv = ["--policy", "apf,zero", "--banks", "held_out", "--episodes", "2", *SHORT]
    whole = tmp_path / "whole"
    assert main([*argv, "--out", str(whole)]) == 0

    real, calls = uasep_env.evaluation.evaluate, []

    def interrupted(*a, **k):
        calls.append(a[0])
        if len(calls) == 2:  # apf's cells (its default and its sweep) are written
            raise KeyboardInterrupt
        return real(*a, **k)

    cut = tmp_path / "cut"
    monkeypatch.setattr(uasep_env.evaluation, "evaluate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        main([*argv, "--out", str(cut)])
    assert len(list((cut / "cells").rglob("*.json"))) == 9 and not (cut / "bench.json").exists()
    calls.clear()

    def counted(*a, **k):
        calls.append(a[0])
        return real(*a, **k)

    monkeypatch.setattr(uasep_env.evaluation, "evaluate", counted)
    assert main([*argv, "--out", str(cut), "--resume"]) == 0
    assert [list(c) for c in calls] == [["default"]]  # only zero's cell was left
    assert _board(cut) == _board(whole)
    calls.clear()
    assert main([*argv, "--out", str(cut)]) == 0 and calls == []  # all finished: nothing runs
    # Another suite's settings in the same folder are refused, not mixed in.
    rc = main([*argv[:-4], "--config", "episode_duration=30", "--no-figure", "--quiet",
               "--out", str(cut)])  # fmt: skip
    assert rc == 2


def test_workers_and_ray_give_the_same_numbers(tmp_path):
    argv = ["--policy", "apf,zero", "--banks", "held_out", "--episodes", "4", "--no-front", *SHORT]
    boards = {}
    for name, extra in (("one", ["--workers", "1"]), ("two", ["--workers", "2"])):
        assert main([*argv, *extra, "--out", str(tmp_path / name)]) == 0
        boards[name] = _board(tmp_path / name)
    assert boards["one"] == boards["two"]
    pytest.importorskip("ray")
    assert main([*argv, "--ray", "--out", str(tmp_path / "ray")]) == 0
    assert _board(tmp_path / "ray") == boards["one"]


def _observations():
    """Observations along collision courses, obstacles near and far (the margins matter)."""
    from uasep_env.envs.core import EnvCore

    cfg = make_config(scenario="collision_head_on", episode_duration=60.0)
    core = EnvCore(cfg, n_envs=4)
    obs, policy, seen = core.reset(seed=[1, 2, 3, 4]), make_policy("apf", cfg), []
    for _ in range(cfg.max_steps):
        seen.append(obs)
        obs = core.step(policy(obs)).obs
    return cfg, np.concatenate(seen[::5])


@pytest.mark.parametrize("method", [m for m in METHODS if m.policy_name], ids=lambda m: m.name)
def test_a_sweep_passes_through_its_policy_default(method):
    """A front's default point is the row's policy (the row stands for it on the front)."""
    name = method.policy_name
    if name not in POLICIES and shipped_policy_path(name) is None:
        pytest.skip(f"{name} is not shipped")
    cfg, obs = _observations()
    assert make_config(cfg, **method.config(method.default)) == cfg
    swept, named = method.policy(cfg, method.default), make_policy(name, cfg)
    swept.reset()
    named.reset()
    np.testing.assert_array_equal(swept(obs), named(obs))
    assert math.isfinite(method.default) and method.default in method.values


def _stats(coll, coll_hi, los, los_hi, dev, dev_lo, dev_hi):
    return {
        "collision": {"rate": coll, "ci_low": 0.0, "ci_high": coll_hi},
        "loss_of_separation": {"rate": los, "ci_low": max(0.0, los - 0.02), "ci_high": los_hi},
        "max_deviation": {"mean": dev, "ci_low": dev_lo, "ci_high": dev_hi},
    }


def _verdict_board(rows_by_bank):
    return {
        "banks": {
            b: {"title": f"bank {b}", "budget": {"loss_of_separation": 0.02}} for b in rows_by_bank
        },
        "results": {
            b: {
                label: {"default": st, "equal_safety": {"deviation": eq}}
                for label, (st, eq) in rows.items()
            }
            for b, rows in rows_by_bank.items()
        },
    }


def test_verdict_names_the_safest_the_cheapest_and_who_beats_the_apf():
    from uasep_env.benchmark import verdict

    held = {
        "apf": (_stats(0.0, 0.01, 0.02, 0.04, 36.0, 34.0, 38.0), 36.0),
        "orca": (_stats(0.0, 0.01, 0.01, 0.03, 17.0, 16.0, 18.0), 17.0),
        "mvp": (_stats(0.05, 0.08, 0.60, 0.65, 9.0, 8.5, 9.5), None),
    }
    real = {
        "apf": (_stats(0.01, 0.03, 0.09, 0.13, 26.0, 25.0, 27.0), 26.0),
        "orca": (_stats(0.06, 0.10, 0.80, 0.85, 10.0, 9.0, 11.0), None),
        "mvp": (_stats(0.08, 0.12, 0.90, 0.93, 9.0, 8.5, 9.5), None),
    }
    board = _verdict_board({"held_out": held, "real_traffic": real})
    assert verdict.safest(board["results"]["held_out"]) == ("orca", ["apf"])
    assert verdict.cheapest(board["results"]["held_out"]) == "orca"
    text = verdict.sentences(board)
    assert len(text) == 3  # synthetic, real traffic, the APF
    assert text[0].startswith("Synthetic encounters: on bank held_out the safest at its ")
    assert "**orca**" in text[0] and "apf not told apart from it" in text[0]
    assert "is **orca**, 17.0 m of max deviation (the APF 36.0 m)" in text[0]
    # The order changes on real traffic: the APF is safest and cheapest there.
    assert text[1].startswith(
        "Real traffic: on bank real_traffic the safest at its default is **apf**"
    )
    assert (
        "cheapest at equal safety (along each front;" in text[1] and "is **apf**, 26.0 m" in text[1]
    )
    assert text[-1].endswith("on bank held_out: orca.")
    # A row as safe but whose deviation interval touches the APF's does not beat it.
    held["orca"] = (_stats(0.0, 0.01, 0.01, 0.03, 33.0, 31.0, 34.5), 33.0)
    assert "not beaten" in verdict.sentences(_verdict_board({"held_out": held}))[-1]
    # Rows played in an earlier env version are left out of the verdict.
    board = _verdict_board({"held_out": held})
    board["versions"] = {"env": 3}
    board["results"]["held_out"]["orca"]["env_version"] = 2
    assert "orca" not in " ".join(verdict.sentences(board))


def test_front_banks_sweep_only_those_banks(tmp_path, capsys):
    out = tmp_path / "b"
    argv = ["--policy", "apf", "--banks", "held_out,collision_head_on", "--episodes", "2",
            "--front-banks", "held_out", "--out", str(out), *SHORT]  # fmt: skip
    assert main(argv) == 0
    board = _board(out)
    assert board["settings"]["front_banks"] == ["held_out"]
    swept = board["results"]["held_out"]["apf"]
    single = board["results"]["collision_head_on"]["apf"]
    assert len(swept["front"]) == len(METHODS[0].values) and swept["front_kind"] == "swept"
    assert len(single["front"]) == 1 and single["front_kind"].startswith("single point")
    assert "swept on held_out" in (out / "bench.md").read_text()
    # A front bank outside --banks is a one-line error naming it.
    assert main([*argv[:6], "--front-banks", "uavs_8", "--out", str(tmp_path / "x"), *SHORT]) == 2
    assert "uavs_8 not in --banks" in capsys.readouterr().err


def test_a_checkpoint_replaced_under_the_same_path_is_not_read_from_its_old_cells(tmp_path):
    """The cell key holds the checkpoint's digest: a retrained file is refused, not reused."""
    import shutil

    from conftest import ROOT

    seeds = ROOT / "baselines" / "seeds" / "shared"
    ck = tmp_path / "policy.zip"
    shutil.copyfile(seeds / "seed_0" / "selected.zip", ck)
    argv = ["--policy", str(ck), "--banks", "held_out", "--episodes", "2", "--no-front",
            "--out", str(tmp_path / "bench"), *SHORT]  # fmt: skip
    assert main(argv) == 0
    assert main(argv) == 0  # the same file: its cells are read back
    shutil.copyfile(seeds / "seed_2" / "selected.zip", ck)  # retrained, same path
    assert main(argv) == 2


def test_verdict_says_whether_a_learned_policy_meets_the_best_classical_controller():
    from uasep_env.benchmark import verdict

    safe = _stats(0.0, 0.01, 0.0, 0.01, 23.0, 22.0, 24.0)

    def board(learned_real, learned_dev=(17.0, 16.5, 17.5)):
        rows = {
            "apf": (safe, 23.0),
            "mvp-region": (_stats(0.0, 0.01, 0.0, 0.01, 21.4, 20.6, 22.1), 21.4),
            "mvp": (_stats(0.05, 0.08, 0.6, 0.65, 9.0, 8.5, 9.5), None),  # less safe
            "orca": (_stats(0.0, 0.01, 0.0, 0.01, 12.0, 11.5, 12.5), 12.0),  # but on real traffic
            "ppo_residual_apf": (_stats(0.0, 0.01, 0.0, 0.01, *learned_dev), 17.0),
        }
        real = dict(rows, ppo_residual_apf=(learned_real, None),
                    orca=(_stats(0.02, 0.05, 0.2, 0.25, 14.0, 13.0, 15.0), None))  # fmt: skip
        banks = {"held_out": rows, "uavs_8": rows, "uavs_32": rows, "real_traffic": real}
        return _verdict_board(banks)

    good = board(safe)
    # The least deviation among the safest on every bank: not orca, less safe on real traffic.
    assert verdict.best_classical(good) == "mvp-region"
    assert verdict.meets(good, "ppo_residual_apf", "mvp-region") == []
    text = verdict.sentences(good)[-1]
    assert text.startswith("Learned policies against the best classical controller, "
                           "**mvp-region**")  # fmt: skip
    assert "**ppo_residual_apf** meets it (17.0 [16.5, 17.5] m" in text
    # Less safe on real traffic (the upper end above the controller's): not met, said why.
    worse = board(_stats(0.0, 0.01, 0.08, 0.12, 20.0, 19.0, 21.0))
    text = verdict.sentences(worse)[-1]
    assert "none meets it (ppo_residual_apf: LoS on real_traffic 8.0% [6.0%, 12.0%]" in text
    # As safe, but its deviation interval touches the controller's: not closer.
    close = board(safe, learned_dev=(20.0, 19.0, 20.7))
    assert verdict.meets(close, "ppo_residual_apf", "mvp-region") == [
        "max deviation on held_out 20.0 [19.0, 20.7] against 21.4 [20.6, 22.1] m"
    ]


def test_label_equals_spec_names_a_row(tmp_path, capsys):
    """Two checkpoints of one file name: refused as one row name, told apart by LABEL=SPEC."""
    from conftest import ROOT

    seeds = ROOT / "baselines" / "seeds" / "lever_mvp_base_v3"
    a, b = (seeds / f"seed_{k}" / "selected.zip" for k in (0, 1))
    out = tmp_path / "bench"
    argv = ["--banks", "held_out", "--episodes", "2", "--no-front", "--out", str(out), *SHORT]
    assert main(["--policy", f"{a},{b}", *argv]) == 2
    assert "share a row name" in capsys.readouterr().err
    assert main(["--policy", f"first={a},second={b}+cbf", *argv]) == 0
    rows = set(_board(out)["results"]["held_out"])
    assert rows == {"first", "second+cbf"}
    capsys.readouterr()
    assert main(["--policy", f"={a}", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "LABEL=SPEC" in err
