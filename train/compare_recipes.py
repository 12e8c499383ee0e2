"""Recipes side by side at equal wall time: MAPPO against the shared-parameter PPO.

    python train/compare_recipes.py runs/seeds_shared runs/seeds_mappo \
        --out baselines/results/mappo_vs_shared

Each argument is a ``train/seeds.py`` output folder (``seeds.json`` and the seeds'
``progress.csv``). Writes ``OUT.md``: per recipe the seeds' training (agent-steps and wall
minutes, mean and range), the held-out figures across seeds (IQM with its stratified
bootstrap interval, from ``seeds.json``), and ``OUT.png``: every seed's learning curves against
wall time, one colour per recipe, so equal budgets compare at equal minutes, not at equal
agent-steps (MAPPO's update is cheaper: it takes more steps per minute). Existing outputs are
refused unless ``--force``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import seeds as seeds_driver  # noqa: E402

from uasep_env.runtime.atomic import atomic_output, atomic_write  # noqa: E402
from uasep_env.runtime.tables import render_table  # noqa: E402


def load_run(folder: Path) -> dict[str, Any]:
    """A seeds folder's report, checked to be one.

    Raises:
        ValueError: No ``seeds.json`` there, or one without the report's fields (named).
    """
    path = folder / "seeds.json"
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: not found (run train/seeds.py into {folder} first)") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err})") from None
    for key in ("recipe", "seeds", "across_seeds", "training", "held_out_seeds"):
        if key not in data:
            raise ValueError(f"{path}: no {key!r}: not a train/seeds.py report")
    if not any(f.get("wall_s") for f in data["training"].values()):
        raise ValueError(f"{path}: no seed's training facts (wall_s): did its seeds train?")
    return data


def budget_minutes(folder: Path, data: dict[str, Any]) -> float | None:
    """The ``--max-minutes`` every seed of a run trained with (None when unrecorded).

    Raises:
        ValueError: The seeds of one run had different budgets (named).
    """
    from uasep_env.policies import load_policy

    budgets = {}
    for k in range(int(data["seeds"])):
        path = seeds_driver.seed_dir(folder, k) / "policy.zip"
        if path.exists():
            args = load_policy(path).meta.info.get("args") or {}
            if "max_minutes" in args:
                budgets[k] = float(args["max_minutes"])
    if len(set(budgets.values())) > 1:
        raise ValueError(f"{folder}: its seeds trained with different --max-minutes {budgets}")
    return next(iter(budgets.values()), None)


def table(runs: list[tuple[Path, dict[str, Any]]]) -> str:
    """One row per recipe: training budget used, and the held-out figures across seeds."""
    headers = ["recipe", "seeds", "agent-steps per seed", "train (min)"]
    headers += [label for _, label, _ in seeds_driver.METRICS]
    rows = []
    for _, data in runs:
        facts = [f for f in data["training"].values() if f]
        steps = np.array([f.get("agent_steps", np.nan) for f in facts], float)
        wall = np.array([f.get("wall_s", np.nan) for f in facts], float) / 60.0
        row = [
            data["recipe"],
            str(data["seeds"]),
            f"{np.mean(steps) / 1e6:.1f}M ({np.min(steps) / 1e6:.1f}-{np.max(steps) / 1e6:.1f}M)",
            f"{np.mean(wall):.1f} ({np.min(wall):.1f}-{np.max(wall):.1f})",
        ]
        for key, _, kind in seeds_driver.METRICS:
            row.append(seeds_driver.iqm_cell(data["across_seeds"][key], kind))
        rows.append(row)
    return render_table(headers, rows, align=["left"] + ["right"] * (len(headers) - 1),
                        markdown=True)  # fmt: skip


def plot(runs: list[tuple[Path, dict[str, Any]]], path: Path) -> None:
    """Every seed's curves against wall time (minutes), one colour per recipe."""
    from matplotlib.figure import Figure  # lazily: only the figure needs matplotlib

    fig = Figure(figsize=(12, 7), layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    names = ("return (mean per agent)", "collision rate", "loss-of-separation rate",
             "max deviation (m)")  # fmt: skip
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    for i, (folder, data) in enumerate(runs):
        for k in range(int(data["seeds"])):
            csv_path = seeds_driver.seed_dir(folder, k) / "progress.csv"
            if not csv_path.exists():
                continue
            c = seeds_driver.read_curve(csv_path)
            minutes = _wall_minutes(csv_path)
            for ax, col in zip(axes, seeds_driver.CURVE_COLUMNS, strict=True):
                ax.plot(minutes, c[col], color=colours[i % len(colours)], lw=1, alpha=0.8,
                        label=data["recipe"] if k == 0 else None)  # fmt: skip
    for ax, name in zip(axes, names, strict=True):
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("wall time (min)", fontsize=8)
    axes[0].legend(fontsize=8)
    fig.suptitle("every seed of each recipe against wall time (last 200 episodes of each)")
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=80, facecolor="white")


def _wall_minutes(path: Path) -> np.ndarray:
    import csv

    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    try:
        return np.array([float(r["wall_s"]) / 60.0 for r in rows])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{path}: every row needs a numeric wall_s") from None


def build_parser() -> argparse.ArgumentParser:
    """This script's flags (a bad value is one line naming the flag)."""
    from uasep_env.training.args import HelpFormatter, OneLineParser

    p = OneLineParser(description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("runs", type=Path, nargs="+", help="train/seeds.py output folders")
    p.add_argument("--out", type=Path, required=True, help="writes OUT.md and OUT.png")
    p.add_argument("--force", action="store_true", help="replace existing outputs")
    p.add_argument("--no-figure", action="store_true", help="write the table only")
    return p


def main(argv: list[str] | None = None) -> str:
    """Write the comparison; return its markdown."""
    import shlex

    argv = list(sys.argv[1:] if argv is None else argv)
    p = build_parser()
    args = p.parse_args(argv)
    md, png = args.out.with_suffix(".md"), args.out.with_suffix(".png")
    for q in (md, png):
        if q.exists() and not args.force:
            p.error(f"--out: {q} exists (pass --force to replace it)")
    try:
        runs = [(folder, load_run(folder)) for folder in args.runs]
    except ValueError as err:
        p.error(str(err))
    try:
        budgets = {d["recipe"]: budget_minutes(folder, d) for folder, d in runs}
    except ValueError as err:
        p.error(str(err))
    known = {b for b in budgets.values() if b is not None}
    if len(known) > 1:
        p.error(f"the recipes trained with different --max-minutes: {budgets}")
    longest = {
        d["recipe"]: max(f.get("wall_s") or 0.0 for f in d["training"].values()) / 60
        for _, d in runs
    }
    held = {json.dumps(d["held_out_seeds"], sort_keys=True) for _, d in runs}
    if len(held) != 1:
        p.error("the runs were evaluated on different held-out encounters: "
                + "; ".join(sorted(held)))  # fmt: skip
    (bank,) = (d["held_out_seeds"] for _, d in runs[:1])
    text = "\n".join(
        [
            "# Recipes at equal wall time",
            "",
            f"Made by `python train/compare_recipes.py {shlex.join(argv)}`. Every seed "
            "trained with the same wall-clock budget (`--max-minutes` "
            f"{', '.join(sorted(f'{b:g}' for b in known)) or 'not recorded'}; longest run: "
            + ", ".join(f"{r} {m:.1f} min" for r, m in longest.items())
            + "); each seed's checkpoint chosen on validation "
            f"encounters only; {bank['count']} held-out encounters (seeds {bank['first']:,}+). "
            "Across seeds: interquartile mean of the per-family scores with a 95 % stratified "
            "bootstrap interval (`train/seeds.py`). Learning curves against wall time: "
            f"`{png.name}`.",
            "",
            table(runs),
            "",
        ]
    )
    atomic_write(md, text)
    if not args.no_figure:
        try:
            plot(runs, png)
        except ValueError as err:
            p.error(str(err))
    print(text)
    return text


if __name__ == "__main__":
    main()
