"""Crafted run folders (issue 55 items 1, 2): refused in one line, nothing written outside.

A run folder is untrusted input: a generator here makes hostile variants of a real
checkpoint (links leading out, FIFOs, a deflate bomb in ``state.pt``, NaN/inf/huge
multipliers, bad CSVs, bad tensors); each must be refused by ``--resume`` (or the lock) in
one line naming the file, exit status 2, and no file outside the folder may change.
"""

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from conftest import HANG_GUARD_S

from uasep_env.runtime.atomic import atomic_write
from uasep_env.training import ppo_shared, rundir
from uasep_env.training.lagrangian import PIDLagrangian

ROOT = Path(__file__).resolve().parents[1]
TINY = [
    "--scenario", "crossing", "--n-uavs", "2", "--n-obstacles", "0", "--episode-duration", "10",
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--hidden", "16",
    "--total-timesteps", "256", "--checkpoint-every", "128", "--eval-episodes", "1",
    "--no-progress",
]  # fmt: skip


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A real tiny PPO run folder with checkpoints at 128 and 256 agent-steps."""
    out = tmp_path_factory.mktemp("ref") / "run"
    ppo_shared.main([*TINY, "--out-dir", str(out)])
    return out


@pytest.fixture
def outside(tmp_path):
    """A file outside every run folder, whose bytes must never change."""
    path = tmp_path / "outside.txt"
    path.write_bytes(b"precious\n")
    return path


def _copy(run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(run, out, symlinks=True)
    (out / ".uasep-run.lock").unlink(missing_ok=True)
    return out


def _resume(out, capsys):
    """``--resume out/checkpoints/step_128`` in-process: the SystemExit and stderr."""
    ck = out / "checkpoints" / "step_128"
    with pytest.raises(SystemExit) as exc:
        ppo_shared.main([*TINY, "--out-dir", str(out), "--resume", str(ck)])
    return exc.value, capsys.readouterr().err


def _refused(exc, err, *named):
    assert exc.code == 2, (exc.code, str(exc))
    line = str(exc)
    assert "\n" not in line and err.strip() == line, (line, err)
    for word in named:
        assert word in line, (word, line)


def _rewrite_zip(path, change):
    """Rewrite the zip ``path`` member by member: ``change(name, data) -> data``."""
    with zipfile.ZipFile(path) as z:
        members = [(i, z.read(i)) for i in z.infolist()]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        for info, data in members:
            z.writestr(info, change(info.filename, data))


def _tensors(ck):
    import torch

    return torch.load(ck / "state.pt", weights_only=True)


def _save_tensors(ck, state):
    import torch

    torch.save(state, ck / "state.pt")


def _bad_policy_dtype(ck):
    state = _tensors(ck)
    key = next(k for k in state["policy"] if k.endswith("weight"))
    state["policy"][key] = state["policy"][key].long()
    _save_tensors(ck, state)


def _bad_policy_value(value):
    def craft(ck):
        state = _tensors(ck)
        key = next(k for k in state["policy"] if k.endswith("weight"))
        state["policy"][key] = state["policy"][key].double().fill_(value)
        _save_tensors(ck, state)

    return craft


def _bad_policy_nan(ck):
    state = _tensors(ck)
    key = next(k for k in state["policy"] if k.endswith("weight"))
    state["policy"][key][0, 0] = float("nan")
    _save_tensors(ck, state)


def _bad_policy_shape(ck):
    state = _tensors(ck)
    key = next(k for k in state["policy"] if k.endswith("weight"))
    state["policy"][key] = state["policy"][key][:, :-1]
    _save_tensors(ck, state)


def _keyless(ck):
    _save_tensors(ck, {"optimizer": _tensors(ck)["optimizer"]})


def _pickled(ck):
    import pickle

    (ck / "state.pt").write_bytes(pickle.dumps({"policy": object}))


def _state_json(change):
    def craft(ck):
        path = ck / "state.json"
        text = change(path.read_text())
        path.unlink()
        path.write_text(text)

    return craft


#: name -> (craft(checkpoint folder), the file the refusal must name)
CHECKPOINT_CASES = {
    "state.pt empty": (lambda ck: (ck / "state.pt").write_bytes(b""), "state.pt"),
    "state.pt truncated": (
        lambda ck: (ck / "state.pt").write_bytes((ck / "state.pt").read_bytes()[:999]),
        "state.pt",
    ),
    "state.pt pickled": (_pickled, "state.pt"),
    "state.pt keyless": (_keyless, "state.pt"),
    "state.pt int64 weight": (_bad_policy_dtype, "state.pt"),
    "state.pt float64 1e300 weight": (_bad_policy_value(1e300), "state.pt"),
    "state.pt NaN weight": (_bad_policy_nan, "state.pt"),
    "state.pt wrong shape": (_bad_policy_shape, "state.pt"),
    "state.json NaN": (
        _state_json(lambda t: t.replace('"wall_s": ', '"wall_s": NaN, "x": ')),
        "state.json",
    ),
    "state.json 1e999": (
        _state_json(lambda t: t.replace('"wall_s": ', '"wall_s": 1e999, "x": ')),
        "state.json",
    ),
    "state.json deep": (_state_json(lambda t: "[" * 5000 + "]" * 5000), "state.json"),
    "state.json not json": (_state_json(lambda t: t[: len(t) // 2]), "state.json"),
    "state.json bad steps": (
        _state_json(lambda t: json.dumps({**json.loads(t), "agent_steps": -5})),
        "state.json",
    ),
    "normalization NaN": (
        lambda ck: _rewrite_zip(
            ck / "normalization.npz",
            lambda n, d: d[:-8] + b"\x00" * 6 + b"\xf8\x7f" if n == "obs_mean.npy" else d,
        ),
        "normalization.npz",
    ),
    "normalization wrong shape": (
        lambda ck: _rewrite_zip(
            ck / "normalization.npz",
            lambda n, d: _npy([1.0, 2.0]) if n == "obs_mean.npy" else d,
        ),
        "normalization.npz",
    ),
}


def _env_state(change):
    """Rewrite ``env_state.npz`` with ``change(arrays)`` applied (arrays by name)."""

    def craft(ck):
        import numpy as np

        path = ck / "env_state.npz"
        with np.load(path) as z:
            arrays = dict(z)
        change(arrays)
        with path.open("wb") as fh:
            np.savez(fh, **arrays)

    return craft


def _put(name, value):
    """A change of :func:`_env_state`: ``arrays[name] = value(arrays[name])``."""

    def change(arrays):
        arrays[name] = value(arrays[name])

    return change


def _nan_at_first(a):
    a = a.copy()
    a.flat[0] = float("nan")
    return a


#: Crafted ``env_state.npz`` files (the environments' state of an SB3 checkpoint): each is
#: refused in one line naming the file and the array.
ENV_STATE_CASES = {
    "wrong shape": (_put("env.world.uav_pos", lambda a: a[:, :1]), "env.world.uav_pos"),
    "NaN": (_put("env.world.uav_vel", _nan_at_first), "env.world.uav_vel"),
    "huge": (_put("env.world.time", lambda a: a + 1e300), "env.world.time"),
    "inf": (_put("env.world.est_pos", lambda a: a - float("inf")), "env.world.est_pos"),
    "wrong dtype": (_put("env.world.steps", lambda a: a.astype("float64")), "env.world.steps"),
    "negative counter": (_put("env.world.steps", lambda a: a - 10**6), "env.world.steps"),
    "noise position": (_put("env.world.noise.buf_pos", lambda a: a + 10**6), "noise.buf_pos"),
    "generators": (
        _put("env.world.noise.generators", lambda a: a[:, :3]),
        "env.world.noise.generators",
    ),
    "last obs NaN": (_put("model.last_obs", _nan_at_first), "model.last_obs"),
    "monitor shape": (_put("monitor.episode_returns", lambda a: a[:1]), "monitor.episode_returns"),
    "numpy rng": (_put("numpy.pos", lambda a: a + 10**6), "numpy.pos"),
    "missing": (lambda arrays: arrays.pop("env.core.obs"), "env.core.obs"),
    "unexpected": (lambda arrays: arrays.update(extra=arrays["numpy.pos"]), "extra"),
    "pickled": (_put("env.world.families", lambda a: a.astype(object)), "allow_pickle"),
}


@pytest.mark.parametrize("case", sorted(ENV_STATE_CASES))
def test_a_crafted_env_state_is_refused_in_one_line(case, run, tmp_path, capsys):
    out = _copy(run, tmp_path)
    change, named = ENV_STATE_CASES[case]
    _env_state(change)(out / "checkpoints" / "step_128")
    exc, err = _resume(out, capsys)
    _refused(exc, err, "env_state.npz", named, "step_128")


def test_an_env_state_over_its_limit_is_refused_before_a_read(run, tmp_path, capsys, monkeypatch):
    import dataclasses

    from uasep_env.training import checkpoint_readers

    out = _copy(run, tmp_path)
    small = dataclasses.replace(checkpoint_readers.LIMITS, env_state=1000)
    monkeypatch.setattr(checkpoint_readers, "LIMITS", small)
    exc, err = _resume(out, capsys)
    _refused(exc, err, "env_state.npz", "limit 1,000")


def _npy(values):
    import io

    import numpy as np

    buf = io.BytesIO()
    np.save(buf, np.array(values))
    return buf.getvalue()


@pytest.mark.parametrize("case", sorted(CHECKPOINT_CASES))
def test_a_crafted_checkpoint_is_refused_in_one_line(case, run, tmp_path, capsys):
    out = _copy(run, tmp_path)
    craft, named = CHECKPOINT_CASES[case]
    craft(out / "checkpoints" / "step_128")
    exc, err = _resume(out, capsys)
    _refused(exc, err, named, "step_128")


@pytest.mark.parametrize(
    "name", ["state.pt", "state.json", "normalization.npz", "policy.zip", "env_state.npz"]
)
@pytest.mark.parametrize("kind", ["link out", "fifo", "device"])
def test_links_out_and_special_files_are_refused_before_a_read(
    name, kind, run, tmp_path, outside, capsys
):
    out = _copy(run, tmp_path)
    target = out / "checkpoints" / "step_128" / name
    shutil.copy(target, outside)  # a valid file, but outside the folder
    before = outside.read_bytes()
    target.unlink()
    if kind == "link out":
        target.symlink_to(outside)
    elif kind == "fifo":
        os.mkfifo(target)
    else:
        target.symlink_to("/dev/zero")
    exc, err = _resume(out, capsys)
    _refused(exc, err, name)
    assert outside.read_bytes() == before


@pytest.mark.parametrize("cell", ["abc", "1\x002", "12.5"], ids=["letters", "nul", "fraction"])
def test_a_bad_csv_is_named(cell, run, tmp_path, capsys):
    out = _copy(run, tmp_path)
    path = out / "progress.csv"
    lines = path.read_text().splitlines(keepends=True)
    lines[1] = cell + lines[1][lines[1].index(",") :]
    path.write_text("".join(lines))
    exc, err = _resume(out, capsys)
    _refused(exc, err, "progress.csv")


def test_a_progress_csv_linked_out_is_not_read_nor_written(run, tmp_path, outside, capsys):
    out = _copy(run, tmp_path)
    shutil.copy(out / "progress.csv", outside)
    before = outside.read_bytes()
    (out / "progress.csv").unlink()
    (out / "progress.csv").symlink_to(outside)
    exc, err = _resume(out, capsys)
    _refused(exc, err, "progress.csv")
    assert outside.read_bytes() == before


def test_the_run_folders_own_files_replace_links(tmp_path, outside):
    before = outside.read_bytes()
    (tmp_path / "progress.csv").symlink_to(outside)
    log = rundir.ProgressLog(tmp_path / "progress.csv", ("agent_steps",))
    log.write({"agent_steps": 1})
    log.close()
    (tmp_path / "validation.json").symlink_to(outside)
    atomic_write(tmp_path / "validation.json", "{}", replace_links=True)
    assert outside.read_bytes() == before
    assert not (tmp_path / "progress.csv").is_symlink()
    assert (tmp_path / "progress.csv").read_text() == "agent_steps\n1\n"
    # A user's own target keeps being written through its link.
    (tmp_path / "mine.json").symlink_to(outside)
    atomic_write(tmp_path / "mine.json", "x")
    assert outside.read_text() == "x"


@pytest.mark.parametrize("kind", ["link", "fifo"])
def test_a_lock_that_is_a_link_or_fifo_is_refused(kind, tmp_path, outside, capsys):
    out = tmp_path / "fresh"
    out.mkdir()
    lock = out / ".uasep-run.lock"
    if kind == "link":
        lock.symlink_to(outside)
    else:
        os.mkfifo(lock)
    before = outside.read_bytes()
    with pytest.raises(SystemExit) as exc:
        ppo_shared.main([*TINY, "--out-dir", str(out)])
    _refused(exc.value, capsys.readouterr().err, ".uasep-run.lock")
    assert outside.read_bytes() == before


def test_a_folder_holding_only_a_foreign_lock_file_is_not_empty(tmp_path):
    out = tmp_path / "fresh"
    out.mkdir()
    (out / ".uasep-run.lock").mkdir()  # not the lock this run holds: content
    with pytest.raises(SystemExit):
        rundir.prepare_out_dir(out, "", False)


@pytest.mark.parametrize(
    "field, value",
    [("multiplier", float("nan")), ("multiplier", float("inf")), ("multiplier", 1e308),
     ("multiplier", -1.0), ("integral", 1e308), ("costs_d", [float("nan")])],
)  # fmt: skip
def test_a_restored_multiplier_is_finite_and_in_range(field, value, capsys):
    pid = PIDLagrangian(1.0, max_multiplier=100.0)
    state = {**pid.state_dict(), field: value}
    with pytest.raises(SystemExit) as exc:
        rundir.restore_json(Path("ck"), "lagrangian.state", pid.load_state_dict, state)
    _refused(exc.value, capsys.readouterr().err, "state.json", field)
    assert pid.multiplier == 0.0


BOMB = """
import resource, sys
from pathlib import Path
from uasep_env.training import rundir
import torch
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    rundir.read_tensors(Path(sys.argv[1]))
except SystemExit as exc:
    print("refused", exc.code)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print("grew_mb", (after - before) / 1024)
"""


def test_a_deflate_bomb_in_state_pt_is_refused_in_bounded_memory(run, tmp_path):
    ck = tmp_path / "ck"
    shutil.copytree(run / "checkpoints" / "step_128", ck)
    with zipfile.ZipFile(ck / "state.pt") as z:
        members = [(i, z.read(i)) for i in z.infolist()]
    first = next(i.filename for i, _ in members if "/data/" in i.filename)
    with zipfile.ZipFile(ck / "state.pt", "w", zipfile.ZIP_DEFLATED) as z:
        for info, data in members:
            if info.filename != first:
                z.writestr(info, data)
                continue
            with z.open(first, "w", force_zip64=True) as fh:  # 1 GiB of deflated zeros
                zero = bytes(1 << 24)
                for _ in range(64):
                    fh.write(zero)
    assert (ck / "state.pt").stat().st_size < 8 << 20
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-c", BOMB, str(ck)], capture_output=True, text=True,
                       env=env, timeout=HANG_GUARD_S)  # fmt: skip
    assert "refused 2" in p.stdout, p.stdout + p.stderr
    assert "state.pt" in p.stderr and p.stderr.count("\n") == 1, p.stderr
    grew = float(p.stdout.split("grew_mb")[1])
    assert grew < 300, f"{grew:.0f} MB"


# ----------------------------------------------------- the other recipes' resume paths

#: recipe -> (module, extra flags): each resumes through its own loader (the lean loop's,
#: skrl MAPPO's, MAPPO-Lagrangian's, SB3 PPO-Lagrangian's); a rollout is 128 agent-steps.
RECIPES = {
    "lean": ("ppo_shared", ["--trainer", "lean"]),
    "mappo": ("mappo", []),
    "mappo_lagrangian": ("mappo_lagrangian", ["--cost-limit", "0.5"]),
    "ppo_lagrangian": ("ppo_lagrangian", ["--cost-limit", "0.5"]),
}


def _recipe_main(recipe):
    import importlib

    module, extra = RECIPES[recipe]
    main = importlib.import_module(f"uasep_env.training.{module}").main
    return lambda argv: main([*TINY, "--eval-episodes", "0", *extra, *argv])


@pytest.fixture(scope="module")
def recipe_runs(tmp_path_factory):
    """A real tiny run folder of each recipe (made when first asked for)."""
    made = {}

    def get(recipe):
        if recipe not in made:
            if "mappo" in recipe:
                pytest.importorskip("skrl")
            out = tmp_path_factory.mktemp(recipe) / "run"
            _recipe_main(recipe)(["--out-dir", str(out)])
            made[recipe] = out
        return made[recipe]

    return get


def _nan_first_float(ck):
    """NaN in the first floating-point tensor of ``state.pt``, wherever it is nested."""
    import torch

    def walk(value):
        if isinstance(value, dict):
            return any(walk(v) for v in value.values())
        if isinstance(value, (list, tuple)):
            return any(walk(v) for v in value)
        if isinstance(value, torch.Tensor) and value.is_floating_point() and value.numel():
            value.view(-1)[0] = float("nan")
            return True
        return False

    state = _tensors(ck)
    assert walk(state)
    _save_tensors(ck, state)


def _multiplier(value):
    """Every ``multiplier`` under ``state.json``'s ``lagrangian`` set to ``value`` (JSON text)."""

    def change(text):
        info = json.loads(text)

        def walk(d):
            for k, v in d.items():
                if k == "multiplier":
                    d[k] = "@@"
                elif isinstance(v, dict):
                    walk(v)

        walk(info["lagrangian"])
        return json.dumps(info).replace('"@@"', value)

    return _state_json(change)


#: name -> (craft, the words the refusal must name); for every recipe.
RECIPE_CASES = {
    "state.pt truncated": (
        lambda ck: (ck / "state.pt").write_bytes((ck / "state.pt").read_bytes()[:999]),
        ("state.pt",),
    ),
    "state.pt pickled": (_pickled, ("state.pt",)),
    "state.pt NaN tensor": (_nan_first_float, ("state.pt", "non-finite")),
    "state.json NaN": (CHECKPOINT_CASES["state.json NaN"][0], ("state.json",)),
    "state.json bad steps": (CHECKPOINT_CASES["state.json bad steps"][0], ("state.json",)),
    "normalization NaN": (CHECKPOINT_CASES["normalization NaN"][0], ("normalization.npz",)),
}
#: The Lagrangian recipes' multiplier, crafted in a real checkpoint's state.json.
LAGRANGIAN_CASES = {
    "multiplier NaN": (_multiplier("NaN"), ("state.json",)),
    "multiplier 1e308": (_multiplier("1e308"), ("state.json", "multiplier")),
    "multiplier -1": (_multiplier("-1.0"), ("state.json", "multiplier")),
}


#: skrl MAPPO's ``env_state.npz`` (its checkpoints between two rollouts: the environments,
#: the agents' last observations, the loop's timestep), crafted in a real checkpoint.
MAPPO_ENV_CASES = {
    "env_state skrl.obs NaN": (
        _env_state(_put("skrl.obs", _nan_at_first)), ("env_state.npz", "skrl.obs", "NaN"),
    ),
    "env_state skrl.obs shape": (
        _env_state(_put("skrl.obs", lambda a: a[:, :1])), ("env_state.npz", "skrl.obs", "shape"),
    ),
    "env_state skrl.timestep negative": (
        _env_state(_put("skrl.timestep", lambda a: a - 10**6)),
        ("env_state.npz", "skrl.timestep"),
    ),
    "env_state skrl.obs missing": (
        _env_state(lambda arrays: arrays.pop("skrl.obs")), ("env_state.npz", "skrl.obs"),
    ),
    "env_state world NaN": (
        _env_state(_put("env.world.uav_vel", _nan_at_first)),
        ("env_state.npz", "env.world.uav_vel"),
    ),
    "env_state truncated": (
        lambda ck: (ck / "env_state.npz").write_bytes((ck / "env_state.npz").read_bytes()[:999]),
        ("env_state.npz",),
    ),
}  # fmt: skip


def _resume_recipe(recipe, out, capsys):
    ck = out / "checkpoints" / "step_128"
    with pytest.raises(SystemExit) as exc:
        _recipe_main(recipe)(["--out-dir", str(out), "--resume", str(ck)])
    return exc.value, capsys.readouterr().err


def _tree(path):
    """Every file's bytes under ``path``, by its name within it."""
    files = (p for p in sorted(path.rglob("*")) if p.is_file() and not p.is_symlink())
    return {str(p.relative_to(path)): p.read_bytes() for p in files}


@pytest.mark.parametrize(
    "recipe, case",
    [(r, c) for r in RECIPES for c in RECIPE_CASES]
    + [(r, c) for r in RECIPES if "lagrangian" in r for c in LAGRANGIAN_CASES]
    + [(r, c) for r in RECIPES if "mappo" in r for c in MAPPO_ENV_CASES],
)
def test_each_recipe_refuses_a_crafted_checkpoint_in_one_line(
    recipe, case, recipe_runs, tmp_path, outside, capsys
):
    out = _copy(recipe_runs(recipe), tmp_path)
    capsys.readouterr()  # the reference run's own lines
    craft, named = {**RECIPE_CASES, **LAGRANGIAN_CASES, **MAPPO_ENV_CASES}[case]
    craft(out / "checkpoints" / "step_128")
    before, precious = _tree(out), outside.read_bytes()
    exc, err = _resume_recipe(recipe, out, capsys)
    _refused(exc, err, *named, "step_128")
    assert outside.read_bytes() == precious
    after = {p: b for p, b in _tree(out).items() if p != ".uasep-run.lock"}
    changed = sorted(p for p in {*before, *after} if before.get(p) != after.get(p))
    assert not changed, changed  # the refused run changed nothing, not even its own folder


@pytest.mark.parametrize(
    "recipe, name",
    [(r, n) for r in RECIPES
     for n in ("state.pt", "state.json", "normalization.npz", "policy.zip")]
    + [(r, "env_state.npz") for r in RECIPES if r != "lean"],  # the lean loop's has none
)  # fmt: skip
def test_each_recipe_refuses_a_checkpoint_file_linked_out(
    recipe, name, recipe_runs, tmp_path, outside, capsys
):
    out = _copy(recipe_runs(recipe), tmp_path)
    capsys.readouterr()  # the reference run's own lines
    target = out / "checkpoints" / "step_128" / name
    shutil.copy(target, outside)  # a valid file, but outside the folder
    before = outside.read_bytes()
    target.unlink()
    target.symlink_to(outside)
    exc, err = _resume_recipe(recipe, out, capsys)
    _refused(exc, err, name)
    assert outside.read_bytes() == before
