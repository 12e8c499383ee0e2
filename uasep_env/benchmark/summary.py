"""The leaderboard from the cells: each row's numbers, its front and its deviation at equal safety.

Per bank, the loss-of-separation budget is ``--budget`` or, by default, the APF's rate at its
default setting on that bank; each row's *deviation at equal safety* is the least max
deviation along its front at which its loss-of-separation rate is within the budget with no
collision (:func:`~uasep_env.benchmark.front.deviation_at_budget`: interpolated along the
front, as the trade-off report's costs at equal distance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from uasep_env.benchmark.banks import BANKS, bank_config
from uasep_env.benchmark.entries import Entry
from uasep_env.benchmark.front import deviation_at_budget
from uasep_env.benchmark.runner import REFERENCE

__all__ = ["FORMAT", "leaderboard"]

#: The layout's version (bump it when a key changes meaning).
FORMAT = 1


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


def _point(value: float | None, stats: dict[str, Any]) -> dict[str, Any]:
    """A front's point as :func:`deviation_at_budget` reads it."""
    return {
        "value": value,
        "collision": _num(stats["collision"]["rate"]),
        "loss_of_separation": _num(stats["loss_of_separation"]["rate"]),
        "max_deviation": _num(stats["max_deviation"]["mean"]),
    }


def _front_kind(entry: Entry, front: bool) -> str:
    if entry.earlier_version:
        return f"single point: played in -v{entry.env_version}"
    if entry.sweep is None:
        return "single point: no knob to sweep"
    return "swept" if front else "single point: front not swept on this bank"


def leaderboard(
    entries: Sequence[Entry],
    banks: Sequence[str],
    cells: dict[tuple[str, str, str], dict[str, Any]],
    *,
    budget: float | None,
    front: bool | Sequence[str],
    episodes: int | None,
    overrides: dict[str, Any],
    command: Sequence[str],
) -> dict[str, Any]:
    """The leaderboard's JSON layout (plain data; its keys are written sorted).

    Returns:
        ``{"format", "command", "versions", "settings", "banks": {bank: {title, seeds,
        seed_range, config, budget}}, "policies": {label: {spec, kind, knob, values,
        default, front, env_version}}, "results": {bank: {label: {"env_version" (the env
        version the row played: a checkpoint's own), "default": stats, "front": [{"value",
        **stats}], "equal_safety": {deviation, setting, budget[, reason]}}}}}``.
    """
    from uasep_env import __version__
    from uasep_env.registration import ENV_VERSION

    fronts = list(banks) if front is True else [] if front is False else list(front)

    out_banks: dict[str, Any] = {}
    results: dict[str, Any] = {}
    for bank in banks:
        b = BANKS[bank]
        n = min(episodes or len(b.seeds), len(b.seeds))
        if budget is not None:
            limit, source = float(budget), "--budget"
        else:
            ref = cells[bank, REFERENCE, "default"]["loss_of_separation"]["rate"]
            limit, source = _num(ref), f"{REFERENCE} at its default setting"
        out_banks[bank] = {
            "title": b.title,
            "seed_range": b.seed_range,
            "seeds": {"first": b.seeds.start, "count": n},
            "config": bank_config(bank, overrides).to_dict(),
            "budget": {"loss_of_separation": limit, "source": source},
        }
        rows: dict[str, Any] = {}
        for e in entries:
            default = cells[bank, e.label, "default"]
            sweep = e.sweep
            points = [(sweep.default if sweep else None, default)]
            if bank in fronts and sweep is not None and not e.earlier_version:
                points = [
                    (float(v), default if v == sweep.default else cells[bank, e.label, f"{v:g}"])
                    for v in sorted({*sweep.values, sweep.default})
                ]
            if e.earlier_version:
                eq = {
                    "deviation": None,
                    "setting": None,
                    "reason": f"played in -v{e.env_version}, the budget is -v{ENV_VERSION}'s",
                }
            elif math.isfinite(limit):
                eq = deviation_at_budget([_point(v, s) for v, s in points], limit)
            else:
                eq = {"deviation": None, "setting": None, "reason": "no budget (reference NaN)"}
            rows[e.label] = {
                "env_version": e.env_version,
                "front_kind": _front_kind(e, bank in fronts),
                "default": default,
                "front": [{"value": v, **s} for v, s in points],
                "equal_safety": {**eq, "budget": limit},
            }
        results[bank] = rows
    return {
        "format": FORMAT,
        "command": list(command),
        "versions": {"uasep_env": __version__, "env": ENV_VERSION},
        "settings": {
            "banks": list(banks),
            "episodes": episodes,
            "config": overrides,
            "budget": budget,
            "front": bool(fronts),
            "front_banks": fronts,
        },
        "banks": out_banks,
        "policies": {
            e.label: {
                "spec": e.spec,
                "kind": e.kind,
                "knob": e.sweep.knob if e.sweep else None,
                "values": list(e.sweep.values) if e.sweep and fronts else None,
                "default": e.sweep.default if e.sweep else None,
                "front": _front_kind(e, bool(fronts)),
                "env_version": e.env_version,
            }
            for e in entries
        },
        "results": results,
    }
