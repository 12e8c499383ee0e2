"""Tables of episode metrics and aggregates: rows (:func:`summary_table`) and their text."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from uasep_env.metrics.results import EpisodeMetrics
from uasep_env.runtime.tables import render_table

__all__ = ["format_table", "summary_table"]

#: Default columns of the tables: safety first (per UAV and per episode alike), then deviation.
_SAFETY_COLUMNS: tuple[str, ...] = (
    "min_uav_separation",
    "min_obstacle_distance",
    "min_region_distance",
    "uav_los_events",
    "obstacle_los_events",
    "collision",
)
_UAV_COLUMNS: tuple[str, ...] = (
    *_SAFETY_COLUMNS,
    "deviation.max_norm",
    "deviation.rms_norm",
    "timeline.t_leave",
    "timeline.t_resolved",
    "timeline.t_back",
    "timeline.conflict_duration",
    "path_length_ratio",
)
_EPISODE_COLUMNS: tuple[str, ...] = (*_SAFETY_COLUMNS, "max_deviation", "max_conflict_duration")

_AGG_COLUMNS: tuple[str, ...] = (
    "metric",
    "kind",
    "mean",
    "std",
    "ci_low",
    "ci_high",
    "min",
    "max",
    "n_valid",
)


def _lookup(d: Mapping[str, Any], dotted: str) -> Any:
    node: Any = d
    for part in dotted.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return math.nan
        node = node[part]
    return node


def summary_table(
    data: Mapping[str, Mapping[str, Any]] | EpisodeMetrics | Sequence[EpisodeMetrics],
    keys: Sequence[str] | None = None,
) -> list[tuple[Any, ...]]:
    """Build table rows; the first row is the header.

    * ``aggregate(...)`` output: one row per metric with columns ``metric, kind, mean, std,
      ci_low, ci_high, min, max, n_valid``; ``keys`` selects (and orders) metrics, matched
      exactly or as a dotted suffix (``"episode.collision"`` or ``"collision"``).
    * One :class:`EpisodeMetrics`: one row per UAV, ``keys`` = dotted per-UAV fields
      (default: separation, loss of separation, deviation and timeline).
    * A sequence of :class:`EpisodeMetrics`: one row per episode, ``keys`` = dotted
      episode-summary fields.

    Args:
        data: What to tabulate.
        keys: Metric or column selection, see above.

    Returns:
        Rows as tuples, header first; pass them to :func:`format_table`.
    """
    if isinstance(data, EpisodeMetrics):
        cols = tuple(keys) if keys is not None else _UAV_COLUMNS
        rows: list[tuple[Any, ...]] = [("uav", *cols)]
        for u in data.uavs:
            ud = u.to_dict()
            rows.append((u.name, *(_lookup(ud, c) for c in cols)))
        return rows
    if isinstance(data, Mapping):
        rows = [_AGG_COLUMNS]
        names = list(data.keys())
        if keys is not None:
            chosen: list[str] = []
            for k in keys:
                chosen.extend(n for n in names if n == k or n.endswith("." + k))
            names = list(dict.fromkeys(chosen))
        for name in names:
            s = data[name]
            rows.append((name, *(s.get(c, math.nan) for c in _AGG_COLUMNS[1:])))
        return rows
    cols = tuple(keys) if keys is not None else _EPISODE_COLUMNS
    rows = [("episode", *cols)]
    for i, em in enumerate(data):
        ed = em.episode.to_dict()
        rows.append((i, *(_lookup(ed, c) for c in cols)))
    return rows


def _format_cell(value: Any, floatfmt: str) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if math.isnan(value):
            return "nan"
        return format(float(value), floatfmt)
    if isinstance(value, Mapping):
        return "(" + ", ".join(_format_cell(v, floatfmt) for v in value.values()) + ")"
    if value is None:
        return "-"
    return str(value)


def format_table(
    rows: Sequence[Sequence[Any]],
    headers: Sequence[str] | None = None,
    floatfmt: str = ".4g",
) -> str:
    """Format rows as a plain-text table (:func:`uasep_env.runtime.tables.render_table`).

    Text columns are left-aligned, numeric columns right-aligned; a dashed rule separates
    the header. Floats use ``floatfmt``, booleans print as ``yes``/``no``.

    Args:
        rows: Table rows. When ``headers`` is None the first row is the header (the shape
            :func:`summary_table` returns).
        headers: Column headers, or None.
        floatfmt: Format spec for floats.

    Returns:
        The table as a string (no trailing newline).

    Raises:
        ValueError: If a row's length differs from the header's.
    """
    rows = [tuple(r) for r in rows]
    if headers is None:
        if not rows:
            return ""
        headers, body = tuple(str(h) for h in rows[0]), rows[1:]
    else:
        headers, body = tuple(str(h) for h in headers), rows
    width = len(headers)
    numeric = [
        bool(body)
        and all(
            len(r) == width
            and isinstance(r[j], (int, float, np.integer, np.floating))
            and not isinstance(r[j], bool)
            for r in body
        )
        for j in range(width)
    ]
    cells = [[_format_cell(v, floatfmt) for v in r] for r in body]
    align = ["right" if num else "left" for num in numeric]
    return render_table(headers, cells, align=align)
