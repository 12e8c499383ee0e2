"""The real-traffic file: a ``.npz`` of plain arrays, written byte-for-byte reproducibly.

Members (all ``.npy``, no object arrays, so nothing is unpickled):

* ``format_version`` -- ``int64`` scalar, :data:`FORMAT_VERSION`;
* ``time_ms`` -- ``int64 (N,)``, each sample's time after its track's first sample (ms);
* ``pos_cm`` -- ``int32 (N, 3)``, positions NED about the track's origin (cm);
* ``vel_cms`` -- ``int32 (N, 3)``, reported ground velocity NED in the origin's frame (cm/s);
* ``track_start`` -- ``int64 (T + 1,)``, the samples of track ``k`` are
  ``track_start[k]:track_start[k + 1]``;
* ``meta`` -- ``uint8``, UTF-8 JSON: the provenance of every track, the build's settings and
  what it dropped.

Integers (cm, ms) make the file independent of the last bits of the platform's maths; the
zip entries carry a fixed date, so rebuilding gives the same bytes. Reading is bounded: the
file, each member, all members together and the JSON have size limits and the members a
compression-ratio limit, checked on the zip's directory before anything is inflated
(:mod:`uasep_env.runtime.boundedzip`, shared with the policy checkpoints); each array's header is
checked (dtype, dimensions, a size that matches its data) before its data is used; the
JSON's nesting, its number of arrays and objects and its keys are checked before it is
parsed. Whatever the bytes, the one error is a :class:`RealTrafficFileError` of one line.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.boundedzip import (
    HOSTILE_FILE_ERRORS,
    check_member,
    check_members,
    read_member,
)
from uasep_env.runtime.jsonio import loads_bounded

__all__ = ["FORMAT_VERSION", "MAX_FILE_BYTES", "RealTrafficFileError", "read_npz", "write_npz"]

#: Version of the layout above; a reader refuses any other.
FORMAT_VERSION = 1
#: Limits on what a reader accepts (bytes): the file, one member once inflated, all members
#: inflated, the JSON (the shipped file is 0.42 MB, its members 0.82 MB inflated, the
#: largest 0.27 MB, the JSON 0.1 MB).
MAX_FILE_BYTES = 32 * 2**20
MAX_MEMBER_BYTES = 16 * 2**20
MAX_TOTAL_BYTES = 32 * 2**20
MAX_META_BYTES = 4 * 2**20
#: The JSON's deepest nesting (the shipped file's is 4) and most arrays and objects (617):
#: each costs Python objects many times its two bytes of text.
MAX_META_DEPTH = 8
MAX_META_CONTAINERS = 50_000
#: Largest compression ratio of a member over 64 KiB (the shipped file's largest is 10.6,
#: the JSON metadata; a zip bomb's is in the hundreds).
MAX_RATIO = 50.0
_MEMBERS = {
    "format_version": (np.int64, 0),
    "time_ms": (np.int64, 1),
    "pos_cm": (np.int32, 2),
    "vel_cms": (np.int32, 2),
    "track_start": (np.int64, 1),
    "meta": (np.uint8, 1),
}
_FIXED_DATE = (1980, 1, 1, 0, 0, 0)


class RealTrafficFileError(ValueError):
    """A real-traffic file is corrupt, too large or of another format version."""


def _one_line(path: Path, err: BaseException) -> RealTrafficFileError:
    detail = " ".join(str(err).split())[:200] or "no detail"
    return RealTrafficFileError(
        f"{path}: not a valid real-traffic file ({type(err).__name__}: {detail})"
    )


def write_npz(path: str | os.PathLike[str], arrays: dict[str, np.ndarray], meta: Any) -> None:
    """Write ``arrays`` and the JSON ``meta`` to ``path`` atomically and reproducibly.

    Args:
        path: Destination ``.npz``.
        arrays: ``time_ms``, ``pos_cm``, ``vel_cms``, ``track_start`` (cast to the file's dtypes).
        meta: JSON-able metadata (written with sorted keys, no whitespace variation).
    """
    text = json.dumps(meta, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    members = dict(arrays)
    members["format_version"] = np.int64(FORMAT_VERSION)
    members["meta"] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name in sorted(_MEMBERS):
            dtype, ndim = _MEMBERS[name]
            arr = np.array(members[name], dtype=dtype, order="C")
            if arr.ndim != ndim:
                raise ValueError(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
            npy = io.BytesIO()
            np.lib.format.write_array(npy, arr, version=(1, 0), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_FIXED_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, npy.getvalue(), compresslevel=9)
    atomic_write(path, buf.getvalue())


def _member_array(
    zf: zipfile.ZipFile, infos: dict[str, zipfile.ZipInfo], name: str, path: Path
) -> np.ndarray:
    """One ``.npy`` member: its header checked against the format before its data is used."""
    raw = read_member(zf, infos[f"{name}.npy"], _limits()[name])
    dtype, ndim = _MEMBERS[name]
    fh = io.BytesIO(raw)
    try:
        version = np.lib.format.read_magic(fh)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f".npy version {version}")
        read_header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, fortran, got = read_header(fh, max_header_size=1024)
    except (ValueError, OSError, EOFError, SyntaxError, TypeError) as exc:
        raise RealTrafficFileError(f"{path}: member {name!r} is not a plain array: {exc}") from exc
    if got != np.dtype(dtype) or len(shape) != ndim:
        raise RealTrafficFileError(
            f"{path}: member {name!r} has dtype {got} and {len(shape)} dimensions, "
            f"expected {np.dtype(dtype)} and {ndim}"
        )
    data = raw[fh.tell() :]
    count = int(np.prod(shape, dtype=object)) if shape else 1
    if any(d < 0 for d in shape) or count * got.itemsize != len(data):
        raise RealTrafficFileError(
            f"{path}: member {name!r} has shape {tuple(shape)} but {len(data):,} data bytes"
        )
    return np.frombuffer(data, dtype=got).reshape(shape, order="F" if fortran else "C")


def _meta(raw: bytes, path: Path) -> Any:
    """The JSON metadata, its nesting, size and keys checked before it is parsed."""
    try:
        return loads_bounded(raw, max_depth=MAX_META_DEPTH, max_containers=MAX_META_CONTAINERS)
    except ValueError as exc:  # not UTF-8 or JSON, too deep or wide, a repeated key
        raise RealTrafficFileError(f"{path}: metadata {exc}") from None


def _limits() -> dict[str, int]:
    """The most bytes each member may inflate to (read at call time: tests lower them)."""
    small = {"format_version": 1024, "meta": MAX_META_BYTES}
    return {name: small.get(name, MAX_MEMBER_BYTES) for name in _MEMBERS}


def read_npz(path: str | os.PathLike[str]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read and check a real-traffic file; no pickle, bounded memory.

    Args:
        path: The ``.npz`` file.

    Returns:
        ``(arrays, meta)``: the numeric members and the parsed JSON metadata.

    Raises:
        FileNotFoundError: No such file (the path is named).
        RealTrafficFileError: Not a zip, a missing or malformed member, a size over the
            limits, inconsistent arrays, or another format version (named with the path).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"real-traffic file not found: {path}")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise RealTrafficFileError(f"{path}: {size} bytes, over the {MAX_FILE_BYTES} limit")
    try:
        return _read(path)
    except RealTrafficFileError:
        raise
    except HOSTILE_FILE_ERRORS as exc:
        raise _one_line(path, exc) from exc


def _read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise RealTrafficFileError(f"{path}: not a real-traffic .npz file ({exc})") from exc
    with zf:
        try:
            # The version first, alone: a file of another version may hold other members,
            # and should be named as such, not as a corrupt one.
            info = zf.NameToInfo.get("format_version.npy")
            if info is not None:
                check_member(info, _limits()["format_version"], MAX_RATIO)
                version = _member_array(zf, {info.filename: info}, "format_version", path)
                if int(version) != FORMAT_VERSION:
                    raise RealTrafficFileError(
                        f"{path}: format_version {int(version)}, this reader needs {FORMAT_VERSION}"
                    )
            expected = {f"{name}.npy": limit for name, limit in _limits().items()}
            infos = check_members(zf, expected, MAX_RATIO)
            total = sum(i.file_size for i in infos.values())
            if total > MAX_TOTAL_BYTES:
                raise ValueError(f"members of {total:,} bytes declared, limit {MAX_TOTAL_BYTES:,}")
        except RealTrafficFileError:
            raise
        except ValueError as exc:
            raise RealTrafficFileError(f"{path}: {exc}") from None
        except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError) as exc:
            raise RealTrafficFileError(f"{path}: corrupt zip member ({exc})") from exc
        try:
            arrays = {
                name: _member_array(zf, infos, name, path)
                for name in ("time_ms", "pos_cm", "vel_cms", "track_start")
            }
            raw_meta = _member_array(zf, infos, "meta", path)
        except RealTrafficFileError:
            raise
        except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, ValueError) as exc:
            raise RealTrafficFileError(f"{path}: corrupt zip member ({exc})") from exc
    meta = _meta(raw_meta.tobytes(), path)
    _check_consistent(arrays, meta, path)
    return arrays, meta


def _check_consistent(arrays: dict[str, np.ndarray], meta: Any, path: Path) -> None:
    n = len(arrays["time_ms"])
    start = arrays["track_start"]
    if arrays["pos_cm"].shape != (n, 3) or arrays["vel_cms"].shape != (n, 3):
        raise RealTrafficFileError(
            f"{path}: pos_cm {arrays['pos_cm'].shape} and vel_cms {arrays['vel_cms'].shape} "
            f"must be ({n}, 3)"
        )
    if len(start) < 1 or start[0] != 0 or start[-1] != n or np.any(np.diff(start) < 2):
        raise RealTrafficFileError(
            f"{path}: track_start must rise from 0 to {n} by at least 2 samples per track"
        )
    if not isinstance(meta, dict) or not isinstance(meta.get("tracks"), list):
        raise RealTrafficFileError(f"{path}: metadata has no 'tracks' list")
    if len(meta["tracks"]) != len(start) - 1:
        raise RealTrafficFileError(
            f"{path}: {len(meta['tracks'])} track records for {len(start) - 1} tracks"
        )
    t = arrays["time_ms"]
    firsts = start[:-1]
    rising = np.diff(t) > 0
    rising[start[1:-1] - 1] = True  # a new track may start anywhere
    if np.any(t[firsts] != 0) or not np.all(rising):
        raise RealTrafficFileError(f"{path}: time_ms must start at 0 and rise within each track")
