"""A run folder's files, opened as untrusted input: inside the folder, regular, bounded.

A run folder (``--out-dir``, a checkpoint folder given to ``--resume``) may have been
copied from elsewhere or tampered with. Before a byte of one of its files is read,
:func:`read_inside` refuses an entry that is a link leading out of the folder, one that is
not a regular file (a FIFO would block the reader forever, ``/dev/zero`` never ends) and one
over a size; the file is then opened without following links (``O_NOFOLLOW``, so a link
swapped in after the check is refused too) and never read past the size.
:func:`open_lock` opens the folder's lock file the same way for writing.

Failures are :class:`RunFileRefused` (a ``ValueError``) of one line naming the path; the run
folder's code (:mod:`uasep_env.training.rundir`) turns them into its one-line refusal.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

from uasep_env.runtime.jsonio import loads_bounded

__all__ = [
    "MAX_JSON_BYTES",
    "RunFileRefused",
    "check_inside",
    "open_lock",
    "read_inside",
    "read_json_inside",
]

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)  # a FIFO opens at once (then is refused)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)


class RunFileRefused(ValueError):
    """A run folder's entry that is not read (or written): one line naming it and why."""


def _what(mode: int) -> str:
    kinds = {
        stat.S_IFIFO: "a FIFO",
        stat.S_IFCHR: "a character device",
        stat.S_IFBLK: "a block device",
        stat.S_IFSOCK: "a socket",
        stat.S_IFDIR: "a folder",
        stat.S_IFLNK: "a symbolic link",
    }
    return kinds.get(stat.S_IFMT(mode), "a special file")


def check_inside(root: str | Path, path: str | Path, limit: int) -> os.stat_result:
    """Check the entry ``path`` of the folder ``root`` without opening it.

    Links are followed only while they stay inside ``root`` (``checkpoints/latest`` ->
    ``step_N`` is fine, ``state.pt`` -> ``/etc/shadow`` is not).

    Returns:
        The entry's ``stat`` (of the file a link inside leads to).

    Raises:
        RunFileRefused: Missing, a link leading out of ``root``, not a regular file, or
            larger than ``limit`` bytes.
    """
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)
    if os.path.commonpath([real_root, real]) != real_root:
        raise RunFileRefused(f"{path}: a link leading out of {root} (to {real}); refused")
    try:
        st = os.lstat(real)
    except FileNotFoundError:
        raise RunFileRefused(f"{path}: missing") from None
    except OSError as err:
        raise RunFileRefused(f"{path}: cannot be read ({err.strerror or err})") from None
    if not stat.S_ISREG(st.st_mode):
        raise RunFileRefused(f"{path}: {_what(st.st_mode)}, not a regular file; refused")
    if st.st_size > limit:
        raise RunFileRefused(f"{path}: {st.st_size:,} bytes, limit {limit:,}")
    return st


def read_inside(root: str | Path, path: str | Path, limit: int) -> bytes:
    """The bytes of the entry ``path`` of the folder ``root`` (:func:`check_inside`).

    Opened without following links or blocking; at most ``limit`` bytes are read, whatever
    the file grew to since it was checked.

    Raises:
        RunFileRefused: See :func:`check_inside`; or the file changed into something else.
    """
    check_inside(root, path, limit)
    real = os.path.realpath(path)
    try:
        fd = os.open(real, os.O_RDONLY | _NOFOLLOW | _NONBLOCK | _CLOEXEC)
    except OSError as err:
        raise RunFileRefused(f"{path}: cannot be read ({err.strerror or err})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):  # swapped after the check
            raise RunFileRefused(f"{path}: {_what(st.st_mode)}, not a regular file; refused")
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > limit:
        raise RunFileRefused(f"{path}: more than {limit:,} bytes")
    return b"".join(chunks)


#: The largest JSON a driver reads from a run folder (a report, a validation, a sweep).
MAX_JSON_BYTES = 64 * 2**20


def read_json_inside(root: str | Path, path: str | Path, limit: int = MAX_JSON_BYTES) -> Any:
    """The JSON entry ``path`` of the folder ``root``, read and parsed within limits.

    :func:`read_inside`, then the bounded JSON reader
    (:func:`~uasep_env.runtime.jsonio.loads_bounded`).

    Raises:
        ValueError: Refused (:class:`RunFileRefused`) or not strict JSON within the limits;
            one line naming ``path``.
    """
    raw = read_inside(root, path, limit)
    try:
        return loads_bounded(raw)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def open_lock(path: str | Path) -> int:
    """Open (or create) a run folder's lock file for writing: a descriptor.

    Never through a link (``O_NOFOLLOW``: a lock that is a link to another file would have
    this run write its name into that file) and only a regular file (a FIFO or a device is
    refused, not written to).

    Raises:
        RunFileRefused: The lock file is a link or not a regular file (one line).
        OSError: It cannot be made (a read-only folder).
    """
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW | _NONBLOCK | _CLOEXEC, 0o644)
    except OSError:
        mode = os.lstat(path).st_mode if os.path.lexists(path) else stat.S_IFREG
        if not stat.S_ISREG(mode):  # ELOOP: O_NOFOLLOW met a link; EISDIR: a folder
            raise RunFileRefused(
                f"{path}: {_what(mode)}, not a lock file; refused (remove it)"
            ) from None
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise RunFileRefused(f"{path}: {_what(st.st_mode)}, not a lock file; refused (remove it)")
    return fd
