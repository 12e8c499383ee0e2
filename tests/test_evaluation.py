"""Tests of the headless evaluation tool (``uasep-eval`` / ``uasep_env.evaluation``)."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S, ROOT, run_in_repo

import uasep_env
from uasep_env.config import make_config
from uasep_env.evaluation import (
    build_config,
    default_batch_size,
    evaluate,
    main,
    parse_config_overrides,
    result_to_json,
    summary_rows,
)

#: Short episodes keep the tests fast; statistics start after 5 s.
SHORT = ["--config", "episode_duration=12", "--settle-time", "5"]


def _strict_json(text: str):
    def reject(name):
        raise ValueError(f"non-strict JSON constant {name}")

    return json.loads(text, parse_constant=reject)


def _short_config(**kw):
    return make_config({"scenario": "paper", "episode_duration": 12.0, **kw})


def _same(a, b):
    """Results equal, NaN == NaN (compared through their strict JSON)."""
    return _strict_json(result_to_json({"r": a})) == _strict_json(result_to_json({"r": b}))


def test_cli_end_to_end_json_csv_plots(tmp_path, capsys):
    out_json = tmp_path / "out" / "res.json"
    out_csv = tmp_path / "res.csv"
    plots = tmp_path / "figs"
    rc = main(
        [
            "--policy",
            "apf",
            "--policy",
            "traditional-apf",
            "--episodes",
            "2",
            "--seed",
            "3",
            *SHORT,
            "--config",
            "noise.accel_std=0",
            "--json",
            str(out_json),
            "--csv",
            str(out_csv),
            "--plot",
            str(plots),
        ]
    )
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    # side-by-side summary on stdout
    header = next(line for line in captured.out.splitlines() if line.startswith("metric"))
    for label in ("apf", "traditional-apf"):
        assert label in header
    assert "min UAV-UAV separation" in captured.out
    assert "acc std z" in captured.out

    data = _strict_json(out_json.read_text())
    assert data["version"] == uasep_env.__version__
    assert data["config"]["episode_duration"] == 12.0
    assert data["config"]["noise"]["accel_std"] == 0
    assert data["config"]["scenario"] == "paper"
    assert data["policies"] == ["apf", "traditional-apf"]
    assert data["seeds"] == [3, 4]
    assert "episodes" not in data
    for label in data["policies"]:
        res = data["results"][label]
        assert [e["seed"] for e in res["episodes"]] == [3, 4]
        for e in res["episodes"]:
            assert set(e["metrics"]) >= {"episode", "uavs", "config"}
            assert len(e["metrics"]["uavs"]) == 3
        agg = res["aggregate"]
        assert agg["episode.min_uav_separation"]["n"] == 2
        assert agg["episode.collision"]["kind"] == "rate"
        assert "uav.uav_2.fluctuation.acc_std.z" in agg

    with out_csv.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 2
    assert {(r["policy"], r["seed"]) for r in rows} == {
        (p, s) for p in ("apf", "traditional-apf") for s in ("3", "4")
    }
    assert "episode.min_obstacle_distance" in rows[0]
    assert "uav.uav_2.timeline.t_leave" in rows[0]
    first = data["results"]["apf"]["episodes"][0]["metrics"]["episode"]
    assert float(rows[0]["episode.min_uav_separation"]) == pytest.approx(
        first["min_uav_separation"]
    )

    pngs = sorted(plots.glob("*.png"))
    assert len(pngs) == 5 * 2 + 1
    assert (plots / "acceleration_z_comparison.png").exists()
    assert (plots / "deviation_traditional-apf.png").exists()
    assert all(p.stat().st_size > 1000 for p in pngs)


@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_policies_share_the_scenario(scenario):
    cfg = _short_config(scenario=scenario)
    res = evaluate(["apf", "zero", "random"], cfg, [0, 1], keep_episodes=2)
    eps = res.episodes
    for k in range(2):
        ref = eps["apf"][k].record
        for label in ("zero", "random"):
            other = eps[label][k].record
            assert eps[label][k].seed == eps["apf"][k].seed
            assert eps[label][k].family == eps["apf"][k].family
            n = min(other.n_steps, ref.n_steps)  # an episode may end early (collision)
            np.testing.assert_array_equal(other.obstacle_pos[:n], ref.obstacle_pos[:n])
            np.testing.assert_array_equal(other.obstacle_active[:n], ref.obstacle_active[:n])
            np.testing.assert_array_equal(other.uav_pos[0], ref.uav_pos[0])
    if scenario == "random":  # different seeds give different encounters
        assert not np.array_equal(
            eps["apf"][0].record.obstacle_pos, eps["apf"][1].record.obstacle_pos
        )
    # the policies themselves behave differently
    assert not np.array_equal(eps["apf"][0].record.uav_acc, eps["zero"][0].record.uav_acc)


def test_workers_do_not_change_results(tmp_path):
    # 2 policies x 2 chunks of seeds, reassembled in seed order; "random" is stochastic
    def run(workers, path):
        rc = main(
            [
                "--policy",
                "apf,random",
                "--episodes",
                "3",
                "--batch-size",
                "2",
                *SHORT,
                "--workers",
                str(workers),
                "--json",
                str(path),
                "--quiet",
            ]
        )
        assert rc == 0
        return _strict_json(path.read_text())

    one = run(1, tmp_path / "w1.json")
    two = run(2, tmp_path / "w2.json")
    assert one["settings"]["workers"] == 1 and two["settings"]["workers"] == 2
    assert one["results"] == two["results"]
    assert one["seeds"] == two["seeds"] == [0, 1, 2]
    assert [e["seed"] for e in two["results"]["random"]["episodes"]] == [0, 1, 2]


def test_default_batch_size_ignores_workers():
    assert default_batch_size(1) == 1
    assert default_batch_size(10) == 10
    assert default_batch_size(100) == 16
    assert default_batch_size(10_000) == 64
    a = evaluate(["random"], _short_config(), [0, 1], workers=1)
    b = evaluate(["random"], _short_config(), [0, 1], workers=2)
    assert a.settings.batch_size == b.settings.batch_size == 2
    assert _same(a.results, b.results)


def test_batch_size_does_not_change_results():
    # the chunking may follow the worker count: episodes must not depend on their batch
    cfg = _short_config(scenario="random")
    a = evaluate(["apf"], cfg, [5, 6, 7], batch_size=3)
    b = evaluate(["apf"], cfg, [5, 6, 7], batch_size=1)
    assert _same(a.results, b.results)


def test_result_json_is_strict_and_nan_becomes_null():
    cfg = _short_config()
    res = evaluate("zero", cfg, [0], settle_time=5.0, keep_episodes=1)
    assert res.episodes
    data = _strict_json(result_to_json(res))
    assert "episodes" not in data
    tl = data["results"]["zero"]["episodes"][0]["metrics"]["uavs"][0]["timeline"]
    # a coasting formation in 12 s: some timeline fields are undefined -> null, never NaN
    assert all(v is None or isinstance(v, (int, float, bool)) for v in tl.values())


def test_write_json_gzips_by_suffix_reproducibly(tmp_path):
    import gzip

    from uasep_env.evaluation import write_json

    res = evaluate("zero", _short_config(), [0], settle_time=5.0)
    plain = write_json(res, tmp_path / "r.json").read_bytes()
    packed = write_json(res, tmp_path / "sub" / "r.json.gz").read_bytes()
    assert packed[:2] == b"\x1f\x8b" and len(packed) < len(plain)
    assert gzip.decompress(packed) == plain
    assert write_json(res, tmp_path / "sub" / "r.json.gz").read_bytes() == packed  # same bytes


def test_summary_single_episode_shows_timeline_per_uav():
    res = evaluate(["apf", "zero"], _short_config(), [0], settle_time=5.0)
    rows = summary_rows(res)
    assert rows[0] == ["metric", "apf", "zero"]
    titles = [r[0] for r in rows]
    for name in ("uav_0", "uav_1", "uav_2"):
        assert f"{name} leave / resolved / back (s)" in titles
    assert all(len(r) == 3 for r in rows)


def test_parse_config_overrides():
    got = parse_config_overrides(
        [
            "noise.accel_std=0",
            "dt=0.1",
            "scenario=crossing",
            "obstacle.wind=[1, 0, 0]",
            "prediction.kalman=false",
            "noise.position_std=0.25",
        ]
    )
    assert got == {
        "noise": {"accel_std": 0, "position_std": 0.25},
        "dt": 0.1,
        "scenario": "crossing",
        "obstacle": {"wind": [1, 0, 0]},
        "prediction": {"kalman": False},
    }
    cfg = build_config("paper", ["noise.accel_std=0", "obstacle.wind=[1, 0, 0]"])
    assert cfg.noise.accel_std == 0.0
    assert cfg.obstacle.wind == (1.0, 0.0, 0.0)
    assert cfg.noise.position_std == make_config().noise.position_std
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_config_overrides(["dt"])
    with pytest.raises(ValueError, match="already set"):
        parse_config_overrides(["noise=false", "noise.accel_std=0"])
    with pytest.raises(TypeError, match="bogus"):
        build_config("paper", ["noise.bogus=1"])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--policy", "no-such-policy"], "no-such-policy"),
        (["--policy", "apf,nope"], "nope"),
        (["--config", "not_a_key=3"], "not_a_key"),
        (["--config", "noise.nope=3"], "noise.nope"),
        (["--config", "dt=-1"], "dt=-1"),
        (["--config", "dt"], "dt"),
        (["--config", "obstacle.wind=5"], "obstacle.wind=5"),
        (["--config", "obstacle.wind=null"], "obstacle.wind=None"),
        (["--episodes", "0"], "'0'"),
        (["--episodes", "many"], "many"),
        (["--workers", "0"], "--workers"),
        (["--scenario", "moon"], "moon"),
        (["--seed", "-3"], "-3"),
    ],
)
def test_bad_arguments_exit_2_naming_the_value(args, needle, capsys):
    rc = main([*args, "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err


@pytest.mark.parametrize("flag", ["--json", "--csv", "--plot"])
def test_bad_output_paths_fail_before_the_evaluation(flag, tmp_path, capsys, monkeypatch):
    """Issue 13 item 7: '--json afile/out.json' failed only after the whole evaluation."""
    import uasep_env.evaluation.cli as ev

    afile = tmp_path / "afile"
    afile.write_text("x")

    def boom(*args, **kwargs):
        raise AssertionError("evaluate() ran before the output paths were checked")

    monkeypatch.setattr(ev, "evaluate", boom)
    rc = main([flag, str(afile / "out.json"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"argument {flag}: cannot write" in err and "is not a directory" in err
    if flag != "--plot":
        rc = main([flag, str(tmp_path), "--quiet"])  # a folder where a file is expected
        assert rc == 2 and "is a directory" in capsys.readouterr().err
    else:
        rc = main([flag, str(afile), "--quiet"])  # a file where a folder is expected
        assert rc == 2 and "is not a directory" in capsys.readouterr().err


def test_argument_errors_are_one_line(capsys):
    """Issue 13 item 7: argparse printed the whole usage before the error."""
    for args in (["--episodes", "0"], ["--bogus"], ["--config", "dt=-1"]):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        assert err.startswith("uasep-eval: error: ")


def test_evaluate_rejects_bad_input():
    cfg = _short_config()
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        evaluate(["nope"], cfg, [0])
    with pytest.raises(ValueError, match="seeds"):
        evaluate(["apf"], cfg, [])
    with pytest.raises(ValueError, match="workers"):
        evaluate(["apf"], cfg, [0], workers=0)


def test_help_and_version(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--policy" in out and "--config" in out
    assert main(["--version"]) == 0
    assert uasep_env.__version__ in capsys.readouterr().out


def _env():
    return dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT))


def test_module_help_subprocess():
    out = run_in_repo("-m", "uasep_env.evaluation", "--help")
    assert out.returncode == 0, out.stderr
    assert "usage: uasep-eval" in out.stdout


def test_console_script_help():
    script = Path(sys.executable).parent / "uasep-eval"
    if not script.exists():
        pytest.skip("uasep-eval console script not installed in this environment")
    out = subprocess.run(
        [str(script), "--help"],
        cwd=ROOT,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert out.returncode == 0, out.stderr
    assert "--episodes" in out.stdout
    bad = subprocess.run(
        [str(script), "--policy", "nope", "--quiet"],
        cwd=ROOT,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert bad.returncode == 2
    assert "nope" in bad.stderr


@pytest.mark.parametrize("bad", [True, "", " ", 3])
def test_evaluate_rejects_a_bad_ray_address(bad):
    with pytest.raises(ValueError, match=r"ray: must be 'local' or a Ray address, got"):
        evaluate(["apf"], _short_config(), [0], ray=bad)


def test_scenario_brings_its_defaults_large_formation_flies_eight(tmp_path):
    """Issue 23 item 8: --scenario large_formation flew 3 UAVs; its gym id flies 8."""
    import gymnasium

    gym_cfg = gymnasium.make("uasep/LargeFormation-v3").unwrapped.config
    cfg = build_config("large_formation")
    assert (cfg.n_uavs, cfg.formation, cfg.n_obstacles) == (8, "wedge", 2)
    assert (gym_cfg.n_uavs, gym_cfg.formation, gym_cfg.n_obstacles) == (8, "wedge", 2)
    assert build_config("large_formation", ["n_uavs=6"]).n_uavs == 6  # overrides win
    assert build_config("paper").n_uavs == 3
    out = tmp_path / "lf.json"
    args = ["--scenario", "large_formation", "--config", "episode_duration=2", "--json", str(out)]
    assert main([*args, "--quiet"]) == 0
    assert json.loads(out.read_text())["config"]["n_uavs"] == 8


@pytest.mark.parametrize("scenario", ["random", "collision_head_on"])  # the last: ends in a crash
def test_episode_cost_in_the_table_csv_and_json(tmp_path, scenario):
    """Each episode's cost per UAV and for the team: the core's per-step costs, summed."""
    from uasep_env.envs.core import EnvCore
    from uasep_env.evaluation import format_summary, write_csv

    cfg = make_config(scenario=scenario, episode_duration=60.0)
    seeds = [5_000_000, 5_000_001]
    res = evaluate("zero", cfg, seeds)
    # the same episodes stepped by hand: each UAV's cost summed while its episode runs
    core = EnvCore(cfg, n_envs=len(seeds))
    core.reset(seed=seeds)
    done = np.zeros(len(seeds), dtype=bool)
    summed = np.zeros((len(seeds), cfg.n_uavs))
    while not done.all():
        step = core.step(np.zeros((len(seeds), cfg.n_uavs, 3)), active=~done)
        summed[~done] += step.cost[~done]
        done |= step.terminated | step.truncated
    assert summed.max() > 0  # the zero policy loses separation in the first encounter
    episodes = res.results["zero"].episodes
    for e, want in zip(episodes, summed, strict=True):
        assert [u.cost for u in e.metrics.uavs] == pytest.approx(want)
        assert e.metrics.episode.cost == pytest.approx(want.mean())
        assert e.metrics.episode.max_uav_cost == pytest.approx(want.max())
    agg = res.results["zero"].aggregate
    assert agg["episode.cost"]["mean"] == pytest.approx(summed.mean())
    assert agg["uav.uav_0.cost"]["ci_high"] >= agg["uav.uav_0.cost"]["mean"]
    # the JSON: per episode, per UAV and for the team, and the aggregate
    doc = _strict_json(result_to_json(res))["results"]["zero"]
    assert doc["episodes"][0]["metrics"]["episode"]["cost"] == pytest.approx(summed[0].mean())
    assert doc["episodes"][0]["metrics"]["uavs"][2]["cost"] == pytest.approx(summed[0, 2])
    assert "episode.max_uav_cost" in doc["aggregate"]
    # the CSV: one column per UAV and the team's
    with write_csv(res, tmp_path / "r.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert float(rows[0]["episode.cost"]) == pytest.approx(summed[0].mean())
    assert float(rows[0]["uav.uav_1.cost"]) == pytest.approx(summed[0, 1])
    assert float(rows[1]["episode.max_uav_cost"]) == pytest.approx(summed[1].max())
    # the table: the team's and the worst UAV's (mean ± half-width), and each UAV's
    titles = {r[0]: r[1] for r in summary_rows(res)}
    assert titles["episode cost, team mean"].startswith(f"{summed.mean():.2f} ")
    assert titles["episode cost, worst UAV"].startswith(f"{summed.max(axis=1).mean():.2f} ")
    assert titles["uav_0 episode cost"].startswith(f"{summed[:, 0].mean():.2f} ")
    assert "episode cost = a UAV's per-step costs summed" in format_summary(res)
