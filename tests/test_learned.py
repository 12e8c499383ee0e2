"""Policy checkpoints: exact round trip, no unpickling, clear errors for what does not fit."""

import io
import itertools
import json
import os
import pickle
import platform
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.evaluation import main as eval_main
from uasep_env.interface.actions import ResidualAPF
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import (
    CheckpointError,
    is_policy_checkpoint,
    load_policy,
    load_sb3_policy,
    make_policy,
)
from uasep_env.policies.learned import PolicyCheckpoint, save_policy
from uasep_env.scenarios import (
    HELD_OUT_PAPER_SEEDS,
    HELD_OUT_SEEDS,
    TRAINING_SEEDS,
    VALIDATION_SEEDS,
    check_training_seeds,
)

CHECKPOINTS = Path(__file__).resolve().parents[1] / "baselines" / "checkpoints"


def _random_checkpoint(path, cfg, hidden=(16, 8), seed=0, obs_norm=True):
    rng = np.random.default_rng(seed)
    dim = ObservationLayout.from_config(cfg).dim
    sizes = [dim, *hidden, 3]
    weights = [
        (rng.normal(0, 0.3, (o, i)).astype(np.float32), rng.normal(0, 0.1, o).astype(np.float32))
        for i, o in itertools.pairwise(sizes)
    ]
    meta = PolicyCheckpoint(
        config=cfg.to_dict(), obs_dim=dim, activation="tanh", hidden=hidden, obs_norm=obs_norm
    )
    mean, var = rng.normal(0, 0.1, dim), rng.uniform(0.5, 2.0, dim)
    save_policy(path, meta, weights, mean, var)
    return weights, mean, var


def _reference_forward(weights, mean, var, obs):
    """The network in float64 with numpy's matmul (any summation order)."""
    x = np.clip((obs.astype(np.float64) - mean) / np.sqrt(var + 1e-8), -10, 10).astype(np.float32)
    for w, b in weights[:-1]:
        x = np.tanh((x @ w.T.astype(np.float64) + b).astype(np.float32))
    w, b = weights[-1]
    return np.clip(x @ w.T.astype(np.float64) + b, -1, 1).astype(np.float32)


def test_round_trip_reproduces_the_network(tmp_path):
    cfg = make_config(scenario="random")
    weights, mean, var = _random_checkpoint(tmp_path / "p.zip", cfg)
    assert is_policy_checkpoint(tmp_path / "p.zip")
    policy = load_policy(tmp_path / "p.zip")
    obs = EnvCore(cfg, 4).reset(seed=0)
    # Equal up to the summation order (learned.dense sums in one fixed order).
    np.testing.assert_allclose(
        policy(obs), _reference_forward(weights, mean, var, obs), rtol=0, atol=1e-6
    )
    # The archive holds JSON and a pickle-free npz only.
    with zipfile.ZipFile(tmp_path / "p.zip") as z:
        assert sorted(z.namelist()) == ["uasep_policy.json", "weights.npz"]
        desc = json.loads(z.read("uasep_policy.json"))
        np.load(io.BytesIO(z.read("weights.npz")), allow_pickle=False)
    assert desc["config"]["action"]["mode"] == "direct"


FLY = """
import hashlib, sys
import numpy as np
from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.policies import load_policy
obs = EnvCore(make_config(scenario="random"), 64).reset(seed=3)
x = np.random.default_rng(0).normal(size=(512, 128)).astype(np.float32)
print(hashlib.sha256(load_policy(sys.argv[1])(obs).tobytes()).hexdigest(),
      hashlib.sha256((x @ x.T).tobytes()).hexdigest())
"""


#: OpenBLAS kernels (``OPENBLAS_CORETYPE`` names) and the instruction sets each one runs:
#: forcing a kernel the CPU lacks dies with SIGILL (SkylakeX on an AMD EPYC without AVX-512).
#: Names are numpy's CPU features (:func:`_cpu_features`).
#: (The names numpy's OpenBLAS reports back as the kernel that runs; "Prescott" runs Katmai's.)
_SSE4 = ("SSE", "SSE2", "SSE3", "SSSE3", "SSE41", "SSE42")
BLAS_KERNEL_NEEDS = {
    "Katmai": ("SSE", "SSE2"),
    "Nehalem": _SSE4,
    "Sandybridge": (*_SSE4, "AVX"),
    "Haswell": (*_SSE4, "AVX", "AVX2", "FMA3"),
    "SkylakeX": (*_SSE4, "AVX", "AVX2", "FMA3", "AVX512F", "AVX512CD", "AVX512BW", "AVX512DQ",
                 "AVX512VL"),
}  # fmt: skip


def _cpu_features() -> dict[str, bool]:
    """The instruction sets numpy found on this CPU and its OS (numpy's own run-time check)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_features__
    return dict(__cpu_features__)


def runnable_blas_kernels(features: dict[str, bool]) -> list[str]:
    """The kernels of :data:`BLAS_KERNEL_NEEDS` whose every instruction set is in ``features``."""
    return [
        core
        for core, needs in BLAS_KERNEL_NEEDS.items()
        if all(features.get(flag, False) for flag in needs)
    ]


#: numpy's CPU features of an AMD EPYC 7B12 (Zen 2: AVX2 and FMA, no AVX-512).
EPYC_ZEN2 = dict.fromkeys(
    ("MMX", "SSE", "SSE2", "SSE3", "SSSE3", "SSE41", "POPCNT", "SSE42", "AVX", "F16C", "FMA3",
     "AVX2"),
    True,
)  # fmt: skip


def test_only_kernels_the_cpu_runs_are_forced():
    """The choice on faked CPUs: an AMD EPYC without AVX-512 never gets SkylakeX."""
    full = {f: True for needs in BLAS_KERNEL_NEEDS.values() for f in needs}
    assert runnable_blas_kernels(full) == list(BLAS_KERNEL_NEEDS)
    assert runnable_blas_kernels(EPYC_ZEN2) == ["Katmai", "Nehalem", "Sandybridge", "Haswell"]
    no_bw = {**full, "AVX512BW": False}  # AVX-512 without the byte/word part (Knights Landing)
    assert runnable_blas_kernels(no_bw) == ["Katmai", "Nehalem", "Sandybridge", "Haswell"]
    no_fma = {**EPYC_ZEN2, "FMA3": False}
    assert runnable_blas_kernels(no_fma) == ["Katmai", "Nehalem", "Sandybridge"]
    assert runnable_blas_kernels({**no_fma, "AVX": False}) == ["Katmai", "Nehalem"]
    assert runnable_blas_kernels({"SSE": True, "SSE2": True}) == ["Katmai"]
    assert runnable_blas_kernels({}) == []
    # This CPU: each chosen kernel's instruction sets are all there.
    here = _cpu_features()
    for core in runnable_blas_kernels(here):
        assert all(here[f] for f in BLAS_KERNEL_NEEDS[core]), core


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86 BLAS kernels")
def test_the_network_gives_the_same_bits_whichever_blas_kernel_runs(tmp_path):
    """A BLAS kernel's summation order depends on the CPU it is chosen for; the policy's not.

    OpenBLAS picks its kernel by the CPU (``OPENBLAS_CORETYPE`` forces one): Haswell's and
    SkylakeX's matmuls differ in the last bits, which a closed loop grows into another
    episode. The policy gives the same bits under each kernel this CPU can run (only those:
    a kernel it lacks the instructions for dies with SIGILL), with and without numba.
    """
    cores = runnable_blas_kernels(_cpu_features())
    if len(cores) < 2:
        pytest.skip(f"this CPU runs fewer than two of the OpenBLAS kernels: {cores}")
    cfg = make_config(scenario="random")
    _random_checkpoint(tmp_path / "p.zip", cfg, hidden=(128, 128))
    (tmp_path / "fly.py").write_text(FLY)
    digests = {}  # by the kernel OpenBLAS says ran (a build without the forced one falls back)
    for k, core in enumerate(cores):
        env = {**os.environ, "OPENBLAS_CORETYPE": core, "OPENBLAS_VERBOSE": "2",
               "UASEP_NUMBA": str(1 - k % 2)}  # fmt: skip
        out = subprocess.run([sys.executable, str(tmp_path / "fly.py"), str(tmp_path / "p.zip")],
                             env=env, capture_output=True, text=True, check=True)  # fmt: skip
        ran = set(re.findall(r"^Core: (\w+)$", out.stderr, re.M))
        if not ran:
            pytest.skip("numpy's BLAS is not OpenBLAS with a kernel chosen at run time")
        assert len(ran) == 1 and ran <= set(cores), (core, ran)  # one the CPU runs
        digests[ran.pop()] = out.stdout.split()
    assert len(digests) >= 2, digests  # two kernels at least did run
    assert len({d[0] for d in digests.values()}) == 1, digests


@pytest.mark.parametrize("mode", ["residual_apf", "residual_mvp_region"])
def test_residual_checkpoint_in_a_direct_env_equals_the_residual_env(tmp_path, mode):
    cfg = make_config(scenario="random", action={"mode": mode})
    _random_checkpoint(tmp_path / "r.zip", cfg, seed=1)
    direct = cfg.replace(action={"mode": "direct"})
    in_direct = load_policy(tmp_path / "r.zip", direct)
    in_residual = load_policy(tmp_path / "r.zip", cfg)
    a, b = EnvCore(direct, 3), EnvCore(cfg, 3)
    oa, ob = a.reset(seed=9), b.reset(seed=9)
    for _ in range(60):
        ra, rb = a.step(in_direct(oa)), b.step(in_residual(ob))
        np.testing.assert_array_equal(a.world.uav_pos, b.world.uav_pos)
        oa, ob = ra.obs, rb.obs
    # And the correction really is added to the APF's command.
    base = ResidualAPF(cfg).base(oa)
    assert not np.array_equal(in_direct(oa), base)


@pytest.mark.parametrize(
    ("env", "message"),
    [
        (
            {"n_uavs": 4},
            r"k_uavs: the network reads the 2 nearest UAVs, this env gives 3 "
            r"\(set observation.k_uavs=2",
        ),
        ({"n_obstacles": 2}, "k_obstacles: the network reads the 1 nearest obstacles"),
        ({"action": {"mode": "residual_apf"}}, "action.mode: trained with 'direct'"),
    ],
)
def test_mismatched_env_is_named(tmp_path, env, message):
    cfg = make_config(scenario="random")
    _random_checkpoint(tmp_path / "p.zip", cfg)
    with pytest.raises(CheckpointError, match=message):
        load_policy(tmp_path / "p.zip", cfg.replace(**env))


def test_a_residual_policy_refuses_another_base(tmp_path):
    cfg = make_config(scenario="random", action={"mode": "residual_mvp_region"})
    _random_checkpoint(tmp_path / "p.zip", cfg)
    other = cfg.replace(action={"mode": "residual_apf"})
    message = "trained with 'residual_mvp_region', this env uses 'residual_apf'"
    with pytest.raises(CheckpointError, match=message):
        load_policy(tmp_path / "p.zip", other)


class _Boom:
    def __reduce__(self):
        return (Path("/tmp/uasep_pickle_ran").touch, ())


def _sb3_like_zip(path):
    """A zip laid out like an SB3 save whose ``data`` holds a pickled payload."""
    import base64

    payload = base64.b64encode(pickle.dumps(_Boom())).decode()
    data = {"policy_class": {":type:": "<class 'x'>", ":serialized:": payload}}
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", json.dumps(data))
        z.writestr("policy.pth", b"")


def test_sb3_files_are_not_unpickled_without_opt_in(tmp_path):
    marker = Path("/tmp/uasep_pickle_ran")
    marker.unlink(missing_ok=True)
    _sb3_like_zip(tmp_path / "model.zip")
    cfg = make_config()
    with pytest.raises(CheckpointError, match="allow_pickle"):
        make_policy(str(tmp_path / "model.zip"), cfg)
    with pytest.raises(CheckpointError, match="allow_pickle"):
        load_sb3_policy(tmp_path / "model.zip", cfg)
    assert not marker.exists()


@pytest.mark.parametrize(
    "content",
    [
        b"not a zip at all",
        b"PK\x03\x04 truncated",
    ],
)
def test_corrupt_files_give_one_line_errors(tmp_path, capsys, content):
    bad = tmp_path / "bad.zip"
    bad.write_bytes(content)
    with pytest.raises(CheckpointError):
        make_policy(str(bad), make_config(), allow_pickle=False)
    code = eval_main(["--policy", str(bad), "--episodes", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert "Traceback" not in err and str(bad) in err


def test_tampered_checkpoints_are_rejected(tmp_path):
    cfg = make_config()
    _random_checkpoint(tmp_path / "p.zip", cfg)
    with zipfile.ZipFile(tmp_path / "p.zip") as z:
        desc = json.loads(z.read("uasep_policy.json"))
        raw = z.read("weights.npz")

    def write(name, desc, raw):
        with zipfile.ZipFile(tmp_path / name, "w") as z:
            z.writestr("uasep_policy.json", json.dumps(desc))
            z.writestr("weights.npz", raw)
        return tmp_path / name

    with pytest.raises(CheckpointError, match="unknown checkpoint format"):
        load_policy(write("a.zip", {**desc, "format": "other/9"}, raw))
    with pytest.raises(CheckpointError, match="layout is 58 wide, obs_dim says 59"):
        load_policy(write("b.zip", {**desc, "obs_dim": desc["obs_dim"] + 1}, raw))
    with pytest.raises(CheckpointError, match=r"layer0.weight.npy: shape \(16, 58\), expected"):
        v1 = {k: v for k, v in desc.items() if k != "layout"}
        load_policy(write("b1.zip", {**v1, "format": "uasep-policy/1", "obs_dim": 59}, raw))
    with pytest.raises(CheckpointError, match="invalid checkpoint description"):
        load_policy(write("c.zip", {**desc, "config": {"n_uavs": 99}}, raw))
    buf = io.BytesIO()
    np.savez(buf, obj=np.array([{"a": 1}], dtype=object))
    with pytest.raises(CheckpointError, match=r"unexpected member\(s\) 'obj.npy'"):
        load_policy(write("d.zip", desc, buf.getvalue()))


def test_seed_ranges_are_disjoint():
    ranges = [TRAINING_SEEDS, VALIDATION_SEEDS, HELD_OUT_SEEDS]
    for i, a in enumerate(ranges):
        for b in ranges[i + 1 :]:
            assert a.stop <= b.start or b.stop <= a.start
    assert len(HELD_OUT_SEEDS) == 500
    assert set(HELD_OUT_PAPER_SEEDS) <= set(HELD_OUT_SEEDS)
    check_training_seeds(0, 64)
    with pytest.raises(ValueError, match="seed=999990"):
        check_training_seeds(999_990, 64)


@pytest.mark.parametrize("name", ["ppo_shared", "ppo_residual_apf"])
def test_shipped_checkpoints_load_and_run_without_flags(name, capsys):
    path = CHECKPOINTS / f"{name}.zip"
    if not path.exists():
        pytest.fail(f"shipped checkpoint {path} is missing")
    policy = load_policy(path, make_config(scenario="random"))
    assert policy.meta.info["agent_steps"] > 0
    assert policy.mode == ("residual_apf" if "residual" in name else "direct")
    code = eval_main(
        ["--policy", str(path), "--scenario", "random", "--episodes", "2",
         "--seed", "5000000", "--batch-size", "2"]
    )  # fmt: skip
    assert code == 0
    assert "collision" in capsys.readouterr().out


def test_learned_vs_apf_writes_tables_and_targets(tmp_path):
    import sys

    sys.path.insert(0, str(CHECKPOINTS.parent))
    import learned_vs_apf

    text = learned_vs_apf.main(
        ["--episodes", "2", "--paper-episodes", "1", "--workers", "1", "--out", str(tmp_path)]
    )
    assert (tmp_path / "learned_vs_apf.md").read_text() == text
    assert (tmp_path / "learned_vs_apf.json.gz").exists()
    assert re.search(r"\| episodes with a collision +\|", text)
    assert "### Targets (held-out bank)" in text
    header = next(line for line in text.splitlines() if re.match(r"\| metric +\|", line))
    for name in ("apf", "motion-state-apf", "traditional-apf"):
        assert f" {name} " in header
    for name in learned_vs_apf.LEARNED:
        if (CHECKPOINTS / f"{name}.zip").exists():
            assert f" {name} " in header
        # A file retrained by train/reproduce.py is held to the budget of the run it reproduces.
        if (CHECKPOINTS / f"{name}_reproduction.json").exists():
            assert re.search(rf"{name}: trains in <= 60 min +\| [^|]*the original run, ", text)


def test_select_checkpoint_ranks_on_validation_seeds(tmp_path):
    import sys

    sys.path.insert(0, str(CHECKPOINTS.parents[1] / "train"))
    import select_checkpoint

    cfg = make_config(scenario="random")
    for step in (1, 2):
        _random_checkpoint(tmp_path / f"checkpoints/step_{step}/policy.zip", cfg, seed=step)
    chosen = select_checkpoint.main(
        [str(tmp_path), "--episodes", "2", "--workers", "1", "--copy-to", str(tmp_path / "c.zip")]
    )
    rows = (tmp_path / "selection.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 + 1  # header, two checkpoints, the APF
    assert chosen.parent.name in ("step_1", "step_2")
    assert (tmp_path / "c.zip").read_bytes() == chosen.read_bytes()


def test_readme_and_docs_show_the_held_out_results_as_written():
    root = CHECKPOINTS.parents[1]
    # -v2 results (the policies' env) on the Results page, under their -v2 heading.
    shown = [(root / page).read_text() for page in ("docs/results.md", "docs/training.md")]
    results = (root / "baselines" / "results" / "learned_vs_apf.md").read_text()
    bank = results[results.index("### Held-out bank") : results.index("### Paper scenario")]
    targets = results[results.index("### Targets") :]
    for section, pages in ((bank, shown), (targets, shown[1:])):
        table = section[section.index("| ") :].strip()
        assert all(table in page for page in pages)


def test_base_gains_only_for_a_residual_policy_flying_its_own_base():
    """A residual checkpoint in a direct env flies the given base; anywhere else it is named."""
    from uasep_env.policies import APFGains

    cfg = make_config(scenario="random")
    wide = APFGains().scaled(("obstacle_safe_min",), 2.0)
    residual = load_policy(CHECKPOINTS / "ppo_residual_apf.zip", cfg, base_gains=wide)
    assert residual._residual.controller.gains == wide
    with pytest.raises(ValueError, match=r"base_gains=APFGains\(.*a direct policy in a direct"):
        load_policy(CHECKPOINTS / "ppo_shared.zip", cfg, base_gains=wide)
    with pytest.raises(ValueError, match="a residual_apf policy in a residual_apf environment"):
        load_policy(
            CHECKPOINTS / "ppo_residual_apf.zip",
            cfg.replace(action={"mode": "residual_apf"}),
            base_gains=wide,
        )


def test_uasep_eval_loads_an_sb3_sac_model_with_algorithm(tmp_path, capsys):
    """Issue 23 item 6: --allow-pickle loaded every SB3 file as PPO; --algorithm picks it."""
    sb3 = pytest.importorskip("stable_baselines3")
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    venv = UAVSharedVecEnv(n_envs=1, seed=0, episode_duration=4.0)
    model = sb3.SAC(
        "MlpPolicy", venv, learning_starts=8, batch_size=8, buffer_size=64, seed=0, device="cpu"
    )
    model.learn(total_timesteps=16)
    path = tmp_path / "sac.zip"
    model.save(path)
    args = ["--policy", str(path), "--allow-pickle", "--config", "episode_duration=4", "--quiet"]
    assert eval_main(args) == 2  # loaded as PPO: refused, with the way out named
    assert "--algorithm" in capsys.readouterr().err
    out = tmp_path / "r.json"
    assert eval_main([*args, "--algorithm", "SAC", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["policies"] == ["sac"]  # labelled by the file stem
    assert eval_main([*args, "--algorithm", "SACC"]) == 2
    assert "--algorithm" in capsys.readouterr().err
