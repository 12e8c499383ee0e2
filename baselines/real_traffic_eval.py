"""Every controller on real traffic: the real-traffic bank beside the synthetic held-out bank.

    python baselines/real_traffic_eval.py [--workers 1] [--episodes 300] [--synthetic-episodes 500]

The registered reference controllers (:func:`uasep_env.policies.reference_controllers`: the
APFs, MVP, ORCA, ...) and the shipped policies (``baselines/checkpoints/*.zip``, loaded
without unpickling) play the same encounters twice:

* the real-traffic bank: 300 ``real_traffic`` encounters
  (:data:`uasep_env.scenarios.REAL_TRAFFIC_TEST_SEEDS`, config
  :data:`uasep_env.scenarios.real_traffic.REAL_TRAFFIC_BANK`): a recorded glider or
  helicopter of the TEST flights (never drawn in training), at its recorded speed, placed to
  pass 0-10 m from a UAV's plan at 60-140 s;
* the same 300 seeds with the tracks slowed x0.2 (``obstacle.replay_speed_scale``,
  :data:`~uasep_env.scenarios.real_traffic.REAL_TRAFFIC_SLOW_BANK`) to the synthetic
  obstacles' speeds, turn rates and manoeuvre timing as recorded (the placement is drawn
  again, so the encounters differ in detail): speed apart from manoeuvres;
* the synthetic held-out bank: the 500 ``random`` encounters of
  ``baselines/learned_vs_apf.py`` (:data:`uasep_env.scenarios.HELD_OUT_SEEDS`), run again
  here so that both columns come from the same code.

Same metrics and intervals as ``learned_vs_apf.py`` (means with 95 % Student-t intervals,
rates with 95 % Wilson intervals). Writes ``baselines/results/real_traffic_eval.md`` (the
tables; the README shows the first) and ``real_traffic_eval.json.gz`` (every metric of every
real-traffic episode; the synthetic bank's aggregates, its episodes being those of
``learned_vs_apf.json.gz``), and prints the tables.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env import make_config, real_traffic
from uasep_env.atomic import atomic_write
from uasep_env.evaluation import EvaluationResult, evaluate, write_json
from uasep_env.metrics.statistics import wilson_interval
from uasep_env.scenarios import HELD_OUT_SEEDS, REAL_TRAFFIC_TEST_SEEDS, sample_scenario
from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK, REAL_TRAFFIC_SLOW_BANK
from uasep_env.tables import render_table

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from learned_vs_apf import TABLE_ROWS, compared_policies  # noqa: E402
from paper_experiment import table  # noqa: E402

#: The summary's columns: (heading, metric, statistic, format).
SUMMARY = (
    ("collision", "episode.collision", "rate", ".1%"),
    ("loss of separation (any)", "episode.loss_of_separation", "rate", ".1%"),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", "mean", ".1f"),
)


def _cell(agg: dict[str, Any], key: str, stat: str, fmt: str) -> str:
    s = agg[key]
    return f"{s[stat]:{fmt}} [{s['ci_low']:{fmt}}, {s['ci_high']:{fmt}}]"


def summary(banks: dict[str, EvaluationResult | None], rows: tuple = SUMMARY) -> str:
    """Controllers as rows; each metric on each bank (``name -> result``) in turn."""
    headers = ["controller"]
    for name, *_ in rows:
        headers += [f"{name}, {bank}" for bank in banks]
    body = []
    labels = next(r for r in banks.values() if r is not None).results
    for label in labels:
        row = [label]
        for _, key, stat, fmt in rows:
            row += [
                "-" if r is None else _cell(r.results[label].aggregate, key, stat, fmt)
                for r in banks.values()
            ]
        body.append(row)
    return render_table(headers, body, markdown=True)


def bank_classes(seeds: list[int]) -> dict[int, tuple[str, str, float]]:
    """Seed -> (aircraft class, flight, median placed speed m/s) of the bank's first obstacle."""
    cfg = make_config(REAL_TRAFFIC_BANK)
    tracks = real_traffic.load().tracks
    out = {}
    for seed in seeds:
        spec = sample_scenario(np.random.default_rng(seed), cfg)
        tr = tracks[int(spec.obstacle_track_index[0])]
        assert tr.split == "test", (seed, tr.flight)  # the bank holds test flights only
        out[seed] = (tr.aircraft_class, tr.flight, float(spec.obstacle_speed[0]))
    return out


def by_class(real: EvaluationResult, classes: dict[int, tuple[str, str, float]]) -> str:
    """Collision and loss-of-separation rates per aircraft class (Wilson intervals)."""
    body = []
    kinds = sorted({c for c, _, _ in classes.values()})
    for label, res in real.results.items():
        for kind in kinds:
            eps = [e for e in res.episodes if classes[e.seed][0] == kind]
            row = [label, kind, str(len(eps))]
            for key in ("collision", "loss_of_separation"):
                hits = sum(bool(getattr(e.metrics.episode, key)) for e in eps)
                lo, hi = wilson_interval(hits, len(eps))
                row.append(f"{hits / len(eps):.1%} [{lo:.1%}, {hi:.1%}]")
            body.append(row)
    headers = ["controller", "class", "episodes", "collision", "loss of separation (any)"]
    return render_table(headers, body, markdown=True)


def bank_table(classes: dict[int, tuple[str, str, float]]) -> str:
    """What the bank holds: episodes, distinct flights and tracks' speeds per class."""
    per: dict[str, list[tuple[str, float]]] = defaultdict(list)
    for kind, flight, speed in classes.values():
        per[kind].append((flight, speed))
    body = []
    for kind, v in sorted(per.items()):
        speeds = [s for _, s in v]
        body.append(
            [kind, str(len(v)), str(len({f for f, _ in v})),
             f"{np.median(speeds):.1f} ({min(speeds):.1f}-{max(speeds):.1f})"]
        )  # fmt: skip
    headers = ["class", "episodes", "test flights", "median speed, m/s (range over episodes)"]
    return render_table(headers, body, markdown=True)


def synthetic_aggregates(result: EvaluationResult) -> dict[str, Any]:
    """The synthetic bank's seeds and aggregates only.

    Its per-episode records are ``learned_vs_apf.json.gz``'s (the same seeds and controllers).
    """
    return {
        "seeds": list(result.seeds),
        "episodes": "baselines/results/learned_vs_apf.json.gz",
        "aggregate": {label: res.aggregate for label, res in result.results.items()},
    }


def main(argv: list[str] | None = None) -> str:
    """Evaluate both banks, write the results and print the tables."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--episodes", type=int, default=len(REAL_TRAFFIC_TEST_SEEDS))
    p.add_argument("--synthetic-episodes", type=int, default=len(HELD_OUT_SEEDS))
    p.add_argument("--out", type=Path, default=ROOT / "results")
    p.add_argument("--no-slow", dest="slow", action="store_false", help="skip the x0.2 bank")
    args = p.parse_args(argv)
    if not 1 <= args.episodes <= len(REAL_TRAFFIC_TEST_SEEDS):
        p.error(f"argument --episodes: must be in [1, {len(REAL_TRAFFIC_TEST_SEEDS)}]")
    if not 0 <= args.synthetic_episodes <= len(HELD_OUT_SEEDS):
        p.error(f"argument --synthetic-episodes: must be in [0, {len(HELD_OUT_SEEDS)}]")
    if args.workers < 1:
        p.error(f"argument --workers: must be >= 1, got {args.workers}")

    policies = compared_policies()
    real_seeds = list(REAL_TRAFFIC_TEST_SEEDS)[: args.episodes]
    syn_seeds = list(HELD_OUT_SEEDS)[: args.synthetic_episodes]
    t0 = time.perf_counter()
    real = evaluate(policies, make_config(REAL_TRAFFIC_BANK), real_seeds, workers=args.workers)
    t_real = time.perf_counter() - t0
    slow = None
    if args.slow:
        slow = evaluate(
            policies, make_config(REAL_TRAFFIC_SLOW_BANK), real_seeds, workers=args.workers
        )
    synthetic = None
    if syn_seeds:
        synthetic = evaluate(
            policies, make_config(scenario="random"), syn_seeds, workers=args.workers
        )
    t_all = time.perf_counter() - t0
    classes = bank_classes(real_seeds)
    real_what = (
        f"{len(real_seeds)} `real_traffic` encounters (test flights), seeds "
        f"{real_seeds[0]}-{real_seeds[-1]}"
    )
    syn_what = (
        f"{len(syn_seeds)} `random` encounters, seeds {syn_seeds[0]}-{syn_seeds[-1]}"
        if syn_seeds
        else "not run"
    )
    sections = [
        "### Synthetic vs real traffic",
        f"Synthetic: the held-out bank ({syn_what}). Real: the real-traffic bank ({real_what}). "
        "Rates with 95 % Wilson intervals, means with 95 % Student-t intervals.",
        summary({"synthetic": synthetic, "real": real}),
        f"### Real-traffic bank: {real_what}",
        table(real, TABLE_ROWS),
        "### Real-traffic bank by aircraft class",
        by_class(real, classes),
        "### The real-traffic bank",
        bank_table(classes),
    ]
    if slow is not None:
        sections += [
            "### Real tracks slowed to synthetic speeds",
            f"The same seeds with `obstacle.replay_speed_scale=0.2` ({real_what}, tracks "
            "slowed x0.2; turn rates and timing as recorded).",
            summary({"synthetic": synthetic, "real": real, "real x0.2": slow}, SUMMARY[:2]),
            f"### Real-traffic bank slowed x0.2: {real_what}",
            table(slow, TABLE_ROWS),
        ]
    if synthetic is not None:
        sections += [f"### Held-out bank: {syn_what}", table(synthetic, TABLE_ROWS)]
    sections.append(
        f"Run time: {t_real:.0f} s for the real-traffic bank, {t_all:.0f} s in all "
        f"(`python baselines/real_traffic_eval.py --workers {args.workers}`, 2 shared cores)."
    )
    text = "\n\n".join(sections) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write(args.out / "real_traffic_eval.md", text.encode("utf-8"))
    results = {
        "real_traffic": real,
        **({"real_traffic_slow": slow} if slow else {}),
        **({"random": synthetic_aggregates(synthetic)} if synthetic else {}),
    }
    write_json(
        {"meta": {"run_time_s": t_all, "real_traffic_s": t_real, "bank": REAL_TRAFFIC_BANK},
         **results},
        args.out / "real_traffic_eval.json.gz",
    )  # fmt: skip
    print(text)
    return text


if __name__ == "__main__":
    main()
