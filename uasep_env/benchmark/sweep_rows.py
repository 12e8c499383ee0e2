"""The trade-off sweep's CSV: rewritten atomically, read tolerantly, never mixing episode counts.

The sweep (``uasep-tradeoff``, :mod:`.tradeoff`) rewrites its CSV after every evaluation call.
The write is atomic (:func:`uasep_env.runtime.atomic.atomic_write`), so a kill or a full disk
leaves the previous file and no finished row is lost; the reader drops a torn last row (a file
cut short some other way); rows of other episode counts are refused, not mixed into the tables.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from uasep_env.runtime.atomic import atomic_write

__all__ = ["check_counts", "read_rows", "write_rows"]

_TEXT_COLUMNS = ("method", "knob", "dataset")


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The CSV's rows; a torn last row (a file cut short, e.g. by a kill) is dropped.

    Raises:
        SystemExit: A damaged row that is not the last (one line naming the file and line).
    """
    if not path.exists():
        return []
    with path.open(newline="") as f:
        raw = list(csv.DictReader(f))
    rows = []
    for k, r in enumerate(raw):
        try:
            if None in r or None in r.values():
                raise ValueError("too few or too many cells")
            rows.append({c: (v if c in _TEXT_COLUMNS else float(v)) for c, v in r.items()})
        except ValueError as err:
            if k == len(raw) - 1:
                print(f"{path}: dropping its torn last row ({err}); that setting runs again")
                break
            raise SystemExit(
                f"{path}: line {k + 2} is damaged ({err}); fix it or pass --fresh"
            ) from None
    return rows


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Rewrite the whole CSV atomically: a kill or a full disk leaves the previous file."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    atomic_write(path, buf.getvalue())


def check_counts(path: Path, rows: list[dict[str, Any]], sets: dict[str, tuple]) -> None:
    """Refuse to add rows of other episode counts to a CSV (the tables would mix them)."""
    for ds, (_scenario, seeds) in sets.items():
        other = sorted({int(r["n"]) for r in rows if r["dataset"] == ds} - {len(seeds)})
        if other:
            raise SystemExit(
                f"{path} holds {ds} rows of {other[0]} episodes, this run asks for "
                f"{len(seeds)}: pass --fresh to start over, or another --out"
            )
