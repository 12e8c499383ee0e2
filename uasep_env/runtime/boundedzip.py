"""Zip archives from elsewhere, read within hard limits (checkpoints, the real-traffic file).

A zip's directory says what its members inflate to, and it may lie. :func:`check_members`
checks the directory before a byte is decompressed (exactly the expected members, no
duplicates, stored or deflated only, not encrypted, declared sizes and compression ratios
bounded); :func:`read_member` then never inflates more than a member's limit, whatever the
directory declared. Failures are ``ValueError`` messages without the path; each format's
reader adds its path and raises its own error class.
"""

from __future__ import annotations

import struct
import zipfile
import zlib
from collections import Counter
from collections.abc import Mapping

__all__ = [
    "HOSTILE_FILE_ERRORS",
    "RATIO_FREE_BYTES",
    "check_member",
    "check_members",
    "read_member",
]

#: What a hostile file can make the standard library and numpy raise on the way through a
#: reader (the checkpoint and real-traffic readers turn each into their own one-line error).
HOSTILE_FILE_ERRORS = (
    zipfile.BadZipFile,
    zipfile.LargeZipFile,
    zlib.error,
    struct.error,
    EOFError,
    MemoryError,
    RecursionError,
    OverflowError,
    NotImplementedError,
    RuntimeError,
    ValueError,
    TypeError,  # numpy's UFuncTypeError is one
    KeyError,
    IndexError,
    AttributeError,
    UnicodeDecodeError,
    OSError,
)

#: Members up to this size may compress well (JSON deflates about 5:1): no ratio check.
RATIO_FREE_BYTES = 64 * 1024


def check_members(
    z: zipfile.ZipFile, expected: Mapping[str, int], max_ratio: float
) -> dict[str, zipfile.ZipInfo]:
    """Check a zip's directory against a format; nothing is decompressed.

    Args:
        z: The open archive.
        expected: Member name -> the most bytes it may inflate to; exactly these members.
        max_ratio: Largest compression ratio of a member over :data:`RATIO_FREE_BYTES`.

    Returns:
        Member name -> its directory entry.

    Raises:
        ValueError: A duplicate, unexpected or missing member, another compression method,
            an encrypted member, a declared size over its limit or a ratio over
            ``max_ratio`` (the member named).
    """
    infos = z.infolist()
    names = [i.filename for i in infos]
    counts = Counter(names)  # linear: a directory of many tiny entries must not cost minutes
    dupes = sorted(n for n, c in counts.items() if c > 1)
    if dupes:
        raise ValueError(f"duplicate member(s) {', '.join(map(repr, dupes[:3]))}")
    extra = [n for n in names if n not in expected]
    if extra:
        shown = ", ".join(repr(n[:60]) for n in extra[:3])
        raise ValueError(f"unexpected member(s) {shown}; the format holds {sorted(expected)}")
    missing = [n for n in expected if n not in names]
    if missing:
        raise ValueError(f"missing member(s) {', '.join(map(repr, missing))}")
    for info in infos:
        check_member(info, expected[info.filename], max_ratio)
    return {info.filename: info for info in infos}


def check_member(info: zipfile.ZipInfo, limit: int, max_ratio: float) -> None:
    """Check one member's directory entry (see :func:`check_members`); nothing is read.

    Raises:
        ValueError: Another compression method, encryption, a declared size over ``limit``
            or a compression ratio over ``max_ratio`` (for members over 64 KiB).
    """
    if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        raise ValueError(f"{info.filename}: compression method {info.compress_type} refused")
    if info.flag_bits & 0x1:
        raise ValueError(f"{info.filename}: encrypted members are refused")
    if info.file_size > limit:
        raise ValueError(f"{info.filename}: {info.file_size:,} bytes declared, limit {limit:,}")
    ratio = info.file_size / max(info.compress_size, 1)
    if info.file_size > RATIO_FREE_BYTES and ratio > max_ratio:
        raise ValueError(f"{info.filename}: compression ratio {ratio:,.0f}, limit {max_ratio}")


def read_member(z: zipfile.ZipFile, info: zipfile.ZipInfo, limit: int) -> bytes:
    """A member's bytes, never more than ``limit`` (however the directory lies about its size).

    Raises:
        ValueError: The member inflates to more than ``limit`` bytes.
    """
    with z.open(info) as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{info.filename}: more than {limit:,} bytes")
    return data
