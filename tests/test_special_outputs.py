"""Outputs that are not plain files (issue 31 B1): a device, a FIFO or a stream is written
through or refused, never replaced by a regular file; a symbolic link stays a link and a
file keeps its permission bits.

Nothing here writes to a device of this machine: /dev/null is only classified, device nodes
are made in tmp_path (or faked), and streams are a subprocess's own stdout.
"""

from __future__ import annotations

import os
import re
import socket
import stat
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S

from uasep_env.runtime import atomic
from uasep_env.runtime.atomic import atomic_output, atomic_write, output_kind

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ every package writer


def _write_bytes(path):
    atomic_write(path, b"bytes\n")


def _write_text(path):
    with atomic_output(path, "w") as fh:
        fh.write("text\n")


def _write_json(path):
    from uasep_env.runtime.jsonio import write_json

    write_json({"a": [1, 2.5, None]}, path)


def _save_policy(path):
    from uasep_env.policies.checkpoint_reader import read_checkpoint
    from uasep_env.policies.learned import save_policy

    shipped = ROOT / "baselines" / "checkpoints" / "ppo_shared.zip"
    meta, weights, mean, var = read_checkpoint(shipped)
    save_policy(path, meta, weights, mean, var)


def _write_npz(path):
    from uasep_env.real_traffic import DEFAULT_PATH
    from uasep_env.real_traffic.fileformat import read_npz, write_npz

    arrays, meta = read_npz(DEFAULT_PATH)
    write_npz(path, arrays, meta)


def _save_figure(path):
    pytest.importorskip("matplotlib")
    from uasep_env.viz.figure_parts import _new_figure, _save

    fig = _new_figure((2, 2))
    fig.add_subplot().plot([0, 1], [1, 0])
    _save(fig, Path(path), dpi=20)


def _eval_csv(path):
    from uasep_env.evaluation import main

    code = main(["--quiet", "--config", "episode_duration=1", "--csv", str(path)])
    assert code == 0


# Targets are named *.png: the figure writer takes its format from the suffix.
WRITERS = {
    "atomic_write": _write_bytes,
    "atomic_output": _write_text,
    "write_json": _write_json,
    "save_policy": _save_policy,
    "write_npz": _write_npz,
    "figure": _save_figure,
    "uasep-eval --csv": _eval_csv,
}


def _read_fifo_in_background(fifo: Path) -> tuple[threading.Thread, list[bytes]]:
    got: list[bytes] = []

    def read() -> None:
        with open(fifo, "rb") as fh:
            got.append(fh.read())

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t, got


@pytest.mark.parametrize("writer", WRITERS)
def test_every_writer_writes_through_a_fifo_and_leaves_it_a_fifo(tmp_path, writer):
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    t, got = _read_fifo_in_background(fifo)
    WRITERS[writer](fifo)
    t.join(HANG_GUARD_S)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode), "the FIFO was replaced by a regular file"
    assert got and len(got[0]) > 0
    assert not [p for p in tmp_path.iterdir() if p != fifo], "a temporary file was left"


@pytest.mark.parametrize("writer", WRITERS)
def test_every_writer_keeps_a_link_a_link_and_a_file_its_mode(tmp_path, writer):
    real = tmp_path / "data" / "real.png"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.png"
    link.symlink_to(Path("data") / "real.png")
    WRITERS[writer](link)
    assert link.is_symlink() and os.readlink(link) == str(Path("data") / "real.png")
    assert real.read_bytes() not in (b"old", b"")

    private = tmp_path / "private.png"
    private.write_bytes(b"old")
    private.chmod(0o600)
    WRITERS[writer](private)
    assert stat.S_IMODE(private.stat().st_mode) == 0o600
    assert private.read_bytes() != b"old"


# ---------------------------------------------------------------- classification, refusal


def test_dev_null_is_classified_as_a_device_without_being_opened(monkeypatch):
    def no_open(*args, **kwargs):
        raise AssertionError("output_kind must not open anything")

    monkeypatch.setattr(atomic, "_open", no_open)
    assert output_kind("/dev/null") == "device"
    for stream in ("/dev/stdout", "/dev/stderr", "/dev/fd/1", "/proc/self/fd/2"):
        assert output_kind(stream) == "stream"


def test_a_character_device_node_is_written_through_never_replaced(tmp_path):
    node = tmp_path / "null"
    try:
        os.mknod(node, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # the null device
        with open(node, "wb"):
            pass
    except OSError as err:  # not root, or tmp mounted nodev
        pytest.skip(f"cannot make a device node here: {err}")
    atomic_write(node, b"{}\n")
    assert stat.S_ISCHR(os.lstat(node).st_mode)
    assert os.listdir(tmp_path) == ["null"]


def test_a_block_device_or_a_socket_is_refused_before_anything_is_opened(tmp_path, monkeypatch):
    opened = []
    monkeypatch.setattr(atomic, "_open", lambda *a, **k: opened.append(a))
    fake = tmp_path / "disk"
    fake.write_bytes(b"")
    real_stat = os.stat

    def stat_as_block(path, *args, **kwargs):
        st = real_stat(path, *args, **kwargs)
        if Path(path) == fake:
            return os.stat_result((stat.S_IFBLK | 0o660, *tuple(st)[1:]))
        return st

    monkeypatch.setattr(atomic.os, "stat", stat_as_block)
    with pytest.raises(OSError, match=r"cannot write .*disk: it is a block device"):
        atomic_write(fake, b"x")
    monkeypatch.undo()

    sock_path = tmp_path / "s"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(sock_path))
        with pytest.raises(OSError, match=r"it is a socket") as info:
            atomic_write(sock_path, b"x")
    assert "\n" not in str(info.value)
    assert stat.S_ISSOCK(os.lstat(sock_path).st_mode)
    assert not opened


def test_a_read_only_file_is_refused_as_open_would_refuse_it(tmp_path, monkeypatch):
    path = tmp_path / "ro.json"
    path.write_text("old")
    path.chmod(0o444)
    monkeypatch.setattr(atomic.os, "access", lambda p, m: False)  # not root
    with pytest.raises(PermissionError, match=r"cannot write .*ro.json: permission denied"):
        atomic_write(path, "new")
    assert path.read_text() == "old"
    monkeypatch.undo()
    if os.geteuid() == 0:  # root may write it, as open() would: the mode is kept
        atomic_write(path, "new")
        assert path.read_text() == "new" and stat.S_IMODE(path.stat().st_mode) == 0o444


def test_uasep_eval_refuses_a_socket_output_before_running(tmp_path, capsys):
    from uasep_env.evaluation import main

    sock_path = tmp_path / "s"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(sock_path))
        assert main(["--quiet", "--json", str(sock_path)]) == 2
    err = capsys.readouterr().err
    assert "argument --json" in err and "socket" in err and err.count("\n") == 1


# ------------------------------------------------------------------------------- streams

_STREAM_WRITE = """
import sys
from uasep_env.runtime.atomic import atomic_write
sys.stdout.write("before\\n"); sys.stdout.flush()
atomic_write(sys.argv[1], "through\\n")
sys.stdout.write("after\\n")
"""


@pytest.mark.parametrize("name", ["/dev/stdout", "/dev/fd/1", "/proc/self/fd/1", "link"])
def test_a_stream_is_written_through_its_descriptor_at_its_offset(tmp_path, name):
    # stdout redirected to a regular file: that file must be appended to, not replaced.
    target = name
    if name == "link":
        target = str(tmp_path / "out")
        os.symlink("/proc/self/fd/1", target)
    log = tmp_path / "log.txt"
    log.write_text("head\n")
    inode = log.stat().st_ino
    with open(log, "a") as fh:
        subprocess.run(
            [sys.executable, "-c", _STREAM_WRITE, target],
            stdout=fh,
            check=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            timeout=HANG_GUARD_S,
        )
    assert log.read_text() == "head\nbefore\nthrough\nafter\n"
    assert log.stat().st_ino == inode
    if name == "link":
        assert os.readlink(target) == "/proc/self/fd/1"


def test_uasep_eval_csv_to_stdout_goes_down_the_pipe(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "uasep_env.evaluation", "--quiet", "--config",
         "episode_duration=1", "--csv", "/dev/stdout"],
        capture_output=True, text=True, check=True, cwd=ROOT, timeout=HANG_GUARD_S,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    lines = out.stdout.splitlines()
    assert lines[0].startswith("policy,seed,family") and lines[1].startswith("apf,0,")
    assert np.isfinite(float(lines[1].split(",")[5]))


# ------------------------------------------------------------ no writer bypasses the helper

_BYPASS = re.compile(
    r"os\.replace\(|\.write_text\(|\.write_bytes\(|open\([^)]*['\"]w|(?:fig|plt)\.savefig\((?!fh\b)"
)


def test_no_writer_bypasses_uasep_env_atomic():
    # Every file the package and its scripts write goes through uasep_env.runtime.atomic (whose
    # behaviour the tests above check per writer); appended logs and rundir.publish_dir's
    # folder renames are the exceptions, by design.
    found = []
    for folder in ("uasep_env", "baselines", "train", "tools"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path.name == "atomic.py":
                continue
            for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                code = line.split("#")[0]
                if _BYPASS.search(code):
                    found.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert not found, "\n".join(found)
