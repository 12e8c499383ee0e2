"""The views of a scaling result (``uasep-report``): markdown tables, targets and the figure.

The result is the JSON-ready dict :func:`uasep_env.reporting.scaling.run` returns (and
``<out>.json`` holds): ``rows`` (one per cell and policy, each with the aggregates of
:data:`METRICS`), ``cells``, ``policies``, ``seeds``, ``held_out``, ``command``,
``elapsed_s`` and ``cpu_s``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from uasep_env.metrics.statistics import VERDICT_LEGEND, stated_rate_verdict
from uasep_env.runtime.atomic import atomic_output
from uasep_env.runtime.tables import render_table

APFS = ("apf", "motion-state-apf", "traditional-apf")
#: (dotted aggregate key, label, unit): safety first, then deviation, then the episode cost
#: (:class:`uasep_env.metrics.EpisodeSummary`: each UAV's per-step costs summed over the
#: episode; the team's the mean over UAVs, and the worst UAV's).
METRICS: tuple[tuple[str, str, str], ...] = (
    ("episode.collision", "episodes with a collision", "rate"),
    ("episode.loss_of_separation", "episodes with loss of separation", "rate"),
    ("episode.terminated", "early ends (collision or lost UAV)", "rate"),
    ("episode.min_uav_separation", "min UAV-UAV separation", "m"),
    ("episode.min_obstacle_distance", "min UAV-obstacle distance", "m"),
    ("episode.min_region_distance", "min distance to reachable region", "m"),
    ("episode.uav_los_events", "loss-of-separation events UAV-UAV", "count"),
    ("episode.obstacle_los_events", "loss-of-separation events UAV-obstacle", "count"),
    ("episode.max_conflict_duration", "max conflict duration", "s"),
    ("episode.max_deviation", "max deviation", "m"),
    ("episode.max_rms_deviation", "RMS deviation, worst UAV", "m"),
    ("episode.cost", "episode cost, team mean", "cost"),
    ("episode.max_uav_cost", "episode cost, worst UAV", "cost"),
)
#: UAV counts the size target is checked at.
TARGET_UAVS = (8, 32)


def sizes_text(sizes: list[int]) -> str:
    """Formation sizes as a reader says them: ``8``, ``3-8`` (consecutive) or ``3, 5, 8``."""
    sizes = sorted(sizes)
    if len(sizes) > 2 and sizes == list(range(sizes[0], sizes[-1] + 1)):
        return f"{sizes[0]}-{sizes[-1]}"
    return ", ".join(str(n) for n in sizes)


def _fmt(stats: dict[str, Any] | None, unit: str) -> str:
    if stats is None:
        return "-"
    mean, lo, hi = stats.get("mean"), stats.get("ci_low"), stats.get("ci_high")
    if mean is None or not math.isfinite(mean):
        return "-"
    if unit == "rate":
        return f"{mean:.1%} [{lo:.1%}, {hi:.1%}]"
    digits = 2 if unit in ("count", "cost") else 1
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {0.5 * (hi - lo):.{digits}f}"


def shown_metrics(result: dict[str, Any]) -> list[tuple[str, str, str]]:
    """The :data:`METRICS` some row of ``result`` holds.

    A result written before a metric joined them (e.g. the episode cost) renders without it.
    """
    rows = [*result["rows"], *result.get("held_out", [])]
    return [m for m in METRICS if any(m[0] in r["metrics"] for r in rows)]


def sweeps(result: dict[str, Any]) -> dict[str, list[dict[str, Any]]]:
    """The rows of each sweep: by number of UAVs (fewest obstacles) and by obstacles."""
    grid = [tuple(c) for c in result["cells"]]
    base_m = min(m for _, m in grid)
    base_n = min(n for n, _ in grid)
    return {
        "n_uavs": [r for r in result["rows"] if r["n_obstacles"] == base_m],
        "n_obstacles": [r for r in result["rows"] if r["n_uavs"] == base_n],
    }


def targets(result: dict[str, Any]) -> list[tuple[str, str, str]]:
    """At 8 and 32 UAVs: each non-APF policy's collision rate no worse than the APF's.

    Each target's verdict is :func:`uasep_env.metrics.statistics.rate_verdict`'s: ``met``
    (the policy's rate is at most the APF's and its 95 % Wilson interval rules out a rate
    more than :data:`~uasep_env.metrics.statistics.NO_WORSE_MARGIN` above the APF's),
    ``not met`` (its interval lies wholly above the APF's) or ``not shown`` (neither: too
    few episodes for the intervals to decide), followed by the episodes behind it; ``not
    evaluated`` when the cell lacks the APF or the policy.

    Returns:
        ``(target, measured, verdict)`` per target.
    """
    by = {(r["n_uavs"], r["n_obstacles"], r["policy"]): r for r in result["rows"]}
    out: list[tuple[str, str, str]] = []
    others = [p["label"] for p in result["policies"] if p["label"] not in APFS]
    for n in TARGET_UAVS:
        ms = sorted({r["n_obstacles"] for r in result["rows"] if r["n_uavs"] == n})
        for m in ms[:1]:
            apf = by.get((n, m, "apf"))
            for label in others:
                mine = by.get((n, m, label))
                what = f"{label}: collisions at {n} UAVs no worse than the APF's"
                if apf is None or mine is None:
                    out.append((what, "-", "not evaluated (needs apf and the policy)"))
                    continue
                a, b = apf["metrics"]["episode.collision"], mine["metrics"]["episode.collision"]
                out.append(
                    (what, f"{_fmt(b, 'rate')} vs APF {_fmt(a, 'rate')}", stated_rate_verdict(b, a))
                )
    return out


def markdown(result: dict[str, Any], command: str, elapsed_s: float) -> str:
    """The results file: one table per sweep, the targets, and how it was made."""
    seeds = result["seeds"]
    cpu = f" ({result['cpu_s'] / 60:.1f} min of CPU here)" if result.get("cpu_s") else ""
    lines = [
        "# Safety and deviation against formation size and obstacle count",
        "",
        f"Made by `{command}` in {elapsed_s / 60:.1f} min of wall time{cpu} on this "
        "project's 2-core machine (shared with other work: wall times vary with its load). "
        f"{seeds['count']} `random` encounters per cell (seeds {seeds['first']:,}-"
        f"{seeds['first'] + seeds['count'] - 1:,}, `SCALING_SEEDS`), the same for every "
        "policy; rates with 95 % Wilson intervals, means ± the 95 % Student-t half-width.",
        "",
    ]
    for p in result["policies"]:
        if p["kind"] == "checkpoint":
            sizes = p.get("sizes") or [p["trained"][0]]
            lines.append(
                f"* `{p['label']}`: trained with {sizes_text(sizes)} UAVs and {p['trained'][1]} "
                f"obstacle(s), observes the {p['layout'][0]} nearest UAVs and "
                f"{p['layout'][1]} nearest obstacle(s); other cells are zero-shot."
            )
    metrics = shown_metrics(result)
    headers = ["UAVs", "obstacles", "policy", *(label for _, label, _ in metrics)]
    for key, title in (("n_uavs", "By formation size"), ("n_obstacles", "By obstacle count")):
        rows = [
            [str(r["n_uavs"]), str(r["n_obstacles"]), r["policy"]]
            + [_fmt(r["metrics"].get(k), unit) for k, _, unit in metrics]
            for r in sweeps(result)[key]
        ]
        align = ["right", "right", "left"] + ["right"] * len(metrics)
        lines += ["", f"## {title}", "", render_table(headers, rows, align=align, markdown=True)]
    if result.get("held_out"):
        rows = [
            [str(r["n_uavs"]), str(r["n_obstacles"]), r["policy"]]
            + [_fmt(r["metrics"].get(k), unit) for k, _, unit in metrics]
            for r in result["held_out"]
        ]
        n_held = result["held_out"][0]["metrics"]["episode.collision"]["n"]
        lines += [
            "",
            "## Held-out bank",
            "",
            f"The first {n_held} encounters of the held-out bank (`HELD_OUT_SEEDS`, from "
            "5,000,000; 3 UAVs, 1 obstacle).",
            "",
            render_table(headers, rows, align=align, markdown=True),
        ]
    body = [list(t) for t in targets(result)]
    if body:
        lines += [
            "",
            "## Targets",
            "",
            VERDICT_LEGEND,
            "",
            render_table(["target", "measured", "verdict"], body, markdown=True),
        ]
    return "\n".join(lines) + "\n"


def figure(result: dict[str, Any], path: Path) -> Path:
    """Every metric against the number of UAVs and of obstacles, with the intervals."""
    from matplotlib.figure import Figure  # lazily: only the figure needs matplotlib

    sw = sweeps(result)
    labels = [p["label"] for p in result["policies"]]
    metrics = shown_metrics(result)
    n_rows = math.ceil(len(metrics) / 2)
    fig = Figure(figsize=(16, 2.6 * n_rows), layout="constrained")
    axes = fig.subplots(n_rows, 4, squeeze=False)
    for i, (key, title, unit) in enumerate(metrics):
        for j, axis in enumerate(("n_uavs", "n_obstacles")):
            ax = axes[i // 2, 2 * (i % 2) + j]
            for label in labels:
                rows = sorted((r for r in sw[axis] if r["policy"] == label), key=lambda r: r[axis])
                xs = [r[axis] for r in rows]
                st = [r["metrics"].get(key, {}) for r in rows]
                ys = [s.get("mean", math.nan) for s in st]
                lo = [
                    y - s.get("ci_low", y) if s.get("ci_low") is not None else 0
                    for y, s in zip(ys, st, strict=True)
                ]
                hi = [
                    s.get("ci_high", y) - y if s.get("ci_high") is not None else 0
                    for y, s in zip(ys, st, strict=True)
                ]
                ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=label)
            ax.set_title(
                f"{title}" + ("" if unit in ("rate", "count", "cost") else f" ({unit})"), fontsize=8
            )
            ax.set_xlabel("UAVs" if axis == "n_uavs" else "obstacles", fontsize=8)
            if axis == "n_uavs":
                ax.set_xscale("log", base=2)
            ax.set_xticks(sorted({r[axis] for r in sw[axis]}))
            ax.set_xticklabels([str(x) for x in sorted({r[axis] for r in sw[axis]})])
            ax.tick_params(labelsize=7)
    for k in range(len(metrics), 2 * n_rows):
        for j in range(2):
            axes[k // 2, 2 * (k % 2) + j].axis("off")
    axes[0, 0].legend(fontsize=7)
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=80, facecolor="white")
    return path
