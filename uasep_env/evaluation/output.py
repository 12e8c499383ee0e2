"""Writing an evaluation: strict JSON (the one writer, :mod:`uasep_env.runtime.jsonio`) and CSV."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.evaluation.results import EvaluationResult
from uasep_env.metrics import flatten_metrics
from uasep_env.runtime.atomic import atomic_output
from uasep_env.runtime.jsonio import dumps, write_json

__all__ = ["result_to_json", "write_csv", "write_json"]


def result_to_json(result: Any, **kwargs: Any) -> str:
    """Strict JSON of an :func:`evaluate` result (without the episodes kept for plots).

    Args:
        result: An :class:`EvaluationResult` (or anything :func:`uasep_env.runtime.jsonio.to_plain`
            takes, e.g. a dict of results).
        **kwargs: Passed to :func:`json.dumps` (e.g. ``indent``).

    Returns:
        JSON text; non-finite floats are written as ``null``.
    """
    return dumps(result, **kwargs)


def _csv_cell(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ""
    return value


def write_csv(result: EvaluationResult, path: str | Path) -> Path:
    """Write one row per (policy, episode) with the flattened scalar metrics.

    Columns: ``policy, seed, family, steps, terminated, episode_return`` and then every key
    of :func:`uasep_env.metrics.flatten_metrics` (e.g. ``episode.min_obstacle_distance``,
    ``uav.uav_2.timeline.t_leave``), among them the episode cost: ``uav.<name>.cost`` (the
    UAV's per-step costs summed over the episode), ``episode.cost`` (their mean over UAVs,
    the team's) and ``episode.max_uav_cost`` (the worst UAV's). Empty cells are NaN /
    undefined.

    Args:
        result: An :func:`evaluate` result.
        path: Output file (written atomically: an error leaves the old file intact).

    Returns:
        The path written.
    """
    rows: list[dict[str, Any]] = []
    keys: dict[str, None] = {}
    for label in result.policies:
        for e in result.results[label].episodes:
            flat = flatten_metrics(e.metrics)
            keys.update(dict.fromkeys(flat))
            rows.append(
                {
                    "policy": label,
                    "seed": e.seed,
                    "family": e.family,
                    "steps": e.steps,
                    "terminated": e.terminated,
                    "episode_return": e.episode_return,
                    **flat,
                }
            )
    header = ["policy", "seed", "family", "steps", "terminated", "episode_return", *keys]
    path = Path(path)
    with atomic_output(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=header, restval="")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    return path
