"""Safety against efficiency for every controller: each one's gain sweep and Pareto front.

    uasep-tradeoff [--workers 2] [--paper-episodes 20] [--bank-episodes 200] [--out tradeoff]
    uasep-tradeoff --methods apf --paper-episodes 2 --bank-episodes 2 --no-figures  # a quick look

A single setting per controller says little: at their defaults the controllers keep
different distances from the obstacle. Here each controller's safety margin is swept over a
grid (:data:`METHODS`), every setting plays the same encounters (the paper experiment's
``paper`` scenario, seeds 0-19, and the 200-encounter ``random`` bank, seeds
4000500-4000699 of the validation range), and efficiency (max deviation, longest conflict
resolution, acceleration fluctuation) is plotted against safety (min UAV-obstacle distance,
loss-of-separation rate, collision rate), with 95 % intervals (Student-t for means, Wilson
for rates) and each method's Pareto front.

The knobs (``scale`` multiplies the gains that set the margin in the reference gains,
:class:`~uasep_env.policies.apf.APFGains`'s field defaults; each method's own default, its
``default_gains``, is the knee of its front on the bank, see :func:`knee`):

* ``apf`` -- the proposed APF with the enclosing prediction (the default):
  ``obstacle_safe_min`` and ``obstacle_time`` (``r_safe = r_min + K v cos delta``, eq. 24);
* ``apf-published`` -- the same gains with the paper's prediction as published
  (:data:`uasep_env.config.AS_PUBLISHED`: terminal set, eqs. 17-18 ellipsoid);
* ``motion-state-apf`` -- ``obstacle_safe_min`` and ``obstacle_time`` (its sphere's safe distance);
* ``traditional-apf`` -- ``traditional_range`` (Khatib's influence distance ``rho_0``);
* ``ppo-residual`` -- the shipped residual policy on the APF whose ``obstacle_safe_min`` and
  ``obstacle_time`` are scaled (its correction was trained on the default base);
* ``ppo-shared`` -- the shipped pure policy has no gain; what sets its margin is the region it
  observes, so the prediction horizon is swept (trained at 10 s; other horizons are outside
  its training distribution);
* ``mappo`` -- the shipped MAPPO actor, swept the same way;
* every other registered reference controller (:data:`uasep_env.policies.REGISTRY`: ``mvp``,
  ``mvp-region``, ``orca``, ...) -- its own ``margin_scale`` (the radii of its protected
  zones), from its registry entry (:func:`registry_methods`): a new controller is swept
  with no edit here.

Writes ``OUT/tradeoff.csv`` (one row per method, setting and scenario: every statistic with
its interval), ``OUT/tradeoff_{paper,bank}.png`` (matplotlib, the ``viz`` extra; not with
``--no-figures``) and ``OUT/tradeoff.md`` (the tables the README quotes, from :func:`report`);
``--out`` defaults to ``tradeoff/`` in the current folder (in a clone,
``python baselines/tradeoff.py`` writes the repository's ``docs/figures/``). Resumable: rows
already in the CSV are kept, and only missing settings run (delete the CSV, or pass
``--fresh``, to start over). The CSV is rewritten atomically after every evaluation call, so a
kill or a full disk never loses finished rows (a torn last row, from a file cut short some
other way, is dropped and that setting runs again); a CSV holding rows of other episode counts
is refused rather than mixed into the tables. The motion-state and traditional APFs do not
read the prediction, so their rows hold for both fits.
"""

from __future__ import annotations

import argparse
import importlib.util
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env import make_config

# The sweep's table and the front's rules are shared with uasep-bench; importable from here.
from uasep_env.benchmark.front import interpolate_at, knee, knee_distances, pareto  # noqa: F401
from uasep_env.benchmark.methods import (  # noqa: F401
    HORIZONS_S,
    METHODS,
    SCALES,
    Method,
    _scaled,
    registry_methods,
)
from uasep_env.benchmark.sweep_rows import check_counts as _check_counts
from uasep_env.benchmark.sweep_rows import read_rows as _read
from uasep_env.benchmark.sweep_rows import write_rows as _write
from uasep_env.config.checks import check_positive_int
from uasep_env.evaluation import PolicyResult, evaluate
from uasep_env.metrics import t_interval
from uasep_env.policies import APF  # noqa: F401
from uasep_env.runtime.atomic import atomic_output, atomic_write
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios.seeds import VALIDATION_SEEDS

#: Where ``uasep-tradeoff`` writes by default: a folder in the current directory (the
#: repository's script, ``baselines/tradeoff.py``, passes ``docs/figures``).
DEFAULT_OUT = Path("tradeoff")
#: The paper experiment's encounters (``baselines/paper_experiment.py``).
PAPER_SEEDS = range(0, 20)
#: The trade-off bank: 200 ``random`` encounters of the validation range, past the first 500
#: that checkpoint selection reads (never the held-out bank: the knees set the defaults).
BANK_FIRST_SEED = VALIDATION_SEEDS.start + 500
#: (column, dotted episode metric or derived name, statistic, axis label, higher is safer)
SAFETY = (
    (
        "min_obstacle_distance",
        "min_obstacle_distance",
        "mean",
        "min UAV-obstacle distance (m)",
    ),
    ("loss_of_separation", "loss_of_separation", "rate", "loss-of-separation rate"),
    ("collision", "collision", "rate", "collision rate"),
)
EFFICIENCY = (
    ("max_deviation", "max_deviation", "mean", "max deviation from plan (m)"),
    (
        "conflict_duration",
        "max_conflict_duration",
        "mean",
        "longest conflict resolution (s)",
    ),
    ("acc_fluctuation", "acc_fluctuation", "mean", "max acceleration std (m/s²)"),
)
#: Per-axis deviation of the middle UAV (the paper's UAV3: which axis it resolves in).
AXES = (("uav2_dev_north", "x"), ("uav2_dev_east", "y"), ("uav2_dev_down", "z"))


def _row_stats(res: PolicyResult) -> dict[str, float]:
    """Every statistic of one setting, with intervals: the evaluation's own aggregate.

    Only the acceleration fluctuation (the largest of the three axes' stds, per episode) is
    not an aggregated metric; its mean and interval follow :func:`~uasep_env.metrics.aggregate`.
    """
    agg = dict(res.aggregate)
    fluct = np.array([max(e.metrics.episode.max_acc_std) for e in res.episodes], float)
    fluct = fluct[np.isfinite(fluct)]
    lo, hi = t_interval(fluct)
    agg["episode.acc_fluctuation"] = {
        "mean": float(fluct.mean()) if fluct.size else float("nan"), "ci_low": lo, "ci_high": hi
    }  # fmt: skip
    out: dict[str, float] = {"n": float(len(res.episodes))}
    for col, key, stat, _ in SAFETY + EFFICIENCY:
        s = agg[f"episode.{key}"]
        out[col], out[f"{col}_lo"], out[f"{col}_hi"] = s[stat], s["ci_low"], s["ci_high"]
    for col, ax in AXES:
        out[col] = agg[f"uav.uav_2.deviation.max_abs.{ax}"]["mean"]
    return out


def _datasets(paper_n: int, bank_n: int) -> dict[str, tuple[str, range]]:
    return {
        "paper": ("paper", range(PAPER_SEEDS.start, PAPER_SEEDS.start + paper_n)),
        "bank": ("random", range(BANK_FIRST_SEED, BANK_FIRST_SEED + bank_n)),
    }


def run(
    methods: Sequence[Method],
    paper_n: int,
    bank_n: int,
    workers: int,
    csv_path: Path,
    fresh: bool = False,
) -> list[dict[str, Any]]:
    """Evaluate every missing (method, setting, dataset) and return all rows of the CSV."""
    rows = [] if fresh else _read(csv_path)
    sets = _datasets(paper_n, bank_n)
    _check_counts(csv_path, rows, sets)
    done = {(r["method"], r["value"], r["dataset"], r["n"]) for r in rows}
    for m in methods:
        for ds, (scenario, seeds) in sets.items():
            todo = [v for v in m.values if (m.name, float(v), ds, float(len(seeds))) not in done]
            if not todo:
                continue
            # Settings that share an environment config run in one call (one set of chunks).
            by_config: dict[str, list[float]] = {}
            for v in todo:
                by_config.setdefault(repr(m.config(v)), []).append(v)
            for values in by_config.values():
                cfg = make_config(m.config(values[0]), scenario=scenario)
                policies = {f"{m.name}@{v:g}": m.policy(cfg, v) for v in values}
                result = evaluate(policies, cfg, seeds, workers=workers)
                for v in values:
                    stats = _row_stats(result.results[f"{m.name}@{v:g}"])
                    rows.append(
                        {
                            "method": m.name,
                            "knob": m.knob,
                            "value": float(v),
                            "dataset": ds,
                            **stats,
                        }
                    )
                    print(
                        f"{m.name:18s} {m.knob} = {v:<5g} {ds:5s} "
                        + " ".join(f"{c}={stats[c]:.3g}" for c, *_ in SAFETY + EFFICIENCY)
                    )
                _write(csv_path, rows)  # after every call: an interrupted run resumes here
    return rows


def plot(rows: list[dict[str, Any]], dataset: str, path: Path, title: str) -> None:
    """A 3 x 3 grid: efficiency (rows) against safety (columns), one curve per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 3, figsize=(15, 13), constrained_layout=True)
    colours = plt.get_cmap("tab10")
    for mi, m in enumerate(METHODS):
        rs = sorted(
            (r for r in rows if r["method"] == m.name and r["dataset"] == dataset),
            key=lambda r: r["value"],
        )
        if not rs:
            continue
        for i, (ecol, _k, _s, elabel) in enumerate(EFFICIENCY):
            for j, (scol, _k2, _s2, slabel) in enumerate(SAFETY):
                ax = axes[i, j]
                x = np.array([r[scol] for r in rs])
                y = np.array([r[ecol] for r in rs])
                xe = np.abs(np.array([[r[f"{scol}_lo"], r[f"{scol}_hi"]] for r in rs]).T - x)
                ye = np.abs(np.array([[r[f"{ecol}_lo"], r[f"{ecol}_hi"]] for r in rs]).T - y)
                front = pareto(x, y, scol == "min_obstacle_distance")
                col = colours(mi)
                ax.errorbar(
                    x,
                    y,
                    xerr=np.nan_to_num(xe),
                    yerr=np.nan_to_num(ye),
                    color=col,
                    alpha=0.35,
                    fmt="none",
                    lw=0.8,
                )
                ax.plot(x, y, "-", color=col, lw=0.8, alpha=0.6)
                ax.plot(
                    x[front],
                    y[front],
                    "o",
                    color=col,
                    ms=5,
                    label=m.label if (i, j) == (0, 0) else None,
                )
                ax.plot(x[~front], y[~front], "o", mfc="none", color=col, ms=5)
                default = [k for k, r in enumerate(rs) if r["value"] == m.default]
                ax.plot(x[default], y[default], "*", color=col, ms=11, mec="k", mew=0.5)
                ax.set_xlabel(slabel)
                ax.set_ylabel(elabel)
                ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.suptitle(
        f"{title}: each controller's safety margin swept (filled = its Pareto front, "
        "star = default setting, bars = 95 % intervals)"
    )
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


#: Common min UAV-obstacle distances (m) at which the fronts are compared, per scenario.
LEVELS_M = {"paper": (12.0, 13.0, 15.0, 17.0), "bank": (13.0, 20.0, 30.0)}


def _method_rows(rows: list[dict[str, Any]], name: str, dataset: str) -> list[dict[str, Any]]:
    return sorted(
        (r for r in rows if r["method"] == name and r["dataset"] == dataset),
        key=lambda r: r["value"],
    )


def at_distance(rs: list[dict[str, Any]], level: float, col: str) -> float | None:
    """``col`` interpolated along a front at a min obstacle distance (None: out of reach)."""
    return interpolate_at(rs, level, "min_obstacle_distance", col)


def _num(x: float) -> str:
    return f"{x:.1f}" if np.isfinite(x) else "-"  # nan: no UAV ever left the plan


def _table(headers: Sequence[str], rows: list[list[str]]) -> list[str]:
    return render_table(headers, rows, markdown=True).splitlines()


def report(rows: list[dict[str, Any]]) -> str:
    """The markdown summary the README quotes: defaults, equal-safety costs, resolution axes."""
    present = [m for m in METHODS if _method_rows(rows, m.name, "bank")]
    out = ["## Defaults: the knee of each front (bank)", ""]
    out += _table(
        ["method", "knob", "knee", "default"],
        [
            [m.label, m.knob, f"{knee(_method_rows(rows, m.name, 'bank'))['value']:g}",
             f"{m.default:g}"]
            for m in present
        ],
    )  # fmt: skip
    for ds, title in (("paper", "Paper scenario"), ("bank", "Random encounter bank")):
        levels = LEVELS_M[ds]
        out += [
            "", f"## {title}: cost at equal min UAV-obstacle distance", "",
            "max deviation (m) / longest conflict resolution (s), interpolated along each "
            "front; - where the method's sweep does not reach that distance", "",
        ]  # fmt: skip
        table = []
        for m in present:
            rs = _method_rows(rows, m.name, ds)
            d = [r["min_obstacle_distance"] for r in rs]
            cells = [m.label, f"{min(d):.1f}-{max(d):.1f}"]
            for v in levels:
                dev = at_distance(rs, v, "max_deviation")
                dur = at_distance(rs, v, "conflict_duration")
                cells.append("-" if dev is None else f"{dev:.1f} / {_num(dur or np.nan)}")
            table.append(cells)
        out += _table(["method", "reaches (m)", *(f"at {v:g} m" for v in levels)], table)
        out += [
            "",
            f"## {title}: the safest loss-of-separation rate each reaches, and its cost",
            "",
        ]
        table = []
        for m in present:
            rs = _method_rows(rows, m.name, ds)
            best = min(r["loss_of_separation"] for r in rs)
            r = min((r for r in rs if r["loss_of_separation"] == best),
                    key=lambda r: r["max_deviation"])  # fmt: skip
            table.append([
                m.label, f"{best:.1%}", f"{m.knob} {r['value']:g}", f"{r['collision']:.1%}",
                f"{r['min_obstacle_distance']:.1f}", f"{r['max_deviation']:.1f}",
                _num(r["conflict_duration"]),
            ])  # fmt: skip
        out += _table(
            ["method", "lowest rate", "setting", "collisions", "min distance (m)",
             "max deviation (m)", "conflict resolution (s)"],
            table,
        )  # fmt: skip
    out += [
        "", "## Paper scenario: the middle UAV's largest deviation by axis (m)", "",
        "mean over the 20 seeds of uav_2's largest deviation from its plan along each axis; "
        "the plan flies north, so north is along the track, east lateral, down vertical", "",
    ]  # fmt: skip
    table = []
    for m in present:
        rs = _method_rows(rows, m.name, "paper")
        safe = [r for r in rs if r["loss_of_separation"] == 0.0]
        picks = [r for r in rs if r["value"] == m.default]
        if safe and safe[0]["value"] != m.default:
            picks.append(safe[0])
        for r in picks:
            tag = "default" if r["value"] == m.default else "least margin without LoS"
            table.append([
                m.label, f"{m.knob} {r['value']:g} ({tag})", f"{r['uav2_dev_north']:.1f}",
                f"{r['uav2_dev_east']:.1f}", f"{r['uav2_dev_down']:.1f}",
            ])  # fmt: skip
    out += _table(["method", "setting", "along track", "lateral", "vertical"], table)
    return "\n".join(out) + "\n"


def positive_int(text: str) -> int:
    """An argparse type: a positive integer (argparse names the flag and the bad value)."""
    return check_positive_int("value", int(text))


def main(
    argv: Sequence[str] | None = None, default_out: Path = DEFAULT_OUT, prog: str | None = None
) -> None:
    """Run the sweep (resuming), then write the CSV, the tables and the figures.

    Args:
        argv: Arguments (without the program name); ``sys.argv[1:]`` when None.
        default_out: ``--out``'s default.
        prog: The program's name in the help and errors (``uasep-tradeoff``).
    """
    p = argparse.ArgumentParser(
        prog=prog or "uasep-tradeoff",
        description=__doc__,
        formatter_class=argparse.RawTextHelpFormatter,
    )
    p.add_argument("--workers", type=positive_int, default=2)
    p.add_argument("--paper-episodes", type=positive_int, default=len(PAPER_SEEDS))
    p.add_argument("--bank-episodes", type=positive_int, default=200)
    p.add_argument(
        "--methods",
        default=",".join(m.name for m in METHODS),
        help="comma-separated subset of: " + ", ".join(m.name for m in METHODS),
    )
    p.add_argument(
        "--out",
        type=Path,
        default=default_out,
        help=f"folder of the CSV, the tables and the figures (default: {default_out})",
    )
    p.add_argument("--fresh", action="store_true", help="ignore the rows already in the CSV")
    p.add_argument(
        "--no-figures", action="store_true", help="no PNG figures (they need matplotlib)"
    )
    args = p.parse_args(argv)
    if not args.no_figures and importlib.util.find_spec("matplotlib") is None:
        # Before hours of episodes, not after them.
        p.error('the figures need matplotlib: pip install "uasep-env[viz]", or pass --no-figures')
    known = {m.name: m for m in METHODS}
    names = [n.strip() for n in args.methods.split(",") if n.strip()]
    bad = [n for n in names if n not in known]
    if bad:
        p.error(f"unknown method(s) {', '.join(bad)}; choose from {', '.join(known)}")
    csv_path = args.out / "tradeoff.csv"
    rows = run(
        [known[n] for n in names],
        args.paper_episodes,
        args.bank_episodes,
        args.workers,
        csv_path,
        args.fresh,
    )
    if not args.no_figures:
        _plot_both(rows, args.paper_episodes, args.bank_episodes, args.out)
    text = report(rows)
    atomic_write(args.out / "tradeoff.md", text)
    print(text)


def _plot_both(rows: list[dict[str, Any]], paper_n: int, bank_n: int, out: Path) -> None:
    plot(
        rows,
        "paper",
        out / "tradeoff_paper.png",
        f"Paper scenario ({paper_n} seeds)",
    )
    plot(
        rows,
        "bank",
        out / "tradeoff_bank.png",
        f"Random encounter bank ({bank_n} encounters)",
    )


if __name__ == "__main__":
    main()
