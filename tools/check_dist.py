"""Check a built wheel and sdist (``make test-package``): what a pip user downloads.

Usage: ``python tools/check_dist.py DIST_DIR`` (the folder ``python -m build`` wrote).

* the wheel carries the shipped policies as ``uasep_env/checkpoints/*.zip``, byte for byte
  the repository's ``baselines/checkpoints/*.zip``, and the LICENSE;
* the sdist carries what its test suite needs (``tests/conftest.py``, ``baselines/``,
  ``train/``, ``tools/``) and the LICENSE;
* the metadata: SPDX licence, version, no relative link left in the description.

Exits 1 naming every problem.
"""

from __future__ import annotations

import re
import sys
import tarfile
import zipfile
from email.parser import Parser
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SDIST_NEEDS = (
    "LICENSE",
    "CITATION.cff",
    "setup.py",
    "pyproject.toml",
    "tests/conftest.py",
    "baselines/checkpoints/ppo_shared.zip",
    "baselines/results/summary.md",
    "tools/sync_readme.py",
    "train/README.md",
)


def check(dist: Path) -> list[str]:
    """Every problem found in the wheel and sdist in ``dist`` (empty when all is well)."""
    problems: list[str] = []
    wheels, sdists = sorted(dist.glob("*.whl")), sorted(dist.glob("*.tar.gz"))
    if len(wheels) != 1 or len(sdists) != 1:
        return [f"expected one wheel and one sdist in {dist}, found {wheels + sdists}"]
    source = {p.name: p.read_bytes() for p in (ROOT / "baselines" / "checkpoints").glob("*.zip")}
    with zipfile.ZipFile(wheels[0]) as whl:
        names = whl.namelist()
        shipped = {
            Path(n).name: whl.read(n)
            for n in names
            if n.startswith("uasep_env/checkpoints/") and n.endswith(".zip")
        }
        meta_name = next(n for n in names if n.endswith(".dist-info/METADATA"))
        meta = Parser().parsestr(whl.read(meta_name).decode())
        if not any(n.endswith(".dist-info/licenses/LICENSE") for n in names):
            problems.append("wheel: no LICENSE")
    if set(shipped) != set(source) or not source:
        problems.append(f"wheel: checkpoints {sorted(shipped)} != repo's {sorted(source)}")
    problems += [
        f"wheel: {n} differs from the repo's" for n in source if shipped.get(n) != source[n]
    ]
    if meta["License-Expression"] != "MIT":
        problems.append(f"metadata: License-Expression {meta['License-Expression']!r}")
    body = meta.get_payload()
    relative = [
        t for t in re.findall(r"\]\(([^)\s]+)\)", body) if not t.startswith(("https://", "#"))
    ]
    if relative:
        problems.append(f"metadata: relative links in the description: {relative[:5]}")
    with tarfile.open(sdists[0]) as tar:
        members = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    problems += [f"sdist: {n} missing" for n in SDIST_NEEDS if n not in members]
    return problems


def main() -> int:
    """Check the folder given on the command line; print the problems."""
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    problems = check(Path(sys.argv[1]))
    for p in problems:
        print(f"check_dist: {p}", file=sys.stderr)
    if not problems:
        print(f"check_dist: wheel and sdist in {sys.argv[1]} OK")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
