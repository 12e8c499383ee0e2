"""The one way the package writes a file: all or nothing.

Every output (evaluation JSON/CSV and figures, training progress, validation, checkpoints and
their ``latest`` pointer, the trade-off tables, results files, policy checkpoints) is written by
:func:`atomic_output` or :func:`atomic_write`: the bytes go to a temporary file in the target's
folder, which is flushed, ``fsync``-ed and renamed over the target (``os.replace``, atomic on
POSIX), and the folder is ``fsync``-ed so the rename itself survives a power cut. A kill at any
point leaves the old file or the new one, never a mix; an error (a full disk) removes the
temporary file, leaves the old file as it was, and raises an :class:`OSError` whose message is
one line naming the target. :func:`atomic_symlink` swaps a symbolic link the same way.

What the target already is decides how it is written (:func:`output_kind`):

* a regular file, or nothing: replaced atomically as above; an existing file keeps its
  permission bits (and, where allowed, its owner), and one the user may not write is refused
  as :func:`open` would refuse it;
* a symbolic link: the file it points to is replaced, the link stays a link;
* a standard stream (``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N``, ``/proc/self/fd/N``):
  written through that open descriptor, at its current offset (``--csv /dev/stdout > f``
  fills ``f`` like any program's output);
* a character device or a FIFO (``/dev/null``, a named pipe): written through, in place;
* anything else (a block device, a socket, a folder): refused, nothing written.

A run folder's own files (``progress.csv``, ``validation.json``, checkpoints) are written
with ``replace_links=True``: whatever the entry is (a link, a FIFO, a device), it is replaced
by a regular file, never written through; a run folder copied from elsewhere cannot make a
run write outside it. A user's ``--json``/``--csv`` target keeps the rules above.

Written-through outputs are not atomic (a stream cannot be rolled back): that is what the
user asked for by naming one. A special file is never replaced by a regular one.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

__all__ = [
    "atomic_copy",
    "atomic_output",
    "atomic_symlink",
    "atomic_write",
    "fsync_dir",
    "output_kind",
]

# Indirection so that tests can simulate a full disk (``monkeypatch.setattr(atomic, "_open",
# ...)``) for every writer at once.
_open = open


#: ``/dev/stdout`` and friends: the paths that name one of the process's descriptors.
_STREAM = re.compile(
    r"/dev/(?:std(?P<std>in|out|err)|fd/(?P<fd>\d+))|/proc/(?P<pid>self|\d+)/fd/(?P<pfd>\d+)"
)
_STD_FDS = {"in": 0, "out": 1, "err": 2}


def _stream_fd(path: Path) -> int | None:
    """The descriptor of this process that ``path`` names, directly or through links, or None.

    Links are followed one at a time (``/dev/stdout`` -> ``/proc/self/fd/1``): resolving
    them all at once would go through the descriptor to the file behind it, and that file
    would then be replaced instead of written through.
    """
    current = os.path.abspath(path)
    for _ in range(40):  # the kernel's own limit on a chain of links
        m = _STREAM.fullmatch(current)
        if m is not None and m["pid"] in (None, "self", str(os.getpid())):
            return _STD_FDS[m["std"]] if m["std"] else int(m["fd"] or m["pfd"])
        head, name = os.path.split(current)
        real_head = os.path.realpath(head)
        if real_head != head:  # a link among the folders: look at the real folder
            current = os.path.join(real_head, name)
        elif os.path.islink(current):
            current = os.path.normpath(os.path.join(head, os.readlink(current)))
        else:
            return None
    return None


def output_kind(path: str | Path) -> str:
    """How :func:`atomic_output` would write ``path``; nothing is opened or written.

    Returns:
        ``"stream"`` (a descriptor of this process: written through), ``"device"`` (a
        character device or FIFO: written through), ``"link"`` (a symbolic link: the file it
        points to is replaced), ``"file"`` (an existing regular file: replaced) or ``"new"``.

    Raises:
        OSError: A target that is never written (a block device, a socket, a folder): one
            line naming the path and what it is.
    """
    p = Path(path)
    if _stream_fd(p) is not None:
        return "stream"
    try:
        st = os.stat(p)
    except OSError:  # nothing there (or no way there): the writer reports what goes wrong
        return "link" if os.path.islink(p) else "new"  # a dangling link: its target is made
    mode = st.st_mode
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
        return "device"
    if stat.S_ISREG(mode):
        return "link" if os.path.islink(p) else "file"
    what = {stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a directory"}
    message = f"cannot write {p}: it is {what.get(stat.S_IFMT(mode), 'a special file')}"
    if stat.S_ISDIR(mode):
        raise IsADirectoryError(errno.EISDIR, message)
    raise OSError(f"{message}; refusing to write to it or replace it")


def _temp_name(path: Path) -> Path:
    """A fresh hidden name beside ``path`` that keeps its suffix (matplotlib reads it)."""
    return path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp{path.suffix}")


def fsync_dir(directory: str | Path) -> None:
    """``fsync`` a folder so that a rename into it is durable (no-op where unsupported)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - some file systems refuse fsync on a folder
        pass
    finally:
        os.close(fd)


def _one_line(path: Path, err: OSError, *, kept: bool = True) -> OSError:
    if (err.strerror or str(err)).startswith(f"cannot write {path}"):  # already one line
        return err
    reason = err.strerror or str(err) or type(err).__name__
    after = "; the previous file, if any, is unchanged" if kept else ""
    message = f"cannot write {path}: {reason}{after}"
    return type(err)(err.errno, message) if err.errno else OSError(message)


def _own_kind(path: Path) -> str:
    """:func:`output_kind` for a run folder's own file: the entry itself is replaced."""
    try:
        st = os.lstat(path)
    except OSError:
        return "new"
    if stat.S_ISDIR(st.st_mode):
        raise IsADirectoryError(errno.EISDIR, f"cannot write {path}: it is a directory")
    return "file" if stat.S_ISREG(st.st_mode) else "new"  # a link or special: replaced


@contextlib.contextmanager
def atomic_output(
    path: str | Path, mode: str = "wb", *, replace_links: bool = False, **kwargs: Any
) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; on a clean exit it replaces ``path``.

    Args:
        path: The target (its folders are created).
        mode: ``"wb"`` or ``"w"`` (text).
        replace_links: A run folder's own file: a link, FIFO or device at ``path`` is
            replaced by the new file, never written through (module docstring).
        **kwargs: Passed to :func:`open` (``newline``, ``encoding``).

    Yields:
        The open temporary file.

    Raises:
        OSError: If writing fails (e.g. a full disk): one line naming ``path``; the old file is
            unchanged and the temporary file removed. Other exceptions propagate unchanged,
            with the same clean-up.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    target = Path(path)
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    kind = _own_kind(target) if replace_links else output_kind(target)
    if kind in ("stream", "device"):
        with _through(target, kind, mode, kwargs) as fh:
            yield fh
        return
    if kind == "link":
        target = Path(os.path.realpath(target))  # replace what it points to, keep the link
    old = os.stat(target) if kind != "new" and target.exists() else None
    if old is not None and not os.access(target, os.W_OK):
        raise PermissionError(
            errno.EACCES,
            f"cannot write {target}: permission denied (mode {stat.filemode(old.st_mode)})",
        )
    tmp = _temp_name(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fh = _open(tmp, mode, **kwargs)
    except OSError as err:
        raise _one_line(target, err) from err
    try:
        try:
            if old is not None:
                _keep_identity(fh.fileno(), old)
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        finally:
            fh.close()
        os.replace(tmp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, OSError):
            raise _one_line(target, err) from err
        raise
    fsync_dir(target.parent)


def _keep_identity(fd: int, old: os.stat_result) -> None:
    """Give the new file the old one's permission bits and, where allowed, its owner."""
    os.fchmod(fd, stat.S_IMODE(old.st_mode))
    if (old.st_uid, old.st_gid) != (os.geteuid(), os.getegid()):
        with contextlib.suppress(OSError):  # only root may give a file away
            os.fchown(fd, old.st_uid, old.st_gid)


@contextlib.contextmanager
def _through(target: Path, kind: str, mode: str, kwargs: dict[str, Any]) -> Iterator[IO[Any]]:
    """Write straight into a stream or a device (not atomic: it cannot be rolled back)."""
    try:
        if kind == "stream":
            fd = _stream_fd(target)
            assert fd is not None
            # A duplicate shares the descriptor's offset: a redirected stdout is appended to.
            fh = os.fdopen(os.dup(fd), mode, **kwargs)
        else:
            fh = _open(target, mode, **kwargs)
    except OSError as err:
        raise _one_line(target, err, kept=False) from err
    try:
        with fh:
            yield fh
    except OSError as err:
        raise _one_line(target, err, kept=False) from err


def atomic_write(path: str | Path, data: bytes | str, *, replace_links: bool = False) -> Path:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically.

    Args:
        path: The target (its folders are created).
        data: The whole content.
        replace_links: A run folder's own file: see :func:`atomic_output`.

    Returns:
        The path written.

    Raises:
        OSError: See :func:`atomic_output`.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with atomic_output(path, "wb", replace_links=replace_links) as fh:
        fh.write(raw)
    return Path(path)


def atomic_copy(source: str | Path, path: str | Path) -> Path:
    """Copy the file ``source`` to ``path`` atomically (streamed: no size is held in memory).

    Raises:
        OSError: ``source`` cannot be read or ``path`` written: one line; ``path`` unchanged.
    """
    with open(source, "rb") as src, atomic_output(path, "wb") as dst:
        shutil.copyfileobj(src, dst, 1 << 20)
    return Path(path)


def atomic_symlink(target: str | Path, link: str | Path) -> Path:
    """Point the symbolic link ``link`` at ``target``, replacing any old link atomically.

    A link is created under a temporary name and renamed over ``link``: a kill leaves either
    the old link or the new one, never none (what unlink-then-symlink would).

    Args:
        target: What the link points to (typically a relative name).
        link: The link's path.

    Returns:
        ``link``.

    Raises:
        OSError: One line naming ``link``, if the link cannot be made.
    """
    link = Path(link)
    tmp = _temp_name(link)
    try:
        os.symlink(target, tmp)
        os.replace(tmp, link)
    except OSError as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise _one_line(link, err) from err
    fsync_dir(link.parent)
    return link
