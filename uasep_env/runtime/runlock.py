"""One process per run folder: a folder is claimed for a run's whole life.

Two training runs started together into one fresh ``--out-dir`` would both find it empty and
both write there (their ``progress.csv`` rows interleaved). :func:`claim_run_folder` takes an
exclusive ``flock`` on a lock file in the folder, held until the process ends: the second run
fails at once with one line naming the folder and the process that holds it. The kernel
releases the lock when its holder dies, however it dies (a kill, a crash, a power cut), so a
folder left by a dead run is never blocked and ``--resume`` works as before; the lock file
stays behind, empty of meaning, and is reused.

Where ``fcntl`` is missing (Windows) the claim is a no-op.
"""

from __future__ import annotations

import datetime
import os
import socket
import time
from pathlib import Path

from uasep_env.runtime.runfiles import open_lock

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "LOCK_NAME",
    "RunFolderBusy",
    "claim_run_folder",
    "is_own_lock",
    "release_run_folder",
]

#: The lock file a claimed folder holds (not a run's output: ignored when a folder's
#: emptiness is checked).
LOCK_NAME = ".uasep-run.lock"

# Descriptors held open for the life of the process (closing one would release its lock).
_HELD: dict[Path, int] = {}


class RunFolderBusy(RuntimeError):
    """Another live process has claimed the folder (the message names it)."""


def claim_run_folder(folder: str | Path) -> Path:
    """Claim ``folder`` (created if needed) for this process until it ends.

    Claiming a folder this process already holds is a no-op.

    Args:
        folder: The run folder.

    Returns:
        The lock file's path.

    Raises:
        RunFolderBusy: Another live process holds it: one line naming the folder and that
            process (pid, host, start time).
        RunFileRefused: The lock file is a link or not a regular file (one line; nothing
            is written through it).
        OSError: The folder or the lock file cannot be made.
    """
    folder = Path(folder)
    key = folder.resolve()
    lock = folder / LOCK_NAME
    if key in _HELD or fcntl is None:
        return lock
    folder.mkdir(parents=True, exist_ok=True)
    fd = open_lock(lock)  # never through a link, never a FIFO (runfiles)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = ""
        for _ in range(20):  # the holder writes who it is just after it takes the lock
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip()
            if holder:
                break
            time.sleep(0.01)
        os.close(fd)
        holder = holder or "another process"
        raise RunFolderBusy(
            f"{folder} is in use by another run ({holder}); wait for it to end or choose "
            "another folder"
        ) from None
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%SZ")
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}, since {stamp}\n".encode(), 0)
    _HELD[key] = fd
    return lock


def release_run_folder(folder: str | Path) -> None:
    """Release a claim of this process early (it ends with the process anyway)."""
    fd = _HELD.pop(Path(folder).resolve(), None)
    if fd is not None:
        os.close(fd)


def is_own_lock(path: str | Path) -> bool:
    """Whether ``path`` is the lock file this process holds (not merely a file of its name).

    A folder's emptiness ignores the lock only then: anything else named
    :data:`LOCK_NAME` (a link, a FIFO, another file) counts as content.
    """
    path = Path(path)
    fd = _HELD.get(path.parent.resolve())
    if fd is None:
        return False
    try:
        st, held = os.lstat(path), os.fstat(fd)
    except OSError:
        return False
    return (st.st_dev, st.st_ino) == (held.st_dev, held.st_ino)
