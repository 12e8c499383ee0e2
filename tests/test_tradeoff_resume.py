"""The trade-off sweep survives kills and full disks without losing or mixing rows."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S, fill_disk

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "baselines"))

import sweep_rows  # noqa: E402
import tradeoff  # noqa: E402

# A cheap sweep: the APF on 10-19 s episodes, one evaluation call (and one CSV rewrite) per
# setting, so that a kill can land between any two of them.
SCRIPT = """
import sys
sys.path.insert(0, {baselines!r})
import tradeoff
from tradeoff import APF, Method, _scaled
# The package module holds the table the sweep reads (baselines/tradeoff.py wraps it).
tradeoff._impl.METHODS = (Method(name="apf", label="APF", knob="margin scale",
    values=tradeoff.SCALES, default=1.0,
    policy=lambda c, s: APF(c, _scaled(APF.margin_gains, s)),
    config=lambda v: {{"episode_duration": 10.0 + 4 * v}}),)
tradeoff.main(["--methods", "apf", "--paper-episodes", "1", "--bank-episodes", "1",
               "--workers", "1", "--out", sys.argv[1]])
"""


def _start(out):
    code = SCRIPT.format(baselines=str(ROOT / "baselines"))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-c", code, str(out)]
    return subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )


def _n_rows(csv_path):
    return len(sweep_rows.read_rows(csv_path))


@pytest.mark.slow
def test_a_killed_sweep_resumes_to_the_uninterrupted_files(tmp_path):
    ref = tmp_path / "ref"
    p = _start(ref)
    assert p.wait(timeout=HANG_GUARD_S) == 0, p.stderr.read()
    expected = (ref / "tradeoff.csv").read_bytes()
    assert expected.count(b"\n") == 1 + 9 * 2

    out = tmp_path / "run"
    rng = np.random.default_rng(1)
    target = 0
    for _kill in range(3):
        target = min(17, target + int(rng.integers(1, 7)))
        p = _start(out)
        while p.poll() is None and _n_rows(out / "tradeoff.csv") < target:
            time.sleep(0.01)
        time.sleep(float(rng.uniform(0, 0.05)))
        p.send_signal(signal.SIGKILL)
        p.wait()
        # Every row that was written is whole: nothing to drop, nothing torn.
        text = (out / "tradeoff.csv").read_text()
        assert text.endswith("\n") and _n_rows(out / "tradeoff.csv") == text.count("\n") - 1
    p = _start(out)
    assert p.wait(timeout=HANG_GUARD_S) == 0, p.stderr.read()
    assert (out / "tradeoff.csv").read_bytes() == expected
    assert (out / "tradeoff.md").read_text() == (ref / "tradeoff.md").read_text()


def _rows(n, count=3):
    return [{"method": "apf", "knob": "k", "value": float(v), "dataset": "paper", "n": float(n),
             "x": 1.5} for v in range(count)]  # fmt: skip


def test_a_full_disk_keeps_the_finished_rows(tmp_path, monkeypatch):
    path = tmp_path / "tradeoff.csv"
    sweep_rows.write_rows(path, _rows(20))
    before = path.read_bytes()
    fill_disk(monkeypatch)
    with pytest.raises(OSError, match="No space left on device; the previous file"):
        sweep_rows.write_rows(path, _rows(20, 4))
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert len(sweep_rows.read_rows(path)) == 3  # the resume still reads every finished row


def test_a_torn_last_row_is_dropped_and_a_damaged_middle_row_named(tmp_path, capsys):
    path = tmp_path / "tradeoff.csv"
    sweep_rows.write_rows(path, _rows(20))
    text = path.read_text()
    path.write_text(text[:-6])  # cut mid-row: 'could not convert string to float' before
    assert len(sweep_rows.read_rows(path)) == 2
    assert "dropping its torn last row" in capsys.readouterr().out
    lines = text.splitlines(keepends=True)
    path.write_text(lines[0] + lines[1][:10] + "\n" + "".join(lines[2:]))
    with pytest.raises(SystemExit, match="line 2 is damaged"):
        sweep_rows.read_rows(path)
    path.write_text("")
    assert sweep_rows.read_rows(path) == []


def test_rows_of_other_episode_counts_are_refused_not_mixed(tmp_path):
    path = tmp_path / "tradeoff.csv"
    sweep_rows.write_rows(path, _rows(20))
    with pytest.raises(SystemExit, match="holds paper rows of 20 episodes, this run asks for 5"):
        tradeoff.run(tradeoff.METHODS[:1], 5, 1, 1, path)
    assert len(sweep_rows.read_rows(path)) == 3
