"""Playing the suite: one cell per (bank, policy, setting), each written when it finishes.

A cell is one setting of one policy on one bank: its default (played by name, exactly as
``uasep-eval`` plays it) or one value of its knob. Cells are written atomically to
``OUT/cells/<bank>/<policy>@<setting>.json`` as their evaluation finishes, each with the
key that identifies it (the policy, the setting, the bank's full config, the seeds, the
package version); a run into the same folder skips every cell whose file holds the same
key, so an interrupted suite resumes where it stopped and gives the same numbers (each
seed's episode is fixed, :mod:`uasep_env.evaluation.runner`). A cell file with another key
(another ``--config``, ``--episodes`` or version) is refused, not mixed in.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uasep_env.benchmark.banks import BANKS, bank_config
from uasep_env.benchmark.entries import Entry, build_point, point_config
from uasep_env.config import EnvConfig

__all__ = [
    "MEANS",
    "RATES",
    "REFERENCE",
    "BenchError",
    "Cell",
    "cell_stats",
    "plan_cells",
    "run_cells",
]

#: Rates of the table (Wilson intervals): column -> aggregate key.
RATES = {"collision": "episode.collision", "loss_of_separation": "episode.loss_of_separation"}
#: Means of the table (Student-t intervals): column -> aggregate key.
MEANS = {
    "max_deviation": "episode.max_deviation",
    "conflict_time": "episode.max_conflict_duration",
    "cost": "episode.cost",
}
_RATE_FIELDS = ("rate", "ci_low", "ci_high", "successes", "n")
_MEAN_FIELDS = ("mean", "ci_low", "ci_high", "n_valid")
#: The policy whose default setting's loss-of-separation rate is each bank's default budget.
REFERENCE = "apf"


class BenchError(ValueError):
    """A bad input found while the suite runs (a policy that fails or returns NaN actions)."""


@dataclass(frozen=True, kw_only=True)
class Cell:
    """One setting of one policy on one bank (``value`` None: the policy's default)."""

    bank: str
    entry: Entry
    value: float | None

    @property
    def setting(self) -> str:
        """The setting's name in files: ``default`` or the knob's value."""
        return "default" if self.value is None else f"{self.value:g}"

    def path(self, out: Path) -> Path:
        """Where the cell's file lives under ``out``."""
        safe = re.sub(r"[^A-Za-z0-9._+=-]", "_", self.entry.label)
        digest = hashlib.sha1(self.entry.label.encode()).hexdigest()[:8]
        return out / "cells" / self.bank / f"{safe}-{digest}@{self.setting}.json"


def _config_digest(cfg: EnvConfig) -> str:
    text = json.dumps(cfg.to_dict(), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _checkpoint_digest(entry: Entry) -> str | None:
    """The sha256 (16 hex) of the checkpoint file behind ``entry``, or None if it has none."""
    from uasep_env.policies import shipped_policy_path

    if entry.kind != "name":
        return None
    base = Path(entry.base)
    path = base if base.is_file() else shipped_policy_path(entry.base)
    return None if path is None else hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def cell_key(cell: Cell, cfg: EnvConfig, seeds: Sequence[int]) -> dict[str, Any]:
    """What identifies a cell's numbers: a file with another key is another suite's.

    A policy checkpoint's key holds the file's digest: a checkpoint retrained under the same
    name or path is another policy, never read from the old one's cells.
    """
    from uasep_env import __version__

    key = {
        "bank": cell.bank,
        "policy": cell.entry.spec,
        "setting": cell.setting,
        "config_sha256": _config_digest(cfg),
        "seeds": [int(seeds[0]), len(seeds)],
        "version": __version__,
    }
    digest = _checkpoint_digest(cell.entry)
    if digest is not None:
        key["checkpoint_sha256"] = digest
    return key


def cell_stats(aggregate: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The table's statistics of one evaluated policy (its aggregate's rates and means)."""
    out: dict[str, Any] = {}
    for col, key in RATES.items():
        out[col] = {f: aggregate[key][f] for f in _RATE_FIELDS}
    for col, key in MEANS.items():
        out[col] = {f: aggregate[key][f] for f in _MEAN_FIELDS}
    return out


def plan_cells(
    entries: Sequence[Entry],
    banks: Sequence[str],
    front: bool | Collection[str],
    reference: Entry | None,
) -> list[Cell]:
    """Every cell of the suite, bank by bank.

    Each entry's default, the budget's reference default where it is no entry, then (on the
    banks of ``front``: all with True, none with False) each sweep's other values.
    """
    fronts = set(banks) if front is True else set() if front is False else set(front)
    cells: list[Cell] = []
    for bank in banks:
        for e in entries:
            cells.append(Cell(bank=bank, entry=e, value=None))
        if reference is not None:
            cells.append(Cell(bank=bank, entry=reference, value=None))
        for e in entries if bank in fronts else ():
            # A row played in an earlier env version has no front: the bank's budget is
            # the current version's APF's, so its equal-safety figure would compare nothing.
            if e.sweep is not None and not e.earlier_version:
                cells += [
                    Cell(bank=bank, entry=e, value=float(v))
                    for v in e.sweep.values
                    if v != e.sweep.default
                ]
    return cells


def read_cell(path: Path, key: dict[str, Any]) -> dict[str, Any] | None:
    """A finished cell's statistics, or None if it has no file yet.

    Raises:
        BenchError: If the file holds another suite's cell (another key).
    """
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except ValueError:
        return None  # cut short some other way: played again
    if data.get("key") != key:
        raise BenchError(
            f"{path} holds a cell of another suite run (key {data.get('key')} != {key}): "
            "use another --out, or --fresh to start over"
        )
    return data["stats"]


def run_cells(
    cells: Sequence[Cell],
    out: Path,
    *,
    episodes: int | None,
    overrides: dict[str, Any],
    workers: int = 1,
    ray: str | None = None,
    log: Callable[[str], None] = lambda _m: None,
) -> dict[tuple[str, str, str], dict[str, Any]]:
    """Play every cell that has no file yet, writing each; return every cell's statistics.

    Cells of one policy on one bank that share a config are played in one evaluation (the
    same chunks; each policy's numbers do not depend on the others'), and written as it
    ends. The returned statistics are read back from the files, so a resumed suite and a
    run in one go give the same.

    Returns:
        ``(bank, label, setting) -> statistics``.

    Raises:
        BenchError: For a policy that fails on a bank (its actions not finite, ...), named.
    """
    from uasep_env.evaluation import evaluate
    from uasep_env.runtime.jsonio import dumps

    # Each row plays its env version of the bank: a checkpoint's own, else the current one.
    bank_cfgs = {
        (c.bank, c.entry.env_version): bank_config(c.bank, overrides, c.entry.env_version)
        for c in cells
    }
    seeds = {
        b: list(BANKS[b].seeds)[: episodes or len(BANKS[b].seeds)]
        for b in dict.fromkeys(c.bank for c in cells)
    }
    done: dict[tuple[str, str, str], dict[str, Any]] = {}
    groups: dict[tuple[str, str, str], list[tuple[Cell, EnvConfig, dict[str, Any]]]] = {}
    for cell in cells:
        cfg = bank_cfgs[cell.bank, cell.entry.env_version]
        played = (
            cfg
            if cell.value is None and cell.entry.kind == "name"
            else point_config(cell.entry, cfg, cell.value)
        )  # a name's default: the bank's config, as uasep-eval gives it
        key = cell_key(cell, played, seeds[cell.bank])
        stats = read_cell(cell.path(out), key)
        if stats is not None:
            done[cell.bank, cell.entry.label, cell.setting] = stats
            continue
        group = (cell.bank, cell.entry.label, _config_digest(played))
        groups.setdefault(group, []).append((cell, played, key))
    for (bank, label, _), members in groups.items():
        cfg = members[0][1]
        entry = members[0][0].entry
        try:
            points = {c.setting: build_point(entry, cfg, c.value) for c, _, _ in members}
            result = evaluate(points, cfg, seeds[bank], workers=workers, ray=ray)
        except (KeyboardInterrupt, SystemExit, MemoryError):
            raise
        except Exception as err:
            text = " ".join(str(err).split()) or type(err).__name__
            raise BenchError(f"policy {entry.spec!r} failed on bank {bank!r}: {text}") from err
        for cell, _, key in members:
            stats = cell_stats(result.results[cell.setting].aggregate)
            path = cell.path(out)
            path.parent.mkdir(parents=True, exist_ok=True)
            from uasep_env.runtime.atomic import atomic_write

            atomic_write(path, dumps({"key": key, "stats": stats}, indent=1) + "\n")
            done[bank, label, cell.setting] = read_cell(path, key)  # type: ignore[assignment]
        log(
            f"{bank}: {label} ({', '.join(c.setting for c, _, _ in members)}) "
            f"on {len(seeds[bank])} episodes"
        )
    return done
