"""Training killed at random points (SIGKILL) and resumed: never a silent mix of runs."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S, fill_disk

pytest.importorskip("stable_baselines3")

ROOT = Path(__file__).resolve().parents[1]
TRAIN = ROOT / "train" / "ppo_shared.py"
TINY = [
    "--scenario", "crossing", "--n-uavs", "2", "--n-obstacles", "0", "--episode-duration", "10",
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "1", "--hidden", "16",
    "--total-timesteps", "1024", "--checkpoint-every", "256", "--eval-episodes", "1",
    "--no-progress",
]  # fmt: skip
TOTAL = 1024


def _start(out, *extra):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, str(TRAIN), *TINY, "--out-dir", str(out), *extra]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip


def _rows(out):
    path = out / "progress.csv"
    if not path.exists():
        return []
    with path.open() as f:
        return list(csv.DictReader(f))


def _run_killed(out, rows_before_kill, delay, *extra):
    """Start a run and SIGKILL it once progress.csv has that many rows (plus ``delay`` s)."""
    p = _start(out, *extra)
    deadline = time.monotonic() + HANG_GUARD_S
    while p.poll() is None and time.monotonic() < deadline:
        if len(_rows(out)) >= rows_before_kill:
            time.sleep(delay)
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGKILL)
    p.wait()


def _finish(out, *extra):
    p = _start(out, *extra)
    _, err = p.communicate(timeout=HANG_GUARD_S)
    return p.returncode, err


def _key(r):
    return {k: v for k, v in r.items() if k != "wall_s"}


@pytest.mark.slow
def test_a_killed_run_resumes_to_a_consistent_run_or_refuses(tmp_path):
    ref = tmp_path / "ref"
    code, err = _finish(ref)
    assert code == 0, err
    ref_rows = _rows(ref)
    assert int(ref_rows[-1]["agent_steps"]) == TOTAL

    out = tmp_path / "run"
    rng = np.random.default_rng(0)
    _run_killed(out, int(rng.integers(3, 6)), float(rng.uniform(0, 0.3)))
    latest = out / "checkpoints" / "latest"
    code, err = _finish(out)  # a fresh run into the used folder is refused
    assert code == 1 and "is not empty" in err and err.count("\n") == 1
    if not latest.exists():  # killed before the first checkpoint: resume refuses clearly
        code, err = _finish(out, "--resume", str(latest))
        assert code == 1 and "no such checkpoint folder" in err and err.count("\n") == 1
        code, err = _finish(out, "--overwrite")
        assert code == 0, err
        assert [_key(r) for r in _rows(out)] == [_key(r) for r in ref_rows]
        return
    first_resume = int(os.readlink(latest).removeprefix("step_"))
    # Kill the resumed run too, then resume again to the end.
    _run_killed(out, len(_rows(out)) + int(rng.integers(1, 3)), float(rng.uniform(0, 0.3)),
                "--resume", str(latest))  # fmt: skip
    code, err = _finish(out, "--resume", str(latest))
    if code != 0:  # killed while replacing a checkpoint folder: refused, clearly
        assert code == 1 and err.count("\n") == 1 and "no such checkpoint folder" in err, err
        return

    rows = _rows(out)
    steps = [int(r["agent_steps"]) for r in rows]
    episodes = [int(r["episodes"]) for r in rows]
    assert (out / "progress.csv").read_text().count("agent_steps") == 1  # one header
    assert steps == sorted(set(steps)) and steps[-1] == TOTAL  # no row twice, none mixed
    assert episodes == sorted(episodes)  # the episode count continues
    # Up to the first resume point, the rows are the uninterrupted run's, exactly.
    before = [_key(r) for r in rows if int(r["agent_steps"]) <= first_resume]
    assert before == [_key(r) for r in ref_rows if int(r["agent_steps"]) <= first_resume]
    assert os.readlink(latest) == f"step_{TOTAL}"
    state = json.loads((latest / "state.json").read_text())
    assert state["agent_steps"] == TOTAL and state["episodes"] == episodes[-1]
    assert json.loads((out / "validation.json").read_text())["training"]["agent_steps"] == TOTAL
    assert not list(out.rglob(".*.tmp*"))


def test_resume_names_missing_and_incomplete_checkpoints(tmp_path):
    sys.path.insert(0, str(ROOT / "train"))
    import rundir

    with pytest.raises(SystemExit, match="no such checkpoint folder"):
        rundir.check_checkpoint(tmp_path / "nope")
    (tmp_path / "ck").mkdir()
    (tmp_path / "ck" / "state.pt").write_bytes(b"")
    with pytest.raises(SystemExit, match=r"incomplete checkpoint \(missing normalization.npz"):
        rundir.check_checkpoint(tmp_path / "ck")


def test_progress_reader_drops_a_torn_row_and_rewind_truncates(tmp_path):
    sys.path.insert(0, str(ROOT / "train"))
    import rundir

    fields = ("agent_steps", "episodes")
    (tmp_path / "progress.csv").write_text("agent_steps,episodes\n128,1\n256,3\n384,5\n51")
    assert [r["agent_steps"] for r in rundir.read_progress(tmp_path / "progress.csv")] == [
        "128", "256", "384",
    ]  # fmt: skip
    for step in (256, 512):
        (tmp_path / "checkpoints" / f"step_{step}").mkdir(parents=True)
    rundir.rewind(tmp_path, fields, 256)
    assert (tmp_path / "progress.csv").read_text() == "agent_steps,episodes\n128,1\n256,3\n"
    assert not (tmp_path / "checkpoints" / "step_512").exists()
    assert os.readlink(tmp_path / "checkpoints" / "latest") == "step_256"


def test_out_dir_is_refused_unless_resume_or_overwrite(tmp_path):
    sys.path.insert(0, str(ROOT / "train"))
    import rundir

    (tmp_path / "progress.csv").write_text("old")
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(SystemExit, match="is not empty"):
        rundir.prepare_out_dir(tmp_path, "", False)
    with pytest.raises(SystemExit, match="choose one"):
        rundir.prepare_out_dir(tmp_path, "x", True)
    rundir.prepare_out_dir(tmp_path, "", True)
    assert not (tmp_path / "progress.csv").exists() and (tmp_path / "notes.txt").exists()


def test_a_full_disk_while_checkpointing_keeps_the_previous_checkpoint(tmp_path, monkeypatch):

    import torch

    sys.path.insert(0, str(ROOT / "train"))
    import ppo_shared

    torch.set_num_threads(1)
    args = ppo_shared.parse_args([*TINY, "--out-dir", str(tmp_path)])
    cfg = ppo_shared.make_env_config(args)
    venv, model = ppo_shared.build(args, cfg)
    ck = tmp_path / "checkpoints" / "step_0"
    ppo_shared.save_checkpoint(model, venv, cfg, args, ck, {"agent_steps": 0, "wall_s": 0.0})
    before = {p.name: p.read_bytes() for p in ck.iterdir()}
    fill_disk(monkeypatch)
    with pytest.raises(OSError, match=r"cannot write .*state.pt: No space left on device"):
        ppo_shared.save_checkpoint(model, venv, cfg, args, ck, {"agent_steps": 9, "wall_s": 1.0})
    monkeypatch.undo()
    assert {p.name: p.read_bytes() for p in ck.iterdir()} == before
    assert sorted(p.name for p in ck.parent.iterdir()) == ["step_0"]  # no temporary left
