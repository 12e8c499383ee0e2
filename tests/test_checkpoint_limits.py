"""Hostile policy checkpoints: refused with one-line CheckpointErrors, within a memory bound."""

import io
import json
import tracemalloc
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import replace_npz_arrays

from uasep_env.evaluation import main as eval_main
from uasep_env.policies import CheckpointError, load_policy, make_policy
from uasep_env.policies.learned import read_checkpoint

CHECKPOINTS = Path(__file__).resolve().parents[1] / "baselines" / "checkpoints"
SHIPPED = CHECKPOINTS / "ppo_shared.zip"
MiB = 1024 * 1024


def _parts(path=SHIPPED):
    with zipfile.ZipFile(path) as z:
        return json.loads(z.read("uasep_policy.json")), z.read("weights.npz")


def _zip(path, members, compression=zipfile.ZIP_DEFLATED):
    """Write ``members`` (name -> bytes, or name -> (n_zero_bytes,) streamed) to ``path``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # duplicate names are the point of one case
        with zipfile.ZipFile(path, "w", compression) as z:
            for name, data in members:
                if isinstance(data, tuple):
                    with z.open(name, "w", force_zip64=True) as fh:
                        chunk = bytes(MiB)
                        for _ in range(data[0] // MiB):
                            fh.write(chunk)
                else:
                    z.writestr(name, data)
    return path


def _npz_with(raw, extra):
    """The shipped weights.npz plus members of ``size`` zero bytes (deflated)."""
    buf = io.BytesIO(raw)
    with zipfile.ZipFile(buf, "a", zipfile.ZIP_DEFLATED) as z:
        for name, size in extra:
            with z.open(name, "w", force_zip64=True) as fh:
                for _ in range(size // MiB):
                    fh.write(bytes(MiB))
    return buf.getvalue()


def _bombs(tmp_path):
    """(name, path, expected message) of every hostile file built here."""
    desc, raw = _parts()
    meta = json.dumps(desc).encode()
    cases = []

    def add(name, members, match, compression=zipfile.ZIP_DEFLATED):
        cases.append((name, _zip(tmp_path / f"{name}.zip", members, compression), match))

    add(
        "unused_npz_member",
        [("uasep_policy.json", meta), ("weights.npz", _npz_with(raw, [("junk.npy", 64 * MiB)]))],
        r"unexpected member\(s\) 'junk.npy'",
    )
    add(
        "unused_zip_member",
        [("uasep_policy.json", meta), ("weights.npz", raw), ("junk", (64 * MiB,))],
        r"unexpected member\(s\) 'junk'",
    )
    add(
        "deflate_bomb_weights",
        [("uasep_policy.json", meta), ("weights.npz", (96 * MiB,))],
        r"weights.npz: 100,663,296 bytes declared, limit",
    )
    add(
        "deflate_bomb_json",
        [("uasep_policy.json", (16 * MiB,)), ("weights.npz", raw)],
        r"uasep_policy.json: 16,777,216 bytes declared",
    )
    add(
        "bzip2_json",
        [("uasep_policy.json", b" " * MiB + meta), ("weights.npz", raw)],
        "compression method 12 refused",
        zipfile.ZIP_BZIP2,
    )
    add(
        "ratio",
        [("uasep_policy.json", meta), ("weights.npz", b"\0" * (4 * MiB))],
        "compression ratio",
    )
    big_info = {**desc, "info": {"x": np.random.default_rng(0).bytes(60_000).hex()}}
    add(
        "info_string",
        [("uasep_policy.json", json.dumps(big_info)), ("weights.npz", raw)],
        "info is larger than 65,536 bytes",
    )
    huge = {**desc, "hidden": [4096, 4096], "n_layers": 3}
    add(
        "huge_network",
        [("uasep_policy.json", json.dumps(huge)), ("weights.npz", raw)],
        "network of 17,035,267 parameters, limit 4,000,000",
    )
    wide = {**desc, "hidden": [8192, 8192], "n_layers": 3}
    add(
        "too_wide",
        [("uasep_policy.json", json.dumps(wide)), ("weights.npz", raw)],
        r"hidden\[0\] must be an integer in \[1, 4096\], got 8192",
    )
    nested = json.dumps(desc).replace(
        '"config": {', '"config": {"x": ' + "[" * 900 + "]" * 900 + ", ", 1
    )
    add(
        "nested_json",
        [("uasep_policy.json", nested), ("weights.npz", raw)],
        "nests 902 levels deep, limit 16",
    )
    add(
        "duplicates",
        [("uasep_policy.json", meta), ("weights.npz", raw), ("weights.npz", raw)],
        r"duplicate member\(s\) 'weights.npz'",
    )
    return cases


def _fields(tmp_path):
    desc, raw = _parts()
    dim = desc["obs_dim"]
    cases = {
        "clip_nan": ({**desc, "clip_obs": float("nan")}, raw, r"clip_obs must be a finite number"),
        "clip_negative": ({**desc, "clip_obs": -1.0}, raw, r"clip_obs .* in \[0.001, .*got -1.0"),
        "eps_nan": ({**desc, "obs_epsilon": float("nan")}, raw, "obs_epsilon must be"),
        "eps_huge": (
            json.dumps(desc).replace('"obs_epsilon": 1e-08', '"obs_epsilon": 1e400'),
            raw,
            "obs_epsilon must be a finite number .* got inf",
        ),
        "eps_big": ({**desc, "obs_epsilon": 5.0}, raw, "obs_epsilon must be"),
        "norm_string": ({**desc, "obs_norm": "false"}, raw, "obs_norm must be true or false"),
        "bool_mean": (
            desc,
            replace_npz_arrays(raw, obs_mean=np.ones(dim, bool)),
            "obs_mean.npy: bool data, expected float",
        ),
        "int_dim": ({**desc, "obs_dim": 58.0}, raw, "obs_dim must be an integer"),
        "true_dim": ({**desc, "obs_dim": True}, raw, "obs_dim must be an integer"),
        "hidden_str": ({**desc, "hidden": "128"}, raw, "hidden must be a list"),
        "info_list": ({**desc, "info": []}, raw, "info must be an object"),
        "unknown_field": ({**desc, "run_this": 1}, raw, r"unknown field\(s\) 'run_this'"),
        "big_int": (
            json.dumps(desc).replace('"obs_dim": 58', '"obs_dim": ' + "9" * 5000),
            raw,
            "ValueError",
        ),
        "nan_weight": (
            desc,
            replace_npz_arrays(raw, **{"layer0.bias": np.full(128, np.nan, np.float32)}),
            "layer0.bias.npy: non-finite values",
        ),
        "wrong_shape": (
            desc,
            replace_npz_arrays(raw, **{"layer1.weight": np.zeros((3, 3), np.float32)}),
            r"layer1.weight.npy: shape \(3, 3\), expected",
        ),
        "not_json": ("{", raw, "JSONDecodeError"),
        "not_utf8": (b"\xff\xfe", raw, "UnicodeDecodeError"),
        "json_list": ("[1, 2]", raw, "must hold an object, got list"),
    }
    out = []
    for name, (d, w, match) in cases.items():
        text = d if isinstance(d, (str, bytes)) else json.dumps(d)
        path = _zip(tmp_path / f"{name}.zip", [("uasep_policy.json", text), ("weights.npz", w)])
        out.append((name, path, match))
    return out


def _one_line(err):
    text = str(err)
    return text and "\n" not in text and not text.rstrip().endswith(":")


def test_hostile_files_are_refused_naming_the_problem(tmp_path):
    for name, path, match in _bombs(tmp_path) + _fields(tmp_path):
        with pytest.raises(CheckpointError, match=match) as info:
            read_checkpoint(path)
        assert _one_line(info.value), (name, str(info.value))


def test_refusing_bombs_stays_within_a_memory_bound_of_a_shipped_load(tmp_path):
    bombs = _bombs(tmp_path)
    read_checkpoint(SHIPPED)  # warm imports and caches
    tracemalloc.start()
    try:
        read_checkpoint(SHIPPED)
        shipped_peak = tracemalloc.get_traced_memory()[1]
        peaks = {}
        for name, path, _ in bombs:
            tracemalloc.reset_peak()
            with pytest.raises(CheckpointError):
                read_checkpoint(path)
            peaks[name] = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # The bombs declare 16-96 MiB; refusing each costs at most about a shipped load.
    bound = 2 * shipped_peak + MiB
    assert max(peaks.values()) <= bound, (shipped_peak, peaks)


def test_byte_flips_and_truncations_only_raise_checkpoint_errors(tmp_path):
    data = bytearray(SHIPPED.read_bytes())
    rng = np.random.default_rng(0)
    path = tmp_path / "m.zip"
    for k in range(150):
        mutant = bytearray(data)
        if k % 3 == 0:
            mutant = mutant[: int(rng.integers(0, len(mutant)))]
        else:
            for i in rng.integers(0, len(mutant), size=int(rng.integers(1, 8))):
                mutant[i] = int(rng.integers(0, 256))
        path.write_bytes(bytes(mutant))
        try:
            read_checkpoint(path)
        except CheckpointError as err:
            assert _one_line(err), (k, str(err))


def test_cli_names_hostile_and_missing_checkpoints_in_one_line(tmp_path, capsys):
    cases = _bombs(tmp_path)[:3] + _fields(tmp_path)[:3]
    for _name, path, _ in cases:
        assert eval_main(["--policy", str(path), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and str(path) in err
        assert not err.split(str(path))[-1].strip(" :()").startswith("(see")  # a reason is given
    missing = tmp_path / "nope.zip"
    with pytest.raises(ValueError, match="no such file"):
        make_policy(str(missing), None)
    assert eval_main(["--policy", str(missing), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "unknown policy" not in err


#: The checkpoints shipped before format 2 (0.3.0's ppo_shared.zip and ppo_residual_apf.zip).
V1 = Path(__file__).resolve().parent / "data" / "checkpoints_v1"


def test_v1_checkpoints_act_as_their_raw_arrays_say():
    """Version-1 files load through the bounded reader with exactly their stored numbers."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore

    for name in ("ppo_shared", "ppo_residual_apf"):
        desc, raw = _parts(V1 / f"{name}.zip")
        assert desc["format"] == "uasep-policy/1"
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta, weights, mean, var = read_checkpoint(V1 / f"{name}.zip")
        for k, (w, b) in enumerate(weights):
            np.testing.assert_array_equal(w, arrays[f"layer{k}.weight"])
            np.testing.assert_array_equal(b, arrays[f"layer{k}.bias"])
        np.testing.assert_array_equal(mean, arrays["obs_mean"])
        np.testing.assert_array_equal(var, arrays["obs_var"])
        cfg = make_config(scenario="random", action={"mode": desc["config"]["action"]["mode"]})
        policy = load_policy(V1 / f"{name}.zip", cfg)
        obs = EnvCore(cfg, 2).reset(seed=3)
        x = np.clip((obs - mean) / np.sqrt(var + meta.obs_epsilon), -10, 10).astype(np.float32)
        for w, b in weights[:-1]:
            x = np.tanh(x @ w.T + b)
        expected = np.clip(x @ weights[-1][0].T + weights[-1][1], -1, 1)
        # Equal up to the summation order (learned.dense adds in one fixed order).
        np.testing.assert_allclose(policy(obs), expected, rtol=0, atol=1e-5)
