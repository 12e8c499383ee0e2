"""Fronts of safety against cost: Pareto masks, the knee, and the cost at equal safety.

``uasep-tradeoff`` (the knee that sets each controller's default, the cost at equal
min distance) and ``uasep-bench`` (the deviation at equal loss-of-separation rate) share
these. A front is a list of settings (dicts), each with its safety and cost statistics.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from uasep_env.metrics.statistics import NOT_MET, rate_verdict

__all__ = [
    "deviation_at_budget",
    "interpolate_at",
    "knee",
    "knee_distances",
    "pareto",
]


def pareto(safety: np.ndarray, cost: np.ndarray, higher_is_safer: bool) -> np.ndarray:
    """Mask of the settings no other setting beats on both safety and cost."""
    s = safety if higher_is_safer else -safety
    keep = np.ones(len(s), bool)
    for i in range(len(s)):
        better = (s >= s[i]) & (cost <= cost[i]) & ((s > s[i]) | (cost < cost[i]))
        keep[i] = not better.any()
    return keep


def _collision(row: Mapping[str, Any]) -> dict[str, float]:
    """A row's collision rate as the interval :func:`rate_verdict` reads."""
    return {"rate": row["collision"], "ci_low": row["collision_lo"], "ci_high": row["collision_hi"]}


def knee_distances(rows: Sequence[dict[str, Any]]) -> list[tuple[dict[str, Any], float]]:
    """The front of :func:`knee`, each setting with its distance from the chord.

    Both axes scaled to [0, 1]; settings off the front or shown to collide more often
    than the safest one are left out. With fewer than 3 settings on the front, the safest has 1.
    """
    rows = sorted(rows, key=lambda r: r["value"])
    safest = min(r["collision"] for r in rows)
    safest_hi = min(r["collision_hi"] for r in rows if r["collision"] == safest)
    ref = {"rate": safest, "ci_low": safest, "ci_high": safest_hi}
    # Eligible unless shown worse (rate_verdict's "not met"): the knee is a choice among
    # settings, not a claim that a target is met, so "not shown" settings stay candidates.
    ok = [r for r in rows if rate_verdict(_collision(r), ref) != NOT_MET]
    s = np.array([r["min_obstacle_distance"] for r in ok])
    c = np.array([r["max_deviation"] for r in ok])
    front = [r for r, k in zip(ok, pareto(s, c, True), strict=True) if k]
    if len(front) < 3:
        best = max(front, key=lambda r: r["min_obstacle_distance"])
        return [(r, 1.0 if r is best else 0.0) for r in front]
    x = np.array([r["min_obstacle_distance"] for r in front])
    y = np.array([r["max_deviation"] for r in front])
    x = (x - x.min()) / max(np.ptp(x), 1e-12)
    y = (y - y.min()) / max(np.ptp(y), 1e-12)
    i0, i1 = np.argmin(x), np.argmax(x)
    d = np.abs((x[i1] - x[i0]) * (y[i0] - y) - (x[i0] - x) * (y[i1] - y[i0]))
    return [(r, float(di)) for r, di in zip(front, d, strict=True)]


def knee(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The knee of a method's front of max deviation against min obstacle distance.

    Among the settings not shown to collide more often than the method's safest setting
    (:func:`~uasep_env.metrics.statistics.rate_verdict` is not ``not met``: the Wilson
    intervals overlap, or the setting's lies below) and on the Pareto front, the point
    farthest from the chord between the front's ends, both axes scaled to [0, 1] (the
    "kneedle" rule): past it, more distance costs more deviation per metre than before it.
    """
    return max(knee_distances(rows), key=lambda rd: rd[1])[0]


def interpolate_at(rows: Sequence[Mapping[str, Any]], level: float, x: str, y: str) -> float | None:
    """``y`` linearly interpolated along a front at ``x == level`` (None: out of its reach).

    Settings whose ``y`` is not finite are left out; the rest are ordered by ``x``.
    """
    xs = np.array([r[x] for r in rows], float)
    ys = np.array([r[y] for r in rows], float)
    ok = np.isfinite(xs) & np.isfinite(ys)
    xs, ys = xs[ok], ys[ok]
    if xs.size == 0 or not xs.min() <= level <= xs.max():
        return None
    order = np.argsort(xs, kind="stable")
    return float(np.interp(level, xs[order], ys[order]))


def deviation_at_budget(
    points: Sequence[Mapping[str, Any]],
    budget: float,
    rate: str = "loss_of_separation",
    cost: str = "max_deviation",
) -> dict[str, Any]:
    """The least cost at which a method's ``rate`` is no worse than ``budget``, collision-free.

    Among the settings with no collision (``collision == 0``) and a finite rate and cost,
    the Pareto front of ``rate`` (lower is safer) against ``cost``; the answer is the least of
    the costs of the front's settings whose rate is within the budget and of the cost
    interpolated along the front at ``rate == budget`` (:func:`interpolate_at`, as the
    trade-off report's costs at equal distance): between a setting over the budget and
    one under it, the front's straight segment crosses the budget at that cost.

    Args:
        points: The method's settings: dicts with ``value`` (its knob's), ``collision``,
            ``rate`` and ``cost`` keys.
        budget: The rate to meet, in [0, 1].
        rate: The key of the safety rate.
        cost: The key of the cost.

    Returns:
        ``{"deviation": float or None, "setting": value or [low, high] (interpolated
        between two settings) or None, "reason": why None (absent otherwise)}``.
    """
    ok = [
        p
        for p in points
        if p["collision"] == 0 and math.isfinite(p[rate]) and math.isfinite(p[cost])
    ]
    if not ok:
        return {"deviation": None, "setting": None, "reason": "no setting without a collision"}
    mask = pareto(np.array([p[rate] for p in ok]), np.array([p[cost] for p in ok]), False)
    front = sorted((p for p, k in zip(ok, mask, strict=True) if k), key=lambda p: p[rate])
    best: tuple[float, Any] | None = None
    for p in front:
        if p[rate] <= budget and (best is None or p[cost] < best[0]):
            best = (float(p[cost]), p.get("value"))
    at = interpolate_at(front, budget, rate, cost)
    if at is not None and (best is None or at < best[0]):
        hi = next(p for p in front if p[rate] >= budget)  # the first at or over the budget
        lo = front[front.index(hi) - 1] if front.index(hi) > 0 else hi
        setting = (
            hi.get("value")
            if hi[rate] == budget or lo is hi
            else sorted([lo.get("value"), hi.get("value")])
        )
        best = (at, setting)
    if best is None:
        least = min(p[rate] for p in front)
        return {
            "deviation": None,
            "setting": None,
            "reason": f"least collision-free rate {least:.3g} is over the budget",
        }
    return {"deviation": best[0], "setting": best[1]}
