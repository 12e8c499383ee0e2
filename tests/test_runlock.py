"""One run per folder (issue 31 B5): two training runs started together into one fresh
--out-dir cannot both run; a folder left by a dead run still resumes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from conftest import HANG_GUARD_S

pytest.importorskip("fcntl")

from uasep_env.runtime.runlock import LOCK_NAME, RunFolderBusy, claim_run_folder, release_run_folder

ROOT = Path(__file__).resolve().parents[1]

# A recipe's start: claim the folder (train/rundir.prepare_out_dir, as ppo_shared.py and
# mappo.py call it), write a progress row, then hold the folder until told to stop.
_RUN = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    sys.path.insert(0, "train")
    import rundir
    out, go, resume = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    while not go.exists():
        time.sleep(0.005)
    try:
        rundir.prepare_out_dir(out, resume, False)
    except SystemExit as err:
        print(err.code, flush=True)
        sys.exit(1)
    log = rundir.ProgressLog(out / "progress.csv", ("agent_steps",))
    log.write({"agent_steps": 1})
    print("running", flush=True)
    sys.stdin.read()  # hold the folder until stdin closes (or a kill)
    """
)


def _start(out: Path, go: Path, resume: str = "") -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", _RUN, str(out), str(go), resume],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip


def test_two_runs_started_together_into_one_fresh_folder_one_fails_naming_it(tmp_path):
    for k in range(4):  # a few races, each started at the same instant
        out, go = tmp_path / f"run{k}", tmp_path / f"go{k}"
        procs = [_start(out, go) for _ in range(2)]
        time.sleep(1.0)  # both imported and waiting
        go.touch()
        lines = []
        for p in procs:
            lines.append(p.stdout.readline().strip())
        winners = [p for p, line in zip(procs, lines, strict=True) if line == "running"]
        losers = [line for line in lines if line != "running"]
        for p in procs:
            p.stdin.close()
            p.wait(timeout=HANG_GUARD_S)
        assert len(winners) == 1, lines
        assert len(losers) == 1 and str(out) in losers[0] and "in use by another run" in losers[0]
        assert "\n" not in losers[0]
        rows = (out / "progress.csv").read_text().splitlines()
        assert rows == ["agent_steps", "1"], rows  # one run's rows only


def test_a_folder_left_by_a_killed_run_resumes(tmp_path):
    out, go = tmp_path / "run", tmp_path / "go"
    go.touch()
    first = _start(out, go)
    assert first.stdout.readline().strip() == "running"
    busy = _start(out, go, resume="checkpoints/latest")
    assert "in use by another run" in busy.stdout.readline()
    busy.wait(timeout=HANG_GUARD_S)
    first.send_signal(signal.SIGKILL)
    first.wait(timeout=HANG_GUARD_S)
    assert (out / LOCK_NAME).exists()  # the stale lock file stays; its lock died with it
    again = _start(out, go, resume="checkpoints/latest")
    assert again.stdout.readline().strip() == "running"
    again.stdin.close()
    again.wait(timeout=HANG_GUARD_S)
    # A fresh start (no --resume) is still refused: the folder holds a run's files.
    fresh = _start(out, go)
    assert "is not empty" in fresh.stdout.readline()
    fresh.wait(timeout=HANG_GUARD_S)


def test_the_lock_file_alone_does_not_make_a_folder_used(tmp_path):
    sys.path.insert(0, str(ROOT / "train"))
    import rundir

    claim_run_folder(tmp_path)
    release_run_folder(tmp_path)
    rundir.prepare_out_dir(tmp_path, "", False)  # only the lock file there: a fresh run
    rundir.prepare_out_dir(tmp_path, "", False)  # this process holds it: claiming again is fine
    release_run_folder(tmp_path)


def test_a_claim_held_elsewhere_is_refused_with_its_holder(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys; from uasep_env.runtime.runlock import claim_run_folder; "
         "claim_run_folder(sys.argv[1]); print('held', flush=True); sys.stdin.read()",
         str(tmp_path)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(RunFolderBusy, match=rf"pid {holder.pid} on "):
        claim_run_folder(tmp_path)
    holder.stdin.close()
    holder.wait(timeout=HANG_GUARD_S)
    claim_run_folder(tmp_path)  # free once its holder ended
    release_run_folder(tmp_path)
