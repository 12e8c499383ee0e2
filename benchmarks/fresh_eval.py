"""What a new user waits for: ``make eval`` on a fresh clone, timed command by command.

Usage::

    python benchmarks/fresh_eval.py [--repo .] [--keep]

Clones the repository's committed ``HEAD`` into a temporary folder (so no venv, build or
numba cache of this checkout is reused) and runs ``make eval`` there: the venv, the
installs (from pip's cache when it is warm, as on a machine that installed anything
before), the kernels' compilation (``python -m uasep_env.precompile``) and the APF on the
paper's scenario. Each command ``make`` echoes starts a phase; the script prints each
phase's wall seconds and the total, against issue 30's goal of 90 s. ``--keep`` keeps the
clone (its path is printed). Needs ``git``, ``make`` and ``python3`` on the path.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOAL_S = 90.0


def main() -> None:
    """Clone, run ``make eval`` with each echoed command timed, print the phases."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repo", default=str(ROOT), help="the repository to clone (its HEAD)")
    p.add_argument("--keep", action="store_true", help="keep the clone")
    args = p.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="uasep-fresh-"))
    clone = tmp / "repo"
    try:
        subprocess.run(["git", "clone", "-q", args.repo, str(clone)], check=True)
        phases: list[tuple[str, float]] = []
        start = time.perf_counter()
        last, label = start, "make"
        proc = subprocess.Popen(
            ["make", "eval"], cwd=clone, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True,
        )  # fmt: skip
        assert proc.stdout is not None
        tail: list[str] = []
        for line in proc.stdout:
            # make echoes each command before it runs it: a new phase starts.
            if line.startswith((".venv/", "python3 ", "touch ")):
                now = time.perf_counter()
                phases.append((label, now - last))
                last, label = now, line.strip()
            elif not line.startswith("WARNING: Location"):
                tail = [*tail, line.rstrip()][-3:]
        rc = proc.wait()
        end = time.perf_counter()
        phases.append((label, end - last))
        if rc != 0:
            print("\n".join(tail), file=sys.stderr)
            sys.exit(f"make eval failed with exit status {rc}")
        for name, seconds in phases:
            if seconds >= 0.05:
                print(f"{seconds:7.1f} s  {name[:100]}")
        total = end - start
        verdict = "met" if total <= GOAL_S else "not met"
        print(f"{total:7.1f} s  in all (goal <= {GOAL_S:.0f} s: {verdict})")
        if args.keep:
            print(f"clone kept: {clone}")
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
