"""Mutated real-traffic files (issue 31 B3): whatever the bytes, the reader raises its own
one-line RealTrafficFileError (or reads a valid file), and a crafted file cannot make it
hold much more memory than the shipped one.

The mutants are generated here from a fixed seed, with a fixed budget: bit flips, cuts,
edited zip length fields, and edits inside the members (npy headers, array bytes, the JSON
metadata), re-zipped so that they get past the CRC checks.
"""

from __future__ import annotations

import io
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S

from uasep_env import real_traffic as rt

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = rt.DEFAULT_PATH.read_bytes()
BUDGET = 400


def _members(raw: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(raw)) as z:
        return {name: z.read(name) for name in z.namelist()}


def _zip(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _flip(rng, raw: bytes) -> bytes:
    b = bytearray(raw)
    for _ in range(int(rng.integers(1, 9))):
        b[int(rng.integers(0, len(b)))] ^= 1 << int(rng.integers(0, 8))
    return bytes(b)


def _cut(rng, raw: bytes) -> bytes:
    return raw[: int(rng.integers(0, len(raw)))]


_FIELDS = {  # zip record signature -> offsets of its (size, count, length) fields
    b"PK\x03\x04": [(18, "<I"), (22, "<I"), (26, "<H"), (28, "<H")],
    b"PK\x01\x02": [(20, "<I"), (24, "<I"), (28, "<H"), (30, "<H"), (42, "<I")],
    b"PK\x05\x06": [(8, "<H"), (10, "<H"), (12, "<I"), (16, "<I")],
}
_EXTREMES = {"<I": [0, 1, 2**31 - 1, 2**32 - 1, 2**31], "<H": [0, 1, 2**15, 2**16 - 1]}


def _length_field(rng, raw: bytes) -> bytes:
    b = bytearray(raw)
    sig = list(_FIELDS)[int(rng.integers(0, len(_FIELDS)))]
    spots = [i for i in range(len(b)) if b.startswith(sig, i)]
    at = spots[int(rng.integers(0, len(spots)))]
    off, fmt = _FIELDS[sig][int(rng.integers(0, len(_FIELDS[sig])))]
    old = struct.unpack_from(fmt, b, at + off)[0]
    top = 2 ** (8 * struct.calcsize(fmt))
    choices = [*_EXTREMES[fmt], old + 1, max(old - 1, 0), old * 2 % top]
    struct.pack_into(fmt, b, at + off, int(choices[int(rng.integers(0, len(choices)))]))
    return bytes(b)


_SHAPES = [b"(0,)", b"(1,)", b"(-1,)", b"(99999999999,)", b"(4611686018427387904,)",
           b"(3, 0)", b"()", b"(2, 3, 4)", b"(18446744073709551615, 3)"]  # fmt: skip
_DESCRS = [b"'<i8'", b"'>i8'", b"'<f8'", b"'|O'", b"'<U9'", b"'V8'", b"'<i4'", b"[('a','<i8')]"]


def _header(rng, data: bytes) -> bytes:
    end = data.index(b"\n") if b"\n" in data else len(data)
    head, body = data[:end], data[end:]
    if rng.random() < 0.5 and b"'shape': " in head:
        i = head.index(b"'shape': ") + 9
        j = head.index(b")", i) + 1
        head = head[:i] + _SHAPES[int(rng.integers(0, len(_SHAPES)))] + head[j:]
    else:
        i = head.index(b"'descr': ") + 9
        j = head.index(b",", i)
        head = head[:i] + _DESCRS[int(rng.integers(0, len(_DESCRS)))] + head[j:]
    return head + body


def _json(rng, data: bytes) -> bytes:
    start = data.index(b"\n") + 1  # the npy header, then the UTF-8 JSON
    text = bytearray(data[start:])
    for _ in range(int(rng.integers(1, 6))):
        at = int(rng.integers(0, len(text) + 1))
        piece = [b"[" * 2000, b"{", b'"', b"\\", b"1e999", b"-", b"\xff", b"]}", b'"tracks":1,',
                 b"null", b'"origin":[1e308,1e308]', b'"first_timestamp_ms":1e400']  # fmt: skip
        text[at:at] = piece[int(rng.integers(0, len(piece)))]
    arr = np.frombuffer(bytes(text), np.uint8)
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr, version=(1, 0), allow_pickle=False)
    return buf.getvalue()


def _values(rng, data: bytes) -> bytes:
    b = bytearray(data)
    start = b.index(b"\n") + 1
    for _ in range(int(rng.integers(1, 5))):
        at = int(rng.integers(start, len(b))) if len(b) > start else start
        width = min(8, len(b) - at)
        b[at : at + width] = rng.bytes(width)
    return bytes(b)


def _member_edit(rng, raw: bytes) -> bytes:
    members = _members(raw)
    names = sorted(members)
    name = names[int(rng.integers(0, len(names)))]
    kind = rng.random()
    if name == "meta.npy" and kind < 0.5:
        members[name] = _json(rng, members[name])
    elif kind < 0.75:
        members[name] = _header(rng, members[name])
    else:
        members[name] = _values(rng, members[name])
    return _zip(members)


MUTATIONS = (_flip, _cut, _length_field, _member_edit)


def _mutants(seed: int, n: int):
    rng = np.random.default_rng(seed)
    for k in range(n):
        mutate = MUTATIONS[k % len(MUTATIONS)]
        yield f"{mutate.__name__}#{k}", mutate(rng, SHIPPED)


def test_only_the_readers_own_error_escapes_from_mutated_files(tmp_path):
    path = tmp_path / "mutant.npz"
    escaped = []
    refused = 0
    for name, raw in _mutants(31, BUDGET):
        path.write_bytes(raw)
        try:
            rt.RealTrafficDataset(path)
        except rt.RealTrafficFileError as err:
            refused += 1
            text = str(err)
            assert text and "\n" not in text and str(path) in text, (name, text)
        except BaseException as err:  # what must not happen is the point
            escaped.append(f"{name}: {type(err).__name__}: {str(err)[:120]}")
    assert not escaped, f"{len(escaped)} of {BUDGET} mutants escaped:\n" + "\n".join(escaped)
    assert refused > BUDGET // 2  # the mutations mostly break the file


_PEAK = """
import resource, sys
from uasep_env import real_traffic as rt
try:
    rt.RealTrafficDataset(sys.argv[1])
    print("accepted", end=" ")
except rt.RealTrafficFileError as err:
    print("refused", end=" ")
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def crafted_file(path: Path) -> Path:
    """A small file that inflates to the most the reader will hold: a metadata JSON of
    empty lists (64 bytes of Python objects per 3 bytes) with random whitespace (keeping
    the compression ratio under the limit), and arrays whose headers claim huge shapes."""
    rng = np.random.default_rng(0)
    members = _members(SHIPPED)
    ws = np.frombuffer(b" \n\t\r", np.uint8)
    n = 4_000_000 - 8
    filler = np.empty((n, 4), np.uint8)
    filler[:, 0], filler[:, 1], filler[:, 2] = ord("["), ord("]"), ord(",")
    filler[:, 3] = ws[rng.integers(0, 4, n)]
    text = b'{"tracks":[' + filler.tobytes() + b"[]]}"
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.frombuffer(text, np.uint8), allow_pickle=False)
    members["meta.npy"] = buf.getvalue()
    path.write_bytes(_zip(members))
    return path


def _peak(path: Path) -> tuple[str, int]:
    out = subprocess.run(
        [sys.executable, "-c", _PEAK, str(path)],
        capture_output=True, text=True, timeout=HANG_GUARD_S, cwd=ROOT, check=True,
    )  # fmt: skip
    verdict, rss = out.stdout.split()
    return verdict, int(rss)


def test_a_crafted_file_is_refused_within_the_memory_of_reading_the_shipped_one(tmp_path):
    crafted = crafted_file(tmp_path / "crafted.npz")
    verdict, peak = _peak(crafted)
    _, shipped = _peak(rt.DEFAULT_PATH)
    size = crafted.stat().st_size
    print(f"crafted file {size:,} B: {verdict}, peak RSS {peak / 1e6:.0f} MB; "
          f"shipped file: {shipped / 1e6:.0f} MB")  # fmt: skip
    assert verdict == "refused"
    assert peak < shipped + 64e6


@pytest.mark.parametrize("mutate", MUTATIONS, ids=lambda m: m.__name__)
def test_every_mutation_kind_yields_files_the_reader_sees(mutate):
    # The generators themselves: each makes bytes that differ from the shipped file.
    rng = np.random.default_rng(1)
    assert any(mutate(rng, SHIPPED) != SHIPPED for _ in range(5))


def test_metadata_is_refused_by_its_shape_before_it_is_parsed(tmp_path, monkeypatch):
    import json
    import types

    from uasep_env.real_traffic import fileformat
    from uasep_env.runtime import jsonio
    from uasep_env.runtime.jsonio import json_shape

    def parsed(*args, **kwargs):
        raise AssertionError("the JSON was parsed")

    monkeypatch.setattr(jsonio, "json", types.SimpleNamespace(loads=parsed))
    rng = np.random.default_rng(2)
    lists = b"".join(b"[]," + b" \n\t\r"[k : k + 1] for k in rng.integers(0, 4, 60_000))
    for text, match in (
        (b'{"tracks": [' + lists + b"[]]}", "holds 60,003 arrays and objects"),
        (b'{"tracks": ' + b"[" * 9 + b"]" * 9 + b"}", "nests 10 levels"),
    ):
        members = _members(SHIPPED)
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.frombuffer(text, np.uint8), allow_pickle=False)
        members["meta.npy"] = buf.getvalue()
        path = tmp_path / "meta.npz"
        path.write_bytes(_zip(members))
        with pytest.raises(rt.RealTrafficFileError, match=match):
            rt.RealTrafficDataset(path)
    monkeypatch.undo()
    depth, containers = json_shape(rt.load().meta and json.dumps(rt.load().meta))
    assert depth <= fileformat.MAX_META_DEPTH // 2
    assert containers <= fileformat.MAX_META_CONTAINERS // 50
