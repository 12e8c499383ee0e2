"""The one way the package writes a file: all or nothing.

Every output (evaluation JSON/CSV and figures, training progress, validation, checkpoints and
their ``latest`` pointer, the trade-off tables, results files, policy checkpoints) is written by
:func:`atomic_output` or :func:`atomic_write`: the bytes go to a temporary file in the target's
folder, which is flushed, ``fsync``-ed and renamed over the target (``os.replace``, atomic on
POSIX), and the folder is ``fsync``-ed so the rename itself survives a power cut. A kill at any
point leaves the old file or the new one, never a mix; an error (a full disk) removes the
temporary file, leaves the old file as it was, and raises an :class:`OSError` whose message is
one line naming the target. :func:`atomic_symlink` swaps a symbolic link the same way.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_output", "atomic_symlink", "atomic_write", "fsync_dir"]

# Indirection so that tests can simulate a full disk (``monkeypatch.setattr(atomic, "_open",
# ...)``) for every writer at once.
_open = open


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


def _one_line(path: Path, err: OSError) -> OSError:
    reason = err.strerror or str(err) or type(err).__name__
    message = f"cannot write {path}: {reason}; the previous file, if any, is unchanged"
    return type(err)(err.errno, message) if err.errno else OSError(message)


@contextlib.contextmanager
def atomic_output(path: str | Path, mode: str = "wb", **kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; on a clean exit it replaces ``path``.

    Args:
        path: The target (its folders are created).
        mode: ``"wb"`` or ``"w"`` (text).
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
    tmp = _temp_name(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fh = _open(tmp, mode, **kwargs)
    except OSError as err:
        raise _one_line(target, err) from err
    try:
        try:
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


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically.

    Args:
        path: The target (its folders are created).
        data: The whole content.

    Returns:
        The path written.

    Raises:
        OSError: See :func:`atomic_output`.
    """
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with atomic_output(path, "wb") as fh:
        fh.write(raw)
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
