"""Rebuild ``uasep_env/data/real_traffic.npz`` from the ``traffic`` 2.13 wheel's sample flights.

The wheel is read as a zip (never installed, never imported); only the sample JSON files
listed in :data:`uasep_env.real_traffic.build.SAMPLES` are used. Without ``--wheel`` the
wheel is fetched with ``pip download --no-deps traffic==2.13`` into a temporary folder.
Rebuilding gives the same file, byte for byte (``tests/test_real_traffic.py``).

    python tools/build_real_traffic.py --wheel /path/traffic-2.13-py3-none-any.whl
    python tools/build_real_traffic.py --check   # exit 1 if the shipped file differs
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from uasep_env.real_traffic.build import SAMPLES, build
from uasep_env.real_traffic.fileformat import write_npz

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "uasep_env" / "data" / "real_traffic.npz"
VERSION = "2.13"
WHEEL = f"traffic-{VERSION}-py3-none-any.whl"


def download_wheel(dest: Path) -> Path:
    """``pip download --no-deps traffic==2.13`` into ``dest``; returns the wheel's path."""
    subprocess.run(
        [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
         f"traffic=={VERSION}", "-d", str(dest)],
        check=True,
    )  # fmt: skip
    return dest / WHEEL


def build_from_wheel(wheel: Path, out: Path) -> None:
    """Read the samples out of ``wheel`` and write the dataset to ``out``."""
    raw = wheel.read_bytes()
    with zipfile.ZipFile(wheel) as zf:
        samples = {s: zf.read(f"traffic/data/samples/{s}.json.gz") for s in sorted(SAMPLES)}
    source = {
        "package": "traffic",
        "version": VERSION,
        "wheel": wheel.name,
        "wheel_sha256": hashlib.sha256(raw).hexdigest(),
        "licence": "traffic is MIT (wheel METADATA: License-Expression: MIT); "
        "see uasep_env/data/REAL_TRAFFIC_LICENSE.md",
    }
    arrays, meta = build(samples, source)
    write_npz(out, arrays, meta)


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wheel", type=Path, help=f"a local {WHEEL} (else pip download)")
    parser.add_argument("--out", type=Path, default=OUT, help="output .npz")
    parser.add_argument("--check", action="store_true", help="compare with --out, write nothing")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        wheel = args.wheel if args.wheel is not None else download_wheel(Path(tmp))
        if not wheel.is_file():
            parser.error(f"--wheel {wheel}: no such file")
        if args.check:
            rebuilt = Path(tmp) / "rebuilt.npz"
            build_from_wheel(wheel, rebuilt)
            same = args.out.is_file() and rebuilt.read_bytes() == args.out.read_bytes()
            print(f"{args.out}: {'up to date' if same else 'DIFFERS from a rebuild'}")
            return 0 if same else 1
        build_from_wheel(wheel, args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
