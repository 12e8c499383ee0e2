"""Aggregation over episodes: flat dotted metric names, then mean / rate with intervals.

Every numeric scalar gets mean, sample standard deviation (ddof=1), min, max, sum, the number
of episodes ``n`` and of finite values ``n_valid``, and a two-sided Student-t confidence
interval for the mean; every boolean is a rate (fraction of episodes where it is True) with a
Wilson score interval. NaNs are ignored.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from uasep_env.metrics.results import EpisodeMetrics
from uasep_env.metrics.statistics import check_probability, t_interval, wilson_interval

__all__ = ["aggregate", "flatten_metrics"]


def flatten_metrics(metrics: EpisodeMetrics | Mapping[str, Any]) -> dict[str, float | bool]:
    """Flatten one episode's metrics into ``{"dotted.key": scalar}``.

    Keys are ``episode.<field>`` and ``uav.<name>.<field>`` (nested fields and per-axis
    values joined with dots, e.g. ``uav.uav_2.deviation.max_abs.z``). Identifier fields
    (``name``, ``index``, ``*_index``, ``hold_time``, ``n_uavs``, ``n_obstacles``) and the
    ``config`` block are left out.

    Args:
        metrics: An :class:`EpisodeMetrics` or its ``to_dict()``.

    Returns:
        Flat dict of float / int / bool values.
    """
    d = metrics.to_dict() if isinstance(metrics, EpisodeMetrics) else metrics
    skip = {"name", "index", "hold_time", "n_uavs", "n_obstacles"}
    out: dict[str, float | bool] = {}

    def walk(prefix: str, node: Any) -> None:
        for key, value in node.items():
            if key in skip or key.endswith("_index"):
                continue
            path = f"{prefix}.{key}"
            if isinstance(value, Mapping):
                walk(path, value)
            elif isinstance(value, (bool, np.bool_)):
                out[path] = bool(value)
            elif isinstance(value, (int, float, np.integer, np.floating)):
                out[path] = float(value)
            elif value is None:
                out[path] = math.nan

    walk("episode", d["episode"])
    for i, u in enumerate(d["uavs"]):
        walk(f"uav.{u.get('name', f'uav_{i}')}", u)
    return out


def aggregate(
    metrics: Sequence[EpisodeMetrics | Mapping[str, Any]], confidence: float = 0.95
) -> dict[str, dict[str, Any]]:
    """Aggregate scalar metrics over episodes.

    Every key of :func:`flatten_metrics` present in at least one episode is aggregated.
    Numeric keys give ``{"kind": "mean", "n", "n_valid", "mean", "std", "min", "max", "sum",
    "ci_low", "ci_high", "confidence"}`` (``std`` with ddof=1, Student-t interval; NaNs and
    episodes lacking the key are not valid values). Boolean keys give ``{"kind": "rate", "n",
    "n_valid", "successes", "rate", "mean" (= rate), "std" (NaN), "min", "max", "sum",
    "ci_low", "ci_high", "confidence"}`` with a Wilson score interval. ``n`` is the number of
    episodes aggregated.

    Args:
        metrics: Per-episode metrics (objects or their ``to_dict()``).
        confidence: Confidence level of the intervals, in (0, 1).

    Returns:
        Dict keyed by dotted metric name, in first-seen order.
    """
    confidence = check_probability("confidence", confidence)
    flats = [flatten_metrics(m) for m in metrics]
    keys: dict[str, bool] = {}
    for f in flats:
        for k, v in f.items():
            keys.setdefault(k, isinstance(v, bool))
    n_ep = len(flats)
    out: dict[str, dict[str, Any]] = {}
    for key, is_bool in keys.items():
        present = [f[key] for f in flats if key in f]
        if is_bool:
            vals = np.asarray([bool(v) for v in present], dtype=bool)
            k = int(vals.sum())
            n_valid = int(vals.size)
            rate = k / n_valid if n_valid else math.nan
            low, high = wilson_interval(k, n_valid, confidence)
            out[key] = {
                "kind": "rate",
                "n": n_ep,
                "n_valid": n_valid,
                "successes": k,
                "rate": rate,
                "mean": rate,
                "std": math.nan,
                "min": float(vals.min()) if n_valid else math.nan,
                "max": float(vals.max()) if n_valid else math.nan,
                "sum": float(k),
                "ci_low": low,
                "ci_high": high,
                "confidence": confidence,
            }
        else:
            arr = np.asarray(present, dtype=np.float64)
            arr = arr[np.isfinite(arr)]
            n_valid = int(arr.size)
            low, high = t_interval(arr, confidence)
            out[key] = {
                "kind": "mean",
                "n": n_ep,
                "n_valid": n_valid,
                "mean": float(arr.mean()) if n_valid else math.nan,
                "std": float(arr.std(ddof=1)) if n_valid >= 2 else math.nan,
                "min": float(arr.min()) if n_valid else math.nan,
                "max": float(arr.max()) if n_valid else math.nan,
                "sum": float(arr.sum()),
                "ci_low": low,
                "ci_high": high,
                "confidence": confidence,
            }
    return out
