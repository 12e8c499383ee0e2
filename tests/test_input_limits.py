"""Limits that must hold on input from elsewhere (issue 31): JSON scanning time, checkpoint
values the policy cannot compute with, and config / command-line values out of range.

Every generator here is seeded (``numpy.random.default_rng``) with a fixed budget: the same
cases on every run, no extra dependency.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S, replace_npz_arrays

from uasep_env.policies import CheckpointError
from uasep_env.policies.checkpoint_reader import read_checkpoint
from uasep_env.runtime.jsonio import DuplicateKeyError, json_depth, loads_unique

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "baselines" / "checkpoints" / "ppo_shared.zip"

# ------------------------------------------------------------------------------- JSON depth


def _true_depth(value) -> int:
    if isinstance(value, dict):
        return 1 + max((_true_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_true_depth(v) for v in value), default=0)
    return 0


_NASTY = '"\\[]{}\\"a\u00e9\u2603 \n'


def _string(rng) -> str:
    return "".join(rng.choice(list(_NASTY)) for _ in range(int(rng.integers(0, 12))))


def _value(rng, depth: int):
    kind = int(rng.integers(0, 6 if depth < 6 else 3))
    if kind == 0:
        return _string(rng)
    if kind == 1:
        return float(rng.normal())
    if kind == 2:
        return None
    if kind == 3:
        return [_value(rng, depth + 1) for _ in range(int(rng.integers(0, 4)))]
    return {_string(rng): _value(rng, depth + 1) for _ in range(int(rng.integers(0, 4)))}


def test_json_depth_is_exact_on_generated_json_with_quotes_and_brackets_in_strings():
    rng = np.random.default_rng(31)
    for _ in range(400):
        value = _value(rng, 0)
        for text in (json.dumps(value), json.dumps(value, ensure_ascii=False, indent=1)):
            assert json_depth(text) == _true_depth(value), text


def test_json_depth_bounds_what_json_loads_would_recurse_into():
    # Mutated valid JSON: whenever json.loads still accepts it, the scan is exact.
    rng = np.random.default_rng(7)
    for _ in range(400):
        text = list(json.dumps(_value(rng, 0)))
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(0, len(text) + 1))
            text.insert(at, str(rng.choice(list('"\\[]{}'))))
        joined = "".join(text)
        depth = json_depth(joined)
        assert depth >= 0
        try:
            value = json.loads(joined)
        except ValueError:
            continue
        assert depth == _true_depth(value), joined


_SCAN = textwrap.dedent(
    """
    import random, sys, time, zipfile
    from pathlib import Path
    from uasep_env.policies import CheckpointError
    from uasep_env.policies.checkpoint_reader import LIMITS, read_checkpoint
    rnd = random.Random(0)
    # An unterminated string of escaped quotes (letters between them defeat the ratio check).
    body = "".join('\\\\"' + rnd.choice("abcdefghij0123456789") for _ in range(87_000))
    text = '{"config": "' + body
    assert 250_000 < len(text) <= LIMITS.meta_bytes, len(text)
    with zipfile.ZipFile(sys.argv[2]) as z:
        weights = z.read("weights.npz")
    path = Path(sys.argv[1])
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("uasep_policy.json", text)
        z.writestr("weights.npz", weights)
    start = time.perf_counter()
    try:
        read_checkpoint(path)
    except CheckpointError as err:
        print("refused", round(time.perf_counter() - start, 3), err)
    """
)


def test_a_256_kb_unterminated_string_of_escaped_quotes_is_refused_without_hanging(tmp_path):
    # Was quadratic (a regex skipping strings): 548 s for 363 KB. The time limit only
    # guards against a hang; the figure is printed, not asserted.
    out = subprocess.run(
        [sys.executable, "-c", _SCAN, str(tmp_path / "scan.zip"), str(SHIPPED)],
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("refused "), out.stdout + out.stderr[-2000:]
    assert "Unterminated string" in out.stdout
    print(out.stdout)


def test_a_long_config_value_of_escaped_quotes_is_parsed_at_once():
    from uasep_env.evaluation.overrides import parse_config_overrides

    value = '"' + '\\"' * 16_384  # 32 KB, an unterminated JSON string: kept as text
    assert parse_config_overrides([f"scenario={value}"]) == {"scenario": value}


# ------------------------------------------------------------------------ duplicate keys


def test_loads_unique_refuses_a_repeated_key_at_any_depth():
    assert loads_unique('{"a": {"b": 1}, "c": [{"b": 2}]}') == {"a": {"b": 1}, "c": [{"b": 2}]}
    for text in ('{"a": 1, "a": 2}', '{"x": [{"b": 1, "b": 1}]}'):
        with pytest.raises(DuplicateKeyError, match="duplicate key"):
            loads_unique(text)


# ----------------------------------------------------------------- checkpoint value ranges


def _parts():
    with zipfile.ZipFile(SHIPPED) as z:
        return json.loads(z.read("uasep_policy.json")), z.read("weights.npz")


def _checkpoint(path: Path, text: str | bytes, raw: bytes) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("uasep_policy.json", text)
        z.writestr("weights.npz", raw)
    return path


def _value_cases(tmp_path):
    desc, raw = _parts()
    assert desc["obs_norm"], "the shipped checkpoint normalises observations"
    dim = desc["obs_dim"]
    w0 = np.load(io.BytesIO(raw))["layer0.weight"].astype(np.float64)
    big = w0.copy()
    big[3, 5] = 1e39  # finite in float64, inf in float32
    text = json.dumps(desc)
    cases = {
        "weight_beyond_f32": (text, replace_npz_arrays(raw, **{"layer0.weight": big}),
                              r"layer0.weight.npy: value 1e\+39 beyond the float32 range"),
        "bias_beyond_f32": (text, replace_npz_arrays(raw, **{"layer2.bias": np.full(3, -1e300)}),
                            "layer2.bias.npy: value 1e\\+300 beyond the float32 range"),
        "mean_beyond_f32": (text, replace_npz_arrays(raw, obs_mean=np.full(dim, 4e38)),
                            "obs_mean.npy: value 4e\\+38 beyond the float32 range"),
        "var_beyond_f32": (text, replace_npz_arrays(raw, obs_var=np.full(dim, 1e200)),
                           "obs_var.npy: value 1e\\+200 beyond the float32 range"),
        "clip_tiny": (json.dumps({**desc, "clip_obs": 1e-300}), raw,
                      r"clip_obs must be a finite number in \[0.001, 1e\+06\], got 1e-300"),
        "clip_huge": (json.dumps({**desc, "clip_obs": 1e7}), raw,
                      r"clip_obs must be a finite number in \[0.001, 1e\+06\]"),
        "duplicate_clip": (text.replace('"clip_obs":', '"clip_obs": 0.5, "clip_obs":', 1), raw,
                           "uasep_policy.json: duplicate key 'clip_obs'"),
        "duplicate_nested": (text.replace('"config": {', '"config": {"dt": 9, ', 1), raw,
                             "duplicate key 'dt'"),
    }  # fmt: skip
    return [(n, _checkpoint(tmp_path / f"{n}.zip", t, w), m) for n, (t, w, m) in cases.items()]


def test_checkpoint_values_the_policy_cannot_use_are_refused_at_load_time(tmp_path):
    for name, path, match in _value_cases(tmp_path):
        with pytest.raises(CheckpointError, match=match) as info:
            read_checkpoint(path)
        assert "\n" not in str(info.value), name


def test_uasep_eval_names_the_bad_checkpoint_field_in_one_line(tmp_path, capsys):
    from uasep_env.evaluation import main

    for name, path, _ in _value_cases(tmp_path)[:1] + _value_cases(tmp_path)[4:7]:
        assert main(["--policy", str(path), "--quiet"]) == 2, name
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "cannot load" in err, err


def test_boundary_values_are_still_accepted(tmp_path):
    desc, raw = _parts()
    w = np.load(io.BytesIO(raw))["layer1.bias"].astype(np.float64)
    w[0] = float(np.finfo(np.float32).max)
    for clip in (1e-3, 1e6):
        path = _checkpoint(tmp_path / f"ok{clip}.zip", json.dumps({**desc, "clip_obs": clip}),
                           replace_npz_arrays(raw, **{"layer1.bias": w}))  # fmt: skip
        meta, *_ = read_checkpoint(path)
        assert meta.clip_obs == clip


# ------------------------------------------------------------- counts that cannot fit (B4)

_HUGE = [10**7, 10**9, 2**63, 2**80]


def _views():
    import gymnasium

    import uasep_env  # noqa: F401  (registers the ids)
    from uasep_env.envs.core import EnvCore
    from uasep_env.envs.vector import FormationVectorEnv

    views = {
        "num_envs": lambda n: FormationVectorEnv(num_envs=n),
        "make_vec num_envs": lambda n: gymnasium.make_vec("uasep/Formation-v3", num_envs=n),
        "n_envs": lambda n: EnvCore(None, n_envs=n),
    }
    try:
        from uasep_env.envs.sb3 import UAVSharedVecEnv
    except ImportError:  # stable-baselines3 is an extra
        pass
    else:
        views["sb3 n_envs"] = lambda n: UAVSharedVecEnv(n_envs=n)
    return views


@pytest.mark.parametrize("n", _HUGE)
def test_every_view_refuses_a_count_that_cannot_fit_naming_it_and_the_estimate(n):
    for view, make in _views().items():
        name = view.split()[-1]
        with pytest.raises(ValueError, match=rf"^{name}={n:,} needs about .* of memory") as info:
            make(n)
        assert "per environment" in str(info.value) and "available" in str(info.value)


def test_the_limit_follows_the_memory_available(monkeypatch):
    from uasep_env.config import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.runtime import capacity

    cfg = make_config()
    per = capacity.env_bytes(cfg)
    monkeypatch.setattr(capacity, "available_memory", lambda: 1000 * per)
    EnvCore(cfg, n_envs=1000)  # fits exactly
    with pytest.raises(ValueError, match=r"n_envs=1,001 needs about"):
        EnvCore(cfg, n_envs=1001)
    big = make_config(n_uavs=32, n_obstacles=8)
    assert capacity.env_bytes(big) > 10 * per  # the estimate grows with the config
    with pytest.raises(ValueError, match=r"with 32 UAVs and 8 obstacle"):
        EnvCore(big, n_envs=200)


_PEAK = """
import sys, tracemalloc
import numpy as np
from uasep_env.config import make_config
from uasep_env.envs.core import EnvCore
cfg = make_config(**eval(sys.argv[1]))
def peak(n):  # the most memory held at once while a batch is made, reset and stepped
    tracemalloc.start()
    core = EnvCore(cfg, n_envs=n)
    core.reset(seed=0)
    core.step(np.zeros((n, cfg.n_uavs, 3), np.float32))
    core.reset(seed=1)
    del core
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak
peak(4)  # compiled kernels, caches
n = int(sys.argv[2])
print((peak(n) - peak(n // 5)) / (n - n // 5))
"""


@pytest.mark.parametrize(
    ("config", "n"),
    [({}, 2000), ({"n_uavs": 32, "n_obstacles": 8}, 200)],
)
def test_the_estimate_is_not_below_what_a_batch_really_takes(config, n):
    from uasep_env.config import make_config
    from uasep_env.runtime import capacity

    out = subprocess.run(
        [sys.executable, "-c", _PEAK, repr(config), str(n)],
        capture_output=True, text=True, timeout=HANG_GUARD_S, cwd=ROOT, check=True,
    )  # fmt: skip
    measured = float(out.stdout.split()[-1])
    estimate = capacity.env_bytes(make_config(**config))
    print(f"{config}: measured {measured:,.0f} B/env, estimate {estimate:,} B/env")
    assert estimate >= measured


# ------------------------------------------------- config and command-line ranges (B8)


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"dt": 1e-12}, "dt"),
        ({"dt": 5e-4}, "dt"),
        ({"uav": {"max_accel": 1e-300}}, "uav.max_accel"),
        ({"uav": {"max_speed": 1e-300}, "cruise_speed": 1e-300}, "uav.max_speed"),
        ({"cruise_speed": 1e-5}, "cruise_speed"),
        ({"episode_duration": 1e6}, "episode_duration"),
        ({"dt": 0.001, "episode_duration": 2000.0}, "episode_duration"),
    ],
)
def test_config_values_that_describe_nothing_are_refused_naming_the_field(overrides, field):
    from uasep_env.config import make_config

    with pytest.raises(ValueError, match=rf"invalid config value {field}="):
        make_config(**overrides)


def test_the_new_lower_bounds_accept_their_boundary_and_every_scenario():
    from uasep_env.config import make_config
    from uasep_env.scenarios import scenario_names

    make_config(dt=1e-3, episode_duration=1000.0, uav={"max_accel": 0.01, "max_speed": 0.01},
                cruise_speed=0.01)  # fmt: skip
    for name in scenario_names():
        make_config(scenario=name)


def _eval(args, capsys):
    from uasep_env.evaluation import main

    code = main(["--quiet", *args])
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--episodes", "1000000000"], "--episodes"),
        (["--episodes", str(2**70)], "--episodes"),
        (["--episodes", "100000", "--batch-size", "100000"], "--batch-size"),
        (["--settle-time", "1e308"], "--settle-time"),
        (["--settle-time", "1000001"], "--settle-time"),
        (["--hold-time", "1e308"], "--hold-time"),
        (["--config", "dt=1e-12"], "--config"),
        (["--config", "uav.max_accel=1e-300"], "--config"),
    ],
)
def test_uasep_eval_refuses_sizes_and_times_up_front_in_one_line(args, flag, capsys):
    code, err = _eval(args, capsys)
    assert code == 2 and f"argument {flag}" in err and err.count("\n") == 1, err


def test_uasep_eval_refuses_a_policy_path_that_is_not_utf8_before_running(tmp_path, capsys):
    import shutil

    name = os.fsdecode(b"policy-\xff.zip")
    path = tmp_path / name
    shutil.copy(SHIPPED, path)
    code, err = _eval(["--policy", str(path), "--csv", str(tmp_path / "o.csv")], capsys)
    assert code == 2 and "argument --policy" in err and "not UTF-8" in err, err
    assert not (tmp_path / "o.csv").exists()
