"""Every controller on real traffic: the real-traffic bank beside the synthetic held-out bank.

    python baselines/real_traffic_eval.py [--workers 1] [--episodes 300] [--synthetic-episodes 500]
    python baselines/real_traffic_eval.py --prediction enclosing,calibrated

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

``--prediction`` chooses the predicted region (``prediction.fit``) of the runs: ``enclosing``
(the default of ``-v2``, the files above) and/or ``calibrated`` (the default from ``-v3`` on:
the conformal region per aircraft class, :mod:`uasep_env.reachable.calibrated`): the same
banks with ``prediction.fit="calibrated"``,
written to ``real_traffic_eval_calibrated.{md,json.gz}`` beside the enclosing runs' summary
(beside the enclosing figures: those of this run with ``enclosing,calibrated``, else those
stored in ``real_traffic_eval.json.gz``).
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from uasep_env import make_config, real_traffic
from uasep_env.evaluation import EvaluationResult, evaluate, write_json
from uasep_env.metrics.statistics import wilson_interval
from uasep_env.policies import reference_controllers, shipped_policies
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios import HELD_OUT_SEEDS, REAL_TRAFFIC_TEST_SEEDS, sample_scenario
from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK, REAL_TRAFFIC_SLOW_BANK

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from learned_vs_apf import LEARNED, TABLE_ROWS  # noqa: E402
from paper_experiment import table  # noqa: E402

#: The summary's columns: (heading, metric, statistic, format).
SUMMARY = (
    ("collision", "episode.collision", "rate", ".1%"),
    ("loss of separation (any)", "episode.loss_of_separation", "rate", ".1%"),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", "mean", ".1f"),
)


#: The predicted regions ``--prediction`` accepts (``prediction.fit``).
PREDICTIONS = ("enclosing", "calibrated")


def registry_controllers() -> dict[str, str]:
    """Every registered controller, then the shipped policies (name -> name).

    Read from the policy registry, so a controller registered there is evaluated here too;
    the shipped policies in :data:`learned_vs_apf.LEARNED`'s order, then any other by name.
    """
    shipped = shipped_policies()
    learned = [n for n in LEARNED if n in shipped] + sorted(n for n in shipped if n not in LEARNED)
    names = [*reference_controllers(), *learned]
    return {n: n for n in names}


@dataclass
class _Aggregates:
    """A bank's aggregates as a results file stores them (what :func:`summary` reads)."""

    results: dict[str, SimpleNamespace]


def stored_enclosing(path: Path) -> dict[str, _Aggregates | None]:
    """The enclosing runs' aggregates from their results file (``real_traffic_eval.json.gz``).

    Raises:
        FileNotFoundError: Naming the file and the command that writes it.
    """
    if not path.exists():
        raise FileNotFoundError(
            f"{path} does not exist: run `python baselines/real_traffic_eval.py` first, or "
            "--prediction enclosing,calibrated"
        )
    data = json.loads(gzip.decompress(path.read_bytes()))

    def bank(key: str) -> _Aggregates | None:
        if key not in data:
            return None
        res = (
            data[key]["results"]
            if "results" in data[key]
            else {k: {"aggregate": v} for k, v in data[key]["aggregate"].items()}
        )
        return _Aggregates({k: SimpleNamespace(aggregate=v["aggregate"]) for k, v in res.items()})

    return {"real": bank("real_traffic"), "slow": bank("real_traffic_slow"),
            "synthetic": bank("random")}  # fmt: skip


def with_fit(config: dict, fit: str) -> dict:
    """``config`` with ``prediction.fit`` set (always: the default moved in ``-v3``)."""
    return {**config, "prediction": {**config.get("prediction", {}), "fit": fit}}


def _cell(agg: dict[str, Any], key: str, stat: str, fmt: str) -> str:
    s = agg[key]
    return f"{s[stat]:{fmt}} [{s['ci_low']:{fmt}}, {s['ci_high']:{fmt}}]"


def summary(banks: dict[str, EvaluationResult | None], rows: tuple = SUMMARY) -> str:
    """Controllers as rows; each metric on each bank (``name -> result``) in turn."""
    headers = ["controller"]
    for name, *_ in rows:
        headers += [f"{name}, {bank}" for bank in banks]
    body = []
    # Every controller of any bank, in order of first appearance ("-" where a bank lacks it).
    labels = list(dict.fromkeys(lb for r in banks.values() if r is not None for lb in r.results))
    for label in labels:
        row = [label]
        for _, key, stat, fmt in rows:
            row += [
                "-"
                if r is None or label not in r.results
                else _cell(r.results[label].aggregate, key, stat, fmt)
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


def run_banks(
    policies: dict[str, str],
    fit: str,
    real_seeds: list[int],
    syn_seeds: list[int],
    slow: bool,
    workers: int,
) -> tuple[dict[str, EvaluationResult | None], float, float]:
    """The three banks with ``prediction.fit=fit``: results, real-bank and total seconds."""
    t0 = time.perf_counter()
    real = evaluate(policies, make_config(with_fit(REAL_TRAFFIC_BANK, fit)), real_seeds,
                    workers=workers)  # fmt: skip
    t_real = time.perf_counter() - t0
    slow_res = None
    if slow:
        slow_res = evaluate(
            policies, make_config(with_fit(REAL_TRAFFIC_SLOW_BANK, fit)), real_seeds,
            workers=workers,
        )  # fmt: skip
    synthetic = None
    if syn_seeds:
        synthetic = evaluate(
            policies, make_config(with_fit({"scenario": "random"}, fit)), syn_seeds,
            workers=workers,
        )  # fmt: skip
    return (
        {"real": real, "slow": slow_res, "synthetic": synthetic},
        t_real,
        (time.perf_counter() - t0),
    )


def calibrated_page(
    enc: dict[str, EvaluationResult | None],
    cal: dict[str, EvaluationResult | None],
    classes: dict[int, tuple[str, str, float]],
    real_what: str,
    syn_what: str,
    run_line: str,
) -> str:
    """The calibrated runs' page: beside the enclosing ones, then their own tables."""
    rows = (
        *SUMMARY,
        ("max deviation from the plan (m)", "episode.max_deviation", "mean", ".1f"),
        ("max RMS deviation (m)", "episode.max_rms_deviation", "mean", ".1f"),
    )
    pair = {"real, enclosing": enc["real"], "real, calibrated": cal["real"]}
    sections = [
        "### Real traffic: enclosing vs calibrated prediction",
        f"Real: the real-traffic bank ({real_what}); `prediction.fit` enclosing (`-v2`'s "
        "default) and calibrated (the default from `-v3` on: conformal regions per aircraft "
        "class, `docs/real_traffic.md`). Rates with 95 % Wilson intervals, means with 95 % "
        "Student-t intervals.",
        summary(pair, rows),
    ]
    if enc["synthetic"] is not None and cal["synthetic"] is not None:
        sections += [
            "### Synthetic held-out bank: enclosing vs calibrated prediction",
            f"The held-out bank ({syn_what}): Dubins obstacles, the `dubins` class's region.",
            summary(
                {"synthetic, enclosing": enc["synthetic"],
                 "synthetic, calibrated": cal["synthetic"]}, rows,
            ),
        ]  # fmt: skip
    sections += [
        f"### Real-traffic bank, calibrated prediction: {real_what}",
        table(cal["real"], TABLE_ROWS),
        "### Real-traffic bank by aircraft class, calibrated prediction",
        by_class(cal["real"], classes),
    ]
    if cal["slow"] is not None:
        sections += [
            "### Real tracks slowed x0.2, calibrated prediction",
            "The same seeds with `obstacle.replay_speed_scale=0.2`. The calibration is for "
            "the recorded speeds: slowed tracks are not the calibrated distribution (the "
            "region scales with the estimated speed, its constant part does not).",
            summary({"real x0.2, enclosing": enc["slow"], "real x0.2, calibrated": cal["slow"]},
                    SUMMARY[:2]),
        ]  # fmt: skip
    if cal["synthetic"] is not None:
        sections += [
            f"### Held-out bank, calibrated prediction: {syn_what}",
            table(cal["synthetic"], TABLE_ROWS),
        ]
    sections.append(run_line)
    return "\n\n".join(sections) + "\n"


def main(argv: list[str] | None = None) -> str:
    """Evaluate both banks, write the results and print the tables."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--episodes", type=int, default=len(REAL_TRAFFIC_TEST_SEEDS))
    p.add_argument("--synthetic-episodes", type=int, default=len(HELD_OUT_SEEDS))
    p.add_argument("--out", type=Path, default=ROOT / "results")
    p.add_argument("--no-slow", dest="slow", action="store_false", help="skip the x0.2 bank")
    p.add_argument(
        "--prediction",
        default="enclosing",
        help="comma-separated prediction fits to run: enclosing (real_traffic_eval.*) and/or "
        "calibrated (real_traffic_eval_calibrated.*)",
    )
    args = p.parse_args(argv)
    if not 1 <= args.episodes <= len(REAL_TRAFFIC_TEST_SEEDS):
        p.error(f"argument --episodes: must be in [1, {len(REAL_TRAFFIC_TEST_SEEDS)}]")
    if not 0 <= args.synthetic_episodes <= len(HELD_OUT_SEEDS):
        p.error(f"argument --synthetic-episodes: must be in [0, {len(HELD_OUT_SEEDS)}]")
    if args.workers < 1:
        p.error(f"argument --workers: must be >= 1, got {args.workers}")

    fits = tuple(f for f in args.prediction.split(",") if f)
    bad = [f for f in fits if f not in PREDICTIONS]
    if bad or not fits:
        p.error(f"argument --prediction: {bad or fits!r}; use a comma-separated subset of "
                f"{list(PREDICTIONS)}")  # fmt: skip

    policies = registry_controllers()
    real_seeds = list(REAL_TRAFFIC_TEST_SEEDS)[: args.episodes]
    syn_seeds = list(HELD_OUT_SEEDS)[: args.synthetic_episodes]
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
    args.out.mkdir(parents=True, exist_ok=True)
    text = ""
    enc: dict[str, Any]
    if "enclosing" in fits:
        enc, t_real, t_all = run_banks(policies, "enclosing", real_seeds, syn_seeds, args.slow,
                                       args.workers)  # fmt: skip
        real, slow, synthetic = enc["real"], enc["slow"], enc["synthetic"]
        assert real is not None
        text = enclosing_page(real, slow, synthetic, classes, real_what, syn_what, t_real,
                              t_all, args.workers)  # fmt: skip
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
    else:  # beside the enclosing figures of the results file
        enc = stored_enclosing(args.out / "real_traffic_eval.json.gz")
    if "calibrated" in fits:
        cal, c_real, c_all = run_banks(policies, "calibrated", real_seeds, syn_seeds, args.slow,
                                       args.workers)  # fmt: skip
        run_line = (
            f"Run time: {c_real:.0f} s for the real-traffic bank with the calibrated prediction, "
            f"{c_all:.0f} s for its three banks (`python baselines/real_traffic_eval.py "
            f"{' '.join(sys.argv[1:] if argv is None else argv)}`, 2 shared cores, under load)."
        )
        page = calibrated_page(enc, cal, classes, real_what, syn_what, run_line)
        atomic_write(args.out / "real_traffic_eval_calibrated.md", page.encode("utf-8"))
        write_json(
            {"meta": {"run_time_s": c_all, "real_traffic_s": c_real,
                      "bank": with_fit(REAL_TRAFFIC_BANK, "calibrated")},
             "real_traffic": cal["real"],
             **({"real_traffic_slow": cal["slow"]} if cal["slow"] else {}),
             **({"random": cal["synthetic"]} if cal["synthetic"] else {})},
            args.out / "real_traffic_eval_calibrated.json.gz",
        )  # fmt: skip
        text += page
    print(text)
    return text


def enclosing_page(
    real: EvaluationResult,
    slow: EvaluationResult | None,
    synthetic: EvaluationResult | None,
    classes: dict[int, tuple[str, str, float]],
    real_what: str,
    syn_what: str,
    t_real: float,
    t_all: float,
    workers: int,
) -> str:
    """The enclosing runs' page (``real_traffic_eval.md``)."""
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
        f"(`python baselines/real_traffic_eval.py --workers {workers}`, 2 shared cores)."
    )
    return "\n\n".join(sections) + "\n"


if __name__ == "__main__":
    main()
