"""Env versions of learned policies: checkpoints play the env version they were trained in.

The policies shipped before ``-v3`` were trained in ``-v2`` (their files predate the recorded
``info["env_version"]``; kept in ``baselines/seeds/``, the residual one is :data:`V2`); the
``-v2`` ids and ``VERSION_DEFAULTS[2]`` still play its
episodes, and ``uasep-eval``, ``uasep-bench`` and ``uasep-report`` play a checkpoint in
its own version unless asked otherwise (issue 56).
"""

from __future__ import annotations

import dataclasses
import json
import warnings

import gymnasium
import numpy as np
import pytest
from conftest import ROOT

import uasep_env.evaluation
from uasep_env import make_config
from uasep_env.config import VERSION_DEFAULTS
from uasep_env.envs.core import EnvCore
from uasep_env.evaluation import evaluate
from uasep_env.policies import APF, APFGains, CheckpointError, load_policy
from uasep_env.policies.checkpoint import save_policy
from uasep_env.policies.checkpoint_reader import read_checkpoint
from uasep_env.policies.env_version import EnvVersionWarning, current_version, env_defaults_for
from uasep_env.registration import ENV_VERSION

#: The residual policy shipped in -v2 (its seed folder since the -v3 policies shipped).
V2 = ROOT / "baselines" / "seeds" / "residual_apf" / "seed_0" / "selected.zip"
SHIPPED = str(V2)
LABEL = V2.stem  # its row's name in uasep-bench (uasep-eval names it by its path)


def _copy(tmp_path, name: str, **info) -> str:
    """The -v2 checkpoint ``V2`` rewritten with ``info`` entries set."""
    meta, weights, mean, var = read_checkpoint(V2)
    meta = dataclasses.replace(meta, info={**meta.info, **info})
    return str(save_policy(tmp_path / f"{name}.zip", meta, weights, mean, var))


def _gym_rollout(env_id: str, steps: int = 40) -> list[np.ndarray]:
    env = gymnasium.make(env_id)
    cfg = env.unwrapped.config
    apf = APF(cfg, APFGains())
    obs, _ = env.reset(seed=3)
    out = [obs]
    for _ in range(steps):
        act = apf(obs.reshape(1, cfg.n_uavs, -1))[0].reshape(-1)
        obs, _, _, _, info = env.step(act)
        out += [obs, info["rewards"]]
    return out


def _core_rollout(cfg, steps: int = 40) -> list[np.ndarray]:
    core = EnvCore(cfg, n_envs=1)
    apf = APF(cfg, APFGains())
    obs = core.reset(seed=3)
    out = [obs[0].reshape(-1)]
    for _ in range(steps):
        res = core.step(apf(obs))
        obs = res.obs
        out += [obs[0].reshape(-1), np.asarray(res.rewards[0])]
    return out


def test_the_v2_ids_play_the_v2_episodes_bit_for_bit():
    v2 = make_config(VERSION_DEFAULTS[2], scenario="random")
    assert gymnasium.make("uasep/Formation-v2").unwrapped.config == v2
    gym_v2 = _gym_rollout("uasep/Formation-v2")
    for got, want in zip(gym_v2, _core_rollout(v2), strict=True):
        np.testing.assert_array_equal(got, want)
    gym_v3 = _gym_rollout(f"uasep/Formation-v{ENV_VERSION}")
    assert any(not np.array_equal(a, b) for a, b in zip(gym_v2, gym_v3, strict=True))


def test_old_files_say_v2_and_new_ones_record_the_current_version(tmp_path):
    assert current_version() == ENV_VERSION  # read below the registration's layer
    meta = read_checkpoint(V2)[0]
    assert "env_version" not in meta.info and meta.env_version == 2
    assert meta.env_config.prediction.fit == "enclosing"
    assert env_defaults_for(meta) == VERSION_DEFAULTS[2]
    fresh = read_checkpoint(_copy(tmp_path, "fresh"))[0]
    assert fresh.info["env_version"] == ENV_VERSION == fresh.env_version
    kept = read_checkpoint(_copy(tmp_path, "kept", env_version=2))[0]
    assert kept.env_version == 2  # a recorded version is kept


def test_an_unreproduced_version_is_refused_in_one_line(tmp_path, capsys):
    path = _copy(tmp_path, "old", env_version=1)
    with pytest.raises(CheckpointError, match=r"old\.zip: trained in env -v1, which"):
        env_defaults_for(read_checkpoint(path)[0], path)
    rc = uasep_env.evaluation.main(["--policy", f"{path},apf", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    assert "old.zip" in err and "-v1" in err
    bad = _copy(tmp_path, "bad", env_version="two")
    with pytest.raises(CheckpointError, match=r"info\.env_version must be an integer"):
        read_checkpoint(bad)


def _eval(tmp_path, capsys, *extra):
    out = tmp_path / "eval.json"
    rc = uasep_env.evaluation.main(
        ["--policy", f"{SHIPPED},apf", "--episodes", "2", "--json", str(out), *extra]
    )
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    return json.loads(out.read_text()), captured


def test_uasep_eval_plays_the_checkpoints_version(tmp_path, capsys):
    data, captured = _eval(tmp_path, capsys)
    line = (
        f"playing -v2 episodes: {SHIPPED} was trained in -v2 "
        f"(--env-version {ENV_VERSION} to play the current ones)"
    )
    assert line in captured.err
    assert data["env_version"] == 2 and data["trained_env_versions"] == {LABEL: 2}
    assert data["config"]["prediction"]["fit"] == "enclosing"
    header = next(ln for ln in captured.out.splitlines() if ln.startswith("metric"))
    assert header.split()[1:] == [LABEL, "(-v2)", "apf"]  # the checkpoint's label only
    # The APF beside it played the -v2 episodes, not the current ones.
    for version, same in ((2, True), (ENV_VERSION, False)):
        cfg = make_config(VERSION_DEFAULTS[version], scenario="paper")
        apf = json.loads(evaluate(["apf"], cfg, [0, 1]).to_json())["results"]["apf"]
        assert (apf["aggregate"] == data["results"]["apf"]["aggregate"]) is same


def test_uasep_eval_env_version_plays_the_current_with_a_warning(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error", EnvVersionWarning)  # the CLI's line says it instead
        data, captured = _eval(tmp_path, capsys, "--env-version", str(ENV_VERSION))
    assert data["env_version"] == ENV_VERSION
    assert data["config"]["prediction"]["fit"] == "calibrated"
    warned = [ln for ln in captured.err.splitlines() if "warning" in ln]
    assert len(warned) == 1
    assert SHIPPED in warned[0] and "-v2" in warned[0] and f"-v{ENV_VERSION}" in warned[0]


def test_checkpoints_of_different_versions_are_an_error(tmp_path, capsys):
    new = _copy(tmp_path, "new", env_version=ENV_VERSION)
    rc = uasep_env.evaluation.main(["--policy", f"{SHIPPED},{new}", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    assert f"{SHIPPED} (-v2)" in err and f"new.zip (-v{ENV_VERSION})" in err


def test_a_bad_env_version_is_one_line(capsys):
    rc = uasep_env.evaluation.main(["--policy", "apf", "--env-version", "9"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    assert "--env-version" in err and "'9'" in err


def test_load_policy_warns_in_another_env_version():
    with pytest.warns(UserWarning) as record:
        load_policy(SHIPPED, make_config(scenario="random"))
    assert len(record) == 1
    text = str(record[0].message)
    assert "selected.zip" in text and "-v2" in text
    assert "'enclosing'" in text and "'calibrated'" in text
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_policy(SHIPPED, make_config(VERSION_DEFAULTS[2], scenario="random"))
        load_policy(SHIPPED)  # its own config


def test_uasep_bench_plays_each_row_in_its_version(tmp_path):
    from uasep_env.benchmark import main
    from uasep_env.benchmark.banks import bank_config

    out = tmp_path / "bench"
    rc = main(["--policy", f"{SHIPPED},apf", "--banks", "held_out", "--episodes", "2",
               "--no-front", "--out", str(out), "--config", "episode_duration=20",
               "--no-figure", "--quiet"])  # fmt: skip
    assert rc == 0
    board = json.loads((out / "bench.json").read_text())
    rows = board["results"]["held_out"]
    assert rows[LABEL]["env_version"] == 2 and rows["apf"]["env_version"] == ENV_VERSION
    table = (out / "bench.md").read_text()
    assert "| env " in table and f"| {LABEL} " in table and "| -v2 " in table
    # The learned row is uasep-eval's on the -v2 bank.
    cfg = bank_config("held_out", {"episode_duration": 20}, version=2)
    assert cfg.prediction.fit == "enclosing"
    seeds = board["banks"]["held_out"]["seeds"]
    seeds = range(seeds["first"], seeds["first"] + 2)
    agg = evaluate({LABEL: SHIPPED}, cfg, seeds).results[LABEL].aggregate
    assert rows[LABEL]["default"]["max_deviation"]["mean"] == agg["episode.max_deviation"]["mean"]


def test_uasep_report_plays_a_checkpoint_in_its_version():
    from uasep_env.reporting.scaling import cell_config, parse_policies

    learned, apf = parse_policies([SHIPPED, "apf"])
    assert (learned.env_version, apf.env_version) == (2, None)
    assert cell_config(8, 1, entry=learned).prediction.fit == "enclosing"
    assert cell_config(8, 1, entry=apf).prediction.fit == "calibrated"
