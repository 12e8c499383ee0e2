"""Reproduce the paper's experiment: three controllers, paper scenario and a random bank.

The three controllers run on the paper's scenario and on a fixed bank of seeded random
encounters.

    python baselines/paper_experiment.py [--paper-episodes 20] [--bank-episodes 200] [--workers 2]

Writes ``baselines/results/paper.json``, ``baselines/results/random_bank.json.gz`` (every metric
of every episode, the config and the package version), ``baselines/results/summary.md`` (the
side-by-side tables quoted in the README) and the paper's figure set for seed 0 in
``docs/figures/``. Every controller plays the same seeds, so they meet the same encounters.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from uasep_env import make_config
from uasep_env.evaluation import EvaluationResult, evaluate, write_json
from uasep_env.plotting import plot_paper_figures
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.tables import render_table

POLICIES = ("apf", "motion-state-apf", "traditional-apf")
ROOT = Path(__file__).resolve().parent
#: The random bank's seeds: fixed, disjoint from the paper runs.
BANK_FIRST_SEED = 100_000

# (label, dotted metric, statistic, format)
ROWS: tuple[tuple[str, str, str, str], ...] = (
    ("min UAV-UAV separation (m)", "episode.min_uav_separation", "mean", ".1f"),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", "mean", ".1f"),
    ("min distance to reachable region (m)", "episode.min_region_distance", "mean", ".1f"),
    ("episodes with UAV-UAV loss of separation", "episode.uav_loss_of_separation", "rate", ".0%"),
    (
        "episodes with UAV-obstacle loss of separation",
        "episode.obstacle_loss_of_separation",
        "rate",
        ".0%",
    ),
    ("episodes with a collision", "episode.collision", "rate", ".0%"),
    ("max deviation from plan (m)", "episode.max_deviation", "mean", ".1f"),
    ("longest conflict resolution (s)", "episode.max_conflict_duration", "mean", ".1f"),
    ("max acceleration std, z (m/s^2)", "episode.max_acc_std.z", "mean", ".3f"),
    ("max acceleration change, z (m/s^3)", "episode.max_acc_rate.z", "mean", ".2f"),
)


def _cell(agg: dict[str, Any], key: str, stat: str, fmt: str) -> str:
    s = agg.get(key)
    if not s:
        return "n/a"
    lo, hi = s.get("ci_low"), s.get("ci_high")
    if stat == "rate":
        txt = format(s["rate"], fmt)
        return f"{txt} [{format(lo, fmt)}, {format(hi, fmt)}]" if lo is not None else txt
    mean = s.get("mean")
    if mean is None:
        return "n/a"
    if s.get("n_valid", 0) > 1 and lo is not None and hi is not None:
        return f"{format(mean, fmt)} [{format(lo, fmt)}, {format(hi, fmt)}]"
    return format(mean, fmt)


def table(result: EvaluationResult, rows: tuple[tuple[str, str, str, str], ...] = ROWS) -> str:
    """A markdown table, controllers side by side (mean [95 % CI] / rate [Wilson CI])."""
    labels = list(result.results)
    body = [
        [name, *(_cell(result.results[p].aggregate, key, stat, fmt) for p in labels)]
        for name, key, stat, fmt in rows
    ]
    return render_table(["metric", *labels], body, markdown=True)


def timeline(result: EvaluationResult, uav: str = "uav_2") -> str:
    """Seed-0 conflict timeline of one UAV per controller (the paper's 103/122/130 s)."""

    def f(v: float) -> str:
        return "-" if v != v else f"{v:.1f}"

    body = []
    for label, res in result.results.items():
        t = res.episodes[0].metrics.uav(uav).timeline
        body.append(
            [label, *(f(v) for v in (t.t_leave, t.t_resolved, t.t_back, t.conflict_duration))]
        )
    headers = [
        "controller",
        "leaves plan (s)",
        "conflict resolved (s)",
        "back on plan (s)",
        "duration (s)",
    ]
    return render_table(headers, body, markdown=True)


def main() -> None:
    """Run both experiments and write the results."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--paper-episodes", type=int, default=20)
    parser.add_argument("--bank-episodes", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "results")
    parser.add_argument("--figures", type=Path, default=ROOT.parent / "docs" / "figures")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    paper = evaluate(
        list(POLICIES),
        make_config(scenario="paper"),
        range(args.paper_episodes),
        workers=args.workers,
        keep_episodes=1,
    )
    write_json(paper, args.out / "paper.json")
    plot_paper_figures({k: v[0] for k, v in paper.episodes.items()}, args.figures)

    bank = evaluate(
        list(POLICIES),
        make_config(scenario="random"),
        range(BANK_FIRST_SEED, BANK_FIRST_SEED + args.bank_episodes),
        workers=args.workers,
    )
    write_json(bank, args.out / "random_bank.json.gz")

    text = "\n\n".join(
        [
            f"## Paper scenario ({args.paper_episodes} seeds)",
            table(paper),
            "### Conflict timeline of the middle UAV (uav_2), seed 0",
            timeline(paper),
            f"## Random encounter bank ({args.bank_episodes} seeds from {BANK_FIRST_SEED})",
            table(bank),
        ]
    )
    atomic_write(args.out / "summary.md", text + "\n")
    print(text)


if __name__ == "__main__":
    main()
