"""The readable summary of an evaluation: the policies side by side (``uasep-eval``'s stdout)."""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from typing import Any

from uasep_env.evaluation.results import EvaluationResult
from uasep_env.policies.env_version import version_label
from uasep_env.runtime.tables import render_table
from uasep_env.sim.dynamics import AXES

__all__ = ["format_summary", "summary_rows"]

#: (label, dotted aggregate key, digits) of the episode-level rows of the summary; negative
#: digits mark counts (no decimals for one episode, ``-digits`` decimals for a mean).
_EPISODE_ROWS: tuple[tuple[str, str, int], ...] = (
    ("min UAV-UAV separation (m)", "episode.min_uav_separation", 2),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", 2),
    ("min distance to reachable region (m)", "episode.min_region_distance", 2),
    ("loss-of-separation events UAV-UAV", "episode.uav_los_events", -2),
    ("loss-of-separation events UAV-obstacle", "episode.obstacle_los_events", -2),
    ("collision events", "episode.collision_events", -2),
    ("episode cost, team mean", "episode.cost", 2),
    ("episode cost, worst UAV", "episode.max_uav_cost", 2),
    ("max deviation (m)", "episode.max_deviation", 2),
    ("RMS deviation, worst UAV (m)", "episode.max_rms_deviation", 2),
    ("max conflict duration (s)", "episode.max_conflict_duration", 1),
)


def _pm_symbol() -> str:
    enc = getattr(sys.stdout, "encoding", None) or "ascii"
    try:
        "±".encode(enc)
    except (LookupError, UnicodeEncodeError):
        return "+/-"
    return "±"


def _fmt_num(value: Any, digits: int) -> str:
    if value is None:
        return "-"
    v = float(value)
    if not math.isfinite(v):
        return "-"
    return f"{v:.{digits}f}"


def _cell(stats: Mapping[str, Any] | None, digits: int, single: bool, pm: str) -> str:
    """One summary cell: the value (one episode) or mean ± CI half-width / rate."""
    if stats is None:
        return "-"
    if stats.get("kind") == "rate":
        return f"{stats['successes']}/{stats['n_valid']}"
    if digits < 0:
        digits = 0 if single else -digits
    if single or stats.get("n_valid", 0) < 2:
        cell = _fmt_num(stats.get("mean"), digits)
        if not single and stats.get("n_valid", 0) < stats.get("n", 0):
            cell += f" (n={stats['n_valid']})"
        return cell
    mean, low, high = stats.get("mean"), stats.get("ci_low"), stats.get("ci_high")
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return _fmt_num(mean, digits)
    cell = f"{_fmt_num(mean, digits)} {pm} {_fmt_num(0.5 * (high - low), digits)}"
    if stats["n_valid"] < stats["n"]:
        cell += f" (n={stats['n_valid']})"
    return cell


def summary_rows(result: EvaluationResult) -> list[list[str]]:
    """Rows of the side-by-side summary (header first: ``metric``, then one column per policy).

    With one episode the cells are the values; with more, ``mean ± half-width`` of the
    confidence interval of the mean (``n=`` when some episodes had no value, e.g. no UAV
    left its track) and ``k/n`` for rates (episodes with a collision). The episode cost (the
    cost channel, :mod:`uasep_env.interface.costs`) is each UAV's per-step cost summed over
    the episode; the team's is the mean of its UAVs' (:class:`uasep_env.metrics.EpisodeSummary`).

    Args:
        result: An :func:`evaluate` result.

    Returns:
        Rows of strings.
    """
    labels = list(result.policies)
    aggs = {lab: result.results[lab].aggregate for lab in labels}
    single = len(result.seeds) == 1
    pm = _pm_symbol()
    uav_names = [u.name for u in result.results[labels[0]].episodes[0].metrics.uavs]

    def row(title: str, key: str, digits: int) -> list[str]:
        return [title, *(_cell(aggs[lab].get(key), digits, single, pm) for lab in labels)]

    trained = result.trained_env_versions or {}
    rows: list[list[str]] = [["metric", *(version_label(lab, trained.get(lab)) for lab in labels)]]
    rows.extend(row(t, k, d) for t, k, d in _EPISODE_ROWS)
    if not single:
        rows.append(row("episodes with a collision", "episode.collision", 0))
        rows.append(row("episodes with loss of separation", "episode.loss_of_separation", 0))
    for ax in AXES:
        rows.append(row(f"acc std {ax}, worst UAV (m/s²)", f"episode.max_acc_std.{ax}", 3))
    rows.append(row("vel std z, worst UAV (m/s)", "episode.max_vel_std.z", 3))
    for name in uav_names:
        pre = f"uav.{name}"
        if single:
            cells = [name + " leave / resolved / back (s)"]
            for lab in labels:
                parts = [
                    _fmt_num(aggs[lab].get(f"{pre}.timeline.{f}", {}).get("mean"), 1)
                    for f in ("t_leave", "t_resolved", "t_back")
                ]
                left = aggs[lab].get(f"{pre}.timeline.left", {}).get("successes", 1)
                cells.append(" / ".join(parts) if left else "never left")
            rows.append(cells)
        rows.append(row(f"{name} conflict duration (s)", f"{pre}.timeline.conflict_duration", 1))
        rows.append(row(f"{name} max deviation (m)", f"{pre}.deviation.max_norm", 2))
        rows.append(row(f"{name} acc std z (m/s²)", f"{pre}.fluctuation.acc_std.z", 3))
        rows.append(row(f"{name} episode cost", f"{pre}.cost", 2))
    rows.append(row("episode return", "episode.episode_return", 1))
    return rows


def format_summary(result: EvaluationResult) -> str:
    """The readable summary: a heading and the policies side by side.

    Args:
        result: An :func:`evaluate` result.

    Returns:
        Multi-line text.
    """
    seeds = result.seeds
    n = len(seeds)
    cfg = result.config
    settings = result.settings
    what = (
        f"{n} episode (seed {seeds[0]})"
        if n == 1
        else f"{n} episodes (seeds {seeds[0]}..{seeds[-1]}), mean "
        f"{_pm_symbol()} {100 * settings.confidence:.0f}% CI half-width"
    )
    env = f"env -v{result.env_version}, " if result.env_version is not None else ""
    head = (
        f"uasep-eval {result.version}: {env}scenario {cfg.scenario}, {what}; "
        f"{cfg.n_uavs} UAVs, {cfg.n_obstacles} obstacle slot(s), "
        f"{cfg.episode_duration:g} s episodes"
    )
    uav = cfg.uav
    foot = (
        f"collision distance {uav.collision_distance:g} m, separation UAV-UAV "
        f"{uav.separation_distance:g} m / UAV-obstacle {uav.obstacle_separation:g} m; "
        f"deviation and fluctuation after t = {settings.settle_time:g} s, "
        f"off-track beyond {settings.deviation_threshold:g} m; "
        f"episode cost = a UAV's per-step costs summed (cost.* weights; by default its "
        f"steps in loss of separation), team = mean over UAVs; "
        f"'-' = undefined (e.g. never left the track)"
        + ("; (n=k): only k episodes had a value." if n > 1 else ".")
    )
    header, *rows = summary_rows(result)
    table = render_table(header, rows, align=["left"] + ["right"] * (len(header) - 1))
    return "\n".join([head, "", table, "", foot])
