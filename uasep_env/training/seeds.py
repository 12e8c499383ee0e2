"""Train a recipe over several training seeds, select on validation, report across seeds.

    uasep-seeds --recipe residual_apf --seeds 3 --parallel 2 --out-dir runs/seeds_residual
    uasep-seeds --recipe shared --seeds 3 --parallel 2 --out-dir runs/seeds_shared
    uasep-seeds --recipe mappo --seeds 3 --parallel 2 --out-dir runs/seeds_mappo
    uasep-seeds --recipe shared --seeds 2 --out-dir /tmp/s -- --max-minutes 1
    uasep-seeds --from-json runs/seeds_mappo/seeds.json

The same command again resumes: finished seeds are kept, interrupted ones continue from
their ``checkpoints/latest``; flags after ``--`` go to the recipe unchanged. ``--from-json``
writes a report again from its stored figures (no training, no episode; the verdicts are
judged again): its ``.md`` and the JSON's targets.
(In a clone, ``python train/seeds.py`` is the same driver, recorded as such in its reports.)
The recipes need the ``train`` extra (install ``torch==2.13.0`` first), ``mappo*`` also skrl.

Stages (each skipped when its output exists, so an interrupted run picks up where it was):

1. **train**: seed ``k`` (0 .. ``--seeds``-1) runs ``uasep-train <recipe> --seed 1000*k
   --out-dir <out>/seed_<k>`` (its environments are seeded ``1000*k + e``, inside
   :data:`~uasep_env.scenarios.TRAINING_SEEDS` and disjoint between runs), up to
   ``--parallel`` side by side, each with one torch thread. A run with a
   ``checkpoints/latest`` but no final ``policy.zip`` is resumed (``--resume``).
2. **select**: :mod:`uasep_env.training.selection` picks each seed's checkpoint on the first
   ``--select-episodes`` validation encounters only
   (:data:`~uasep_env.scenarios.VALIDATION_SEEDS`) and copies it to
   ``<out>/seed_<k>/selected.zip``. Then the same rule, on the same validation figures,
   picks the seed whose checkpoint ships (``--ship-to`` copies it).
3. **held-out**: every selected checkpoint and the APF play the first ``--episodes``
   encounters of the held-out bank (:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`).
4. **report**: ``<out>/seeds.md`` and ``seeds.json``: every seed's figures (rates with Wilson
   intervals, means with Student-t intervals), and across seeds the interquartile mean with
   a 95 % stratified bootstrap interval (runs resampled within each scenario family, as
   ``rliable`` does; :func:`uasep_env.metrics.statistics.stratified_bootstrap_iqm`), the
   targets (met / not met / not shown, from these numbers: a rate held to the APF's by
   :func:`uasep_env.metrics.statistics.rate_verdict`) and ``curves.png``, the learning
   curves of all seeds in one figure; ``--publish PREFIX`` copies them (and the scaling tables) to
   ``PREFIX.md`` etc. for the repository. ``--scaling-episodes N`` adds
   ``uasep-report`` (:mod:`uasep_env.reporting.scaling`) over the selected checkpoints
   (``<out>/scaling.*``, kept when it exists). ``seeds.json`` records the recipe's options
   (``recipe_args``, from seed 0's selected checkpoint), with which ``train/reproduce.py``
   (in a clone) retrains a chosen checkpoint.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.metrics.statistics import (
    MET,
    NOT_MET,
    NOT_SHOWN,
    VERDICT_LEGEND,
    episodes_behind,
    limit_verdict,
    rate_verdict,
    weakest_verdict,
)
from uasep_env.runtime.atomic import atomic_output, atomic_write
from uasep_env.runtime.runlock import RunFolderBusy, claim_run_folder
from uasep_env.training import selection as select_checkpoint
from uasep_env.training.args import HelpFormatter, OneLineParser, non_negative_int, positive_int

#: The folder that holds the imported ``uasep_env`` (a checkout, or site-packages): the
#: recipes' subprocesses import the same code as this driver.
ROOT = Path(__file__).resolve().parents[2]
#: This driver's recipe names -> ``uasep-train``'s (:data:`uasep_env.training.RECIPES`).
RECIPES = {
    "shared": "ppo_shared",
    "residual_apf": "ppo_residual_apf",
    "mappo": "mappo",
    "lagrangian": "ppo_lagrangian",
    "lagrangian_residual": "ppo_lagrangian_residual",
    "mappo_lagrangian": "mappo_lagrangian",
}
#: Recipes whose targets are the APF's safety (and, for the constrained ones, its formation).
AS_SAFE_AS_APF = ("residual_apf", "lagrangian", "lagrangian_residual", "mappo_lagrangian")
#: Training seed of run ``k`` is ``SEED_STRIDE * k`` (its environments ``+ e``, e < stride).
SEED_STRIDE = 1000
#: Most training seeds a driver runs (seed k trains on SEED_STRIDE * k + e).
MAX_SEEDS = 100
#: (dotted aggregate key, label, kind) reported per seed and across seeds.
METRICS = (
    ("episode.collision", "collisions", "rate"),
    ("episode.loss_of_separation", "loss of separation", "rate"),
    ("episode.terminated", "early ends", "rate"),
    ("episode.max_deviation", "max deviation (m)", "mean"),
    ("episode.min_obstacle_distance", "min UAV-obstacle distance (m)", "mean"),
)
CURVE_COLUMNS = ("return_mean", "collision_rate", "loss_of_separation_rate", "max_deviation_mean")


def _python() -> list[str]:
    return [sys.executable]


def recipe_env() -> dict[str, str]:
    """The environment a recipe runs in: this driver's package on the path, one OpenMP thread."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def seed_dir(out: Path, k: int) -> Path:
    """The run folder of seed ``k``."""
    return out / f"seed_{k}"


def train_command(recipe: str, out: Path, k: int, extra: list[str]) -> list[str] | None:
    """The command that trains (or resumes) seed ``k``; None when it has finished."""
    run = seed_dir(out, k)
    if (run / "policy.zip").exists() and (run / "validation.json").exists():
        return None
    cmd = [
        *_python(),
        "-m",
        "uasep_env.training",  # uasep-train, with the interpreter that runs this driver
        RECIPES[recipe],
        "--out-dir",
        str(run),
        "--seed",
        str(SEED_STRIDE * k),
        "--torch-threads",
        "1",
        "--no-progress",
        *extra,
    ]
    latest = run / "checkpoints" / "latest"
    if latest.exists():
        cmd += ["--resume", str(latest)]
    elif run.exists():  # an attempt that left nothing to resume from: keep it aside
        run.rename(run.with_name(f"{run.name}.aborted-{time.strftime('%Y%m%d-%H%M%S')}"))
    return cmd


def train_all(recipe: str, out: Path, seeds: int, parallel: int, extra: list[str]) -> None:
    """Stage 1: train every seed, ``parallel`` at a time; raise if one fails."""
    pending = [(k, cmd) for k in range(seeds) if (cmd := train_command(recipe, out, k, extra))]
    running: list[tuple[int, subprocess.Popen, Any]] = []
    failed: list[int] = []
    while pending or running:
        while pending and len(running) < parallel:
            k, cmd = pending.pop(0)
            # The log lies beside the run folder: a recipe refuses a used --out-dir.
            log = (out / f"seed_{k}.log").open("a")
            print(f"seed {k}: {' '.join(cmd[1:])}", flush=True)
            # The seeds side by side share the cores: each recipe's kernels take its share.
            env = dict(recipe_env(), UASEP_WORKERS=str(parallel))
            proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env)
            running.append((k, proc, log))
        time.sleep(1.0)
        for item in list(running):
            k, proc, log = item
            if proc.poll() is not None:
                log.close()
                running.remove(item)
                print(f"seed {k}: finished (exit {proc.returncode})", flush=True)
                if proc.returncode != 0:
                    failed.append(k)
    if failed:
        raise SystemExit(f"training failed for seeds {failed}: see {out}/seed_<k>.log")


def select_all(out: Path, seeds: int, episodes: int, workers: int) -> list[Path]:
    """Stage 2: each seed's checkpoint chosen on validation encounters only."""
    chosen = []
    for k in range(seeds):
        run = seed_dir(out, k)
        target = run / "selected.zip"
        if not target.exists():
            select_checkpoint.main(
                [
                    str(run),
                    "--episodes",
                    str(episodes),
                    "--workers",
                    str(workers),
                    "--copy-to",
                    str(target),
                ]
            )
        chosen.append(target)
    return chosen


def ship(out: Path, seeds: int) -> dict[str, Any]:
    """Stage 2b: the seed whose selected checkpoint ships, chosen on validation only.

    Every seed's selection played the same validation encounters, so their chosen rows
    compare directly; the same rule as within a run (``select_checkpoint.choose``) picks
    one across seeds.

    Raises:
        ValueError: The seeds' selections did not play the same validation encounters
            (their APF figures differ).
    """
    picks, apf = [], None
    for k in range(seeds):
        rows, apf_k = select_checkpoint.read_selection(seed_dir(out, k))
        if apf is not None and apf_k != apf:
            raise ValueError(
                f"seed {k}: its selection's APF figures {apf_k} differ from seed 0's {apf}: "
                "the seeds were not selected on the same validation encounters"
            )
        apf = apf_k
        pick = select_checkpoint.choose(rows, apf_k)
        # Named from the run folder: results files name no machine's folder.
        where = Path(pick["policy"])
        run = seed_dir(out, k)
        if where.is_relative_to(run):
            where = where.relative_to(run.parent)
        picks.append({"seed": k, **pick, "policy": where.as_posix()})
    best = select_checkpoint.choose(picks, apf)
    return {"seed": best["seed"], "validation": {"apf": apf, "seeds": picks}}


def held_out(chosen: list[Path], episodes: int, workers: int) -> Any:
    """Stage 3: the selected checkpoints and the APF on the held-out bank."""
    from uasep_env import make_config
    from uasep_env.evaluation import evaluate
    from uasep_env.scenarios import HELD_OUT_SEEDS

    cfg = make_config(scenario="random")
    policies: dict[str, Any] = {"apf": "apf"}
    policies |= {f"seed_{k}": str(p) for k, p in enumerate(chosen)}
    return evaluate(policies, cfg, list(HELD_OUT_SEEDS)[:episodes], workers=workers)


def _episode_value(entry: Any, key: str) -> float:
    e = entry.metrics.episode.to_dict()
    name = key.removeprefix("episode.")
    if name == "terminated":
        return float(entry.terminated)
    v = e.get(name)
    return math.nan if v is None else float(v)


def family_scores(result: Any, label: str, key: str) -> dict[str, float]:
    """Mean of ``key`` per scenario family for one policy (a rate for booleans)."""
    by: dict[str, list[float]] = {}
    for entry in result.results[label].episodes:
        by.setdefault(entry.family, []).append(_episode_value(entry, key))
    return {f: float(np.nanmean(v)) for f, v in sorted(by.items())}


def across_seeds(result: Any, seeds: int) -> dict[str, dict[str, Any]]:
    """IQM and stratified bootstrap interval of each metric across the seeds."""
    from uasep_env.metrics.statistics import stratified_bootstrap_iqm

    out = {}
    for key, _, _ in METRICS:
        per = [family_scores(result, f"seed_{k}", key) for k in range(seeds)]
        families = sorted(set().union(*per))
        mat = np.array([[p.get(f, math.nan) for f in families] for p in per])
        keep = np.isfinite(mat).all(axis=0)
        point, lo, hi = stratified_bootstrap_iqm(mat[:, keep])
        # The APF through the same statistic (its per-family scores, one "run"), so that a
        # learned IQM is compared with like: the IQM trims families, a plain mean does not.
        apf = family_scores(result, "apf", key)
        apf_scores = np.array([[apf.get(f, math.nan) for f in families]])[:, keep]
        out[key] = {
            "iqm": point,
            "ci_low": lo,
            "ci_high": hi,
            "apf_iqm": stratified_bootstrap_iqm(apf_scores)[0],
            "families": families,
            "scores": mat.tolist(),
        }
    return out


def targets(
    recipe: str, per_seed: dict[str, dict[str, Any]], agg: dict[str, dict[str, Any]]
) -> list[tuple[str, str, str]]:
    """The issue's targets for ``recipe``: ``(target, measured, verdict)``.

    ``per_seed`` maps ``apf`` and each ``seed_<k>`` to its aggregate on the held-out bank,
    ``agg`` is :func:`across_seeds`'. A rate held to the APF's gets
    :func:`~uasep_env.metrics.statistics.rate_verdict`'s verdict (``met``, ``not met`` or
    ``not shown``) with the episodes behind it; a fixed limit (5 % collisions, 25 % less
    deviation) :func:`~uasep_env.metrics.statistics.limit_verdict`'s, read off the interval.
    """
    apf = per_seed["apf"]
    labels = [lab for lab in per_seed if lab != "apf"]
    out = []
    if recipe in AS_SAFE_AS_APF:
        for key in ("episode.collision", "episode.loss_of_separation"):
            # Every seed on its own (Wilson intervals over the same encounters as the APF's):
            # stricter than the IQM, which trims the families where a seed does worst. The
            # seed shown is the one that decides: the weakest verdict, then the highest rate.
            a = apf[key]
            verdicts = {lab: rate_verdict(per_seed[lab][key], a) for lab in labels}
            rank = (NOT_MET, NOT_SHOWN, MET)
            worst = min(labels, key=lambda lab: (rank.index(verdicts[lab]),
                                                 -per_seed[lab][key]["rate"]))  # fmt: skip
            w = per_seed[worst][key]
            out.append(
                (
                    f"{key.removeprefix('episode.')}: every seed as safe as the APF "
                    "(the weakest seed's verdict)",
                    f"worst {worst}: {w['rate']:.1%} [{w['ci_low']:.1%}, {w['ci_high']:.1%}] "
                    f"vs APF {a['rate']:.1%} [{a['ci_low']:.1%}, {a['ci_high']:.1%}]",
                    f"{weakest_verdict(verdicts.values())} ({episodes_behind(w, a)})",
                )
            )
        d = agg["episode.max_deviation"]
        cut = 1.0 - d["iqm"] / d["apf_iqm"]
        means = [per_seed[lab]["episode.max_deviation"]["mean"] for lab in labels]
        plain = apf["episode.max_deviation"]["mean"]
        if recipe == "mappo_lagrangian":
            # The constraint buys the APF's safety; the task reward must keep the formation.
            out.append(
                (
                    "mean max deviation no larger than the APF's (keeps the formation; IQM "
                    "over seeds x families, the APF through the same statistic)",
                    f"IQM {d['iqm']:.1f} m [{d['ci_low']:.1f}, {d['ci_high']:.1f}] vs APF "
                    f"{d['apf_iqm']:.1f} m; plain means {min(means):.1f}-{max(means):.1f} m "
                    f"vs {plain:.1f} m",
                    limit_verdict(d, d["apf_iqm"], key="iqm"),
                )
            )
            return out
        out.append(
            (
                "mean max deviation at least 25 % below the APF's (IQM over seeds x families, "
                "the APF through the same statistic)",
                f"IQM {d['iqm']:.1f} m [{d['ci_low']:.1f}, {d['ci_high']:.1f}] vs APF "
                f"{d['apf_iqm']:.1f} m ({cut:+.1%} less); plain means {min(means):.1f}-"
                f"{max(means):.1f} m vs {plain:.1f} m ({1 - max(means) / plain:+.1%} to "
                f"{1 - min(means) / plain:+.1%})",
                limit_verdict(d, 0.75 * d["apf_iqm"], key="iqm"),
            )
        )
    else:
        s = agg["episode.collision"]
        out.append(
            (
                "at most 5 % collisions (IQM across seeds)",
                f"{s['iqm']:.1%} [{s['ci_low']:.1%}, {s['ci_high']:.1%}] (early ends, "
                f"collision or lost UAV: {agg['episode.terminated']['iqm']:.1%})",
                limit_verdict(s, 0.05, key="iqm"),
            )
        )
    return out


def _met(ok: bool) -> str:
    return MET if ok else NOT_MET


def iqm_cell(stats: dict[str, Any], kind: str) -> str:
    """An across-seeds aggregate as a table cell: IQM [95 % interval]."""
    if kind == "rate":
        return f"{stats['iqm']:.1%} [{stats['ci_low']:.1%}, {stats['ci_high']:.1%}]"
    return f"{stats['iqm']:.1f} [{stats['ci_low']:.1f}, {stats['ci_high']:.1f}]"


def _fmt(stats: dict[str, Any], kind: str) -> str:
    if kind == "rate":
        return f"{stats['rate']:.1%} [{stats['ci_low']:.1%}, {stats['ci_high']:.1%}]"
    return f"{stats['mean']:.1f} [{stats['ci_low']:.1f}, {stats['ci_high']:.1f}]"


def _training_facts(run: Path) -> dict[str, Any]:
    try:
        return json.loads((run / "validation.json").read_text())["training"]
    except (OSError, ValueError, KeyError):
        return {}


def recipe_args(out: Path) -> dict[str, Any]:
    """The options seed 0 trained with, as its selected checkpoint records them.

    The run's own fields (:data:`~uasep_env.training.args.PER_RUN`) are left out: every
    seed shares the rest, and ``train/reproduce.py`` gives them back as flags, so that a
    report is retrained as it was even after the recipe's defaults moved. Empty when the
    checkpoint does not record them, or there is none.
    """
    from uasep_env.policies.checkpoint_reader import read_checkpoint
    from uasep_env.training.args import PER_RUN

    path = seed_dir(out, 0) / "selected.zip"
    if not path.exists():
        return {}
    meta = read_checkpoint(path)[0]
    args = meta.info.get("args") if isinstance(meta.info, dict) else None
    return {k: v for k, v in args.items() if k not in PER_RUN} if isinstance(args, dict) else {}


def report(
    recipe: str,
    out: Path,
    seeds: int,
    result: Any,
    command: str,
    shipped: dict[str, Any],
    curves_name: str = "curves.png",
) -> tuple[str, dict]:
    """Stage 4: the markdown and JSON of every seed and of the aggregate."""
    agg = across_seeds(result, seeds)
    per_seed = {
        lab: {k: result.results[lab].aggregate[k] for k, _, _ in METRICS} for lab in result.policies
    }
    data = {
        "recipe": recipe,
        "command": command,
        "recipe_args": recipe_args(out),
        "seeds": seeds,
        "held_out_seeds": {"first": result.seeds[0], "count": len(result.seeds)},
        "per_seed": per_seed,
        "across_seeds": agg,
        "targets": _target_records(targets(recipe, per_seed, agg)),
        "shipped": shipped,
        "training": {f"seed_{k}": _training_facts(seed_dir(out, k)) for k in range(seeds)},
    }
    return render_report(data, curves_name), data


def _target_records(tg: list[tuple[str, str, str]]) -> list[dict[str, str]]:
    return [{"target": t, "measured": m, "verdict": v} for t, m, v in tg]


def _nan_back(value: Any) -> Any:
    """A JSON report's statistics with NaN for null (its writer's NaN), to be formatted."""
    if isinstance(value, dict):
        return {k: _nan_back(v) for k, v in value.items()}
    return math.nan if value is None else value


def render_report(data: dict[str, Any], curves_name: str = "curves.png") -> str:
    """The markdown of a report from its JSON data (:func:`report`'s, or a stored one).

    The targets are judged again from the data's figures (:func:`targets`), so that a report
    written under an older rule reads the current one; ``data["targets"]`` is set to them.
    """
    from uasep_env.runtime.tables import render_table

    per_seed = _nan_back(data["per_seed"])
    agg = _nan_back(data["across_seeds"])
    tg = targets(data["recipe"], per_seed, agg)
    data["targets"] = _target_records(tg)
    headers = ["policy", "agent-steps", "train (min)", *(label for _, label, _ in METRICS)]
    rows = []
    for label, a in per_seed.items():
        facts = data["training"].get(label) or {}
        steps = f"{facts['agent_steps']:,}" if "agent_steps" in facts else "-"
        wall = f"{facts['wall_s'] / 60:.1f}" if "wall_s" in facts else "-"
        rows.append([label, steps, wall, *(_fmt(a[k], kind) for k, _, kind in METRICS)])
    rows.append(["IQM across seeds", "", "", *(iqm_cell(agg[k], kind) for k, _, kind in METRICS)])
    apf_row = ["apf, the same IQM over families", "", ""]
    for key, _, kind in METRICS:
        v = agg[key]["apf_iqm"]
        apf_row.append(f"{v:.1%}" if kind == "rate" else f"{v:.1f}")
    rows.append(apf_row)
    first, n = data["held_out_seeds"]["first"], data["held_out_seeds"]["count"]
    return "\n".join(
        [
            f"# {data['recipe']}: {data['seeds']} training seeds",
            "",
            f"Made by `{data['command']}`. Each seed's checkpoint chosen on validation "
            f"encounters only; {n} held-out encounters (seeds {first:,}-{first + n - 1:,}). Per "
            "seed: rates with 95 % Wilson intervals, means with 95 % Student-t intervals. Across "
            "seeds: interquartile mean (IQM) of the per-family scores, 95 % stratified bootstrap "
            "interval (seeds resampled within each scenario family).",
            "",
            "## Held-out bank",
            "",
            render_table(
                headers, rows, align=["left"] + ["right"] * (len(headers) - 1), markdown=True
            ),
            "",
            "## Targets",
            "",
            VERDICT_LEGEND,  # every verdict is read off intervals: say how
            "",
            render_table(["target", "measured", "verdict"], [list(t) for t in tg], markdown=True),
            "",
            f"Chosen to ship: seed {data['shipped']['seed']}'s checkpoint, chosen across seeds on "
            "the validation encounters only, by the rule that chose each seed's checkpoint "
            "(no less safe than the APF, then the lowest mean max deviation; "
            "`train/select_checkpoint.py`).",
            "",
            f"Learning curves of every seed: `{curves_name}`.",
            "",
        ]
    )


def rerender(path: Path) -> str:
    """``--from-json``: rewrite a report's ``.md`` (and its JSON's targets) from its ``.json``.

    No episode is played: the figures are the JSON's; only the verdicts are judged again.
    The curves' file is the one beside it (``<stem>_curves.png``, ``curves.png`` in a run
    folder).

    Raises:
        SystemExit: If ``path`` is not a report's JSON.
    """
    from uasep_env.runtime.jsonio import write_json

    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise SystemExit(f"--from-json {path}: not a train/seeds.py report ({err})") from None
    if not isinstance(data, dict) or not {"per_seed", "across_seeds"} <= data.keys():
        raise SystemExit(f"--from-json {path}: not a train/seeds.py report (no per_seed)")
    curves = "curves.png" if path.stem == "seeds" else f"{path.stem}_curves.png"
    text = render_report(data, curves)
    atomic_write(path.with_suffix(".md"), text)
    write_json(data, path)
    return text


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """A run's ``progress.csv`` as float columns (empty cells NaN)."""
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    cols = ("agent_steps", *CURVE_COLUMNS)
    return {c: np.array([float(r.get(c) or "nan") for r in rows]) for c in cols}


def plot_curves(out: Path, seeds: int, title: str) -> Path | None:
    """Every seed's learning curves in one figure (``<out>/curves.png``).

    None, said on stderr, when no seed has a ``progress.csv`` row to plot (no blank figure).
    """
    curves = {}
    for k in range(seeds):
        path = seed_dir(out, k) / "progress.csv"
        c = read_curve(path) if path.exists() else {"agent_steps": ()}
        if len(c["agent_steps"]):
            curves[k] = c
    if not curves:
        print(f"{out / 'curves.png'} not written: no seed has a progress row", file=sys.stderr)
        return None
    from matplotlib.figure import Figure  # lazily: only the figure needs matplotlib

    fig = Figure(figsize=(12, 7), layout="constrained")
    axes = fig.subplots(2, 2).ravel()
    names = (
        "return (mean per agent)",
        "collision rate",
        "loss-of-separation rate",
        "max deviation (m)",
    )
    for k, c in curves.items():
        for ax, col in zip(axes, CURVE_COLUMNS, strict=True):
            ax.plot(c["agent_steps"], c[col], label=f"seed {k}", lw=1)
    for ax, name in zip(axes, names, strict=True):
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("agent-steps", fontsize=8)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{title}: {seeds} seeds (last 200 episodes of each)")
    path = out / "curves.png"
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=80, facecolor="white")
    return path


def split_recipe_args(argv: list[str] | None) -> tuple[list[str], list[str]]:
    """``(this script's arguments, the recipe's)``: those after ``--`` go to the recipe."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" not in argv:
        return argv, []
    at = argv.index("--")
    return argv[:at], argv[at + 1 :]


def command_line(script: str, argv: list[str], extra: list[str]) -> str:
    """The command that ran ``script``, as a shell reads it back (a value with spaces quoted).

    The inverse of :func:`split_recipe_args`: ``argv`` are the script's own arguments,
    ``extra`` the recipe's (after ``--``).
    """
    import shlex

    return f"python {script} " + shlex.join([*argv, *(["--", *extra] if extra else [])])


def build_parser() -> argparse.ArgumentParser:
    """This driver's flags (validated: a bad value is one line naming the flag)."""
    p = OneLineParser(description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("--recipe", choices=sorted(RECIPES), help="the recipe (required)")
    p.add_argument("--seeds", type=positive_int, default=3, help="number of training seeds")
    p.add_argument("--parallel", type=positive_int, default=1, help="seeds trained side by side")
    p.add_argument("--out-dir", type=Path, help="the seeds' folders (required)")
    p.add_argument("--select-episodes", type=positive_int, default=100,
                   help="validation encounters per checkpoint")  # fmt: skip
    p.add_argument("--episodes", type=positive_int, default=500, help="held-out encounters")
    p.add_argument("--scaling-episodes", type=non_negative_int, default=0,
                   help="episodes per scaling cell (0: no scaling sweep)")  # fmt: skip
    p.add_argument("--workers", type=positive_int, default=2, help="evaluation processes")
    p.add_argument(
        "--publish",
        type=Path,
        default=None,
        metavar="PREFIX",
        help="also write the report to PREFIX.md, PREFIX.json, PREFIX_curves.png (and "
        "PREFIX_scaling.*), e.g. baselines/results/seeds_residual_apf",
    )
    p.add_argument("--force", action="store_true", help="replace the --publish and --ship-to files")
    p.add_argument(
        "--from-json",
        type=Path,
        default=None,
        metavar="JSON",
        help="only rewrite a report's .md (and its JSON's targets) from its seeds.json or "
        "published PREFIX.json: no training, no episode (the other flags are not read)",
    )
    p.add_argument(
        "--ship-to",
        type=Path,
        default=None,
        help="copy the checkpoint chosen across seeds (on validation only) to this file",
    )
    return p


def main(argv: list[str] | None = None, script: str | None = None) -> dict[str, Any]:
    """Run the stages; return the report's JSON data.

    Args:
        argv: Arguments (without the program name); ``sys.argv[1:]`` when None.
        script: The repository's script that ran this (``train/seeds.py``), recorded in the
            report as ``python SCRIPT ...``; None: ``uasep-seeds ...``.
    """
    from uasep_env.runtime.jsonio import write_json

    argv, extra = split_recipe_args(argv)
    p = build_parser()
    p.prog = f"python {script}" if script else "uasep-seeds"
    args = p.parse_args(argv)
    if args.from_json is not None:
        text = rerender(args.from_json)
        print(text)
        return json.loads(args.from_json.read_text())
    missing = [f for f in ("recipe", "out_dir") if getattr(args, f) is None]
    if missing:
        p.error(f"the following arguments are required: --{missing[0].replace('_', '-')}")
    if args.seeds > MAX_SEEDS:
        p.error(f"argument --seeds: at most {MAX_SEEDS} (seed k trains on 1000*k + e)")
    for flag in ("--seed", "--out-dir", "--resume"):
        if flag in extra:
            p.error(f"{flag} is set per seed by this driver; do not pass it after --")
    out = args.out_dir
    # Outputs outside the run folder: checked before hours of training, never overwritten
    # unless --force.
    targets = [] if args.publish is None else published(args.publish, args.scaling_episodes > 0)
    if args.ship_to is not None:
        targets.append(args.ship_to)
    taken = [q for q in targets if q.exists()]
    if taken and not args.force:
        p.error(f"{taken[0]} exists (pass --force to replace it)")
    try:
        claim_run_folder(out)  # one driver per folder (each seed's run claims its own)
    except RunFolderBusy as err:
        p.error(f"argument --out-dir: {err}")
    command = command_line(script or "", argv, extra)
    if script is None:  # the console command, as a wheel user typed it
        command = "uasep-seeds " + command.removeprefix("python  ")

    t0 = time.perf_counter()
    train_all(args.recipe, out, args.seeds, args.parallel, extra)
    t_train = time.perf_counter() - t0
    chosen = select_all(out, args.seeds, args.select_episodes, args.workers)
    shipped = ship(out, args.seeds)
    print(f"shipped (chosen on validation): seed {shipped['seed']}", flush=True)
    if args.ship_to is not None:
        atomic_write(args.ship_to, chosen[shipped["seed"]].read_bytes())
        print(f"copied {chosen[shipped['seed']]} -> {args.ship_to}", flush=True)
    result = held_out(chosen, args.episodes, args.workers)
    curves = "curves.png" if args.publish is None else published(args.publish, False)[2].name
    text, data = report(args.recipe, out, args.seeds, result, command, shipped, curves)
    data["driver_wall_s"] = {"train": t_train, "total": time.perf_counter() - t0}
    atomic_write(out / "seeds.md", text)
    write_json(data, out / "seeds.json")
    plot_curves(out, args.seeds, args.recipe)
    if args.scaling_episodes and not scaling_done(out, args.scaling_episodes):
        from uasep_env.reporting import scaling

        scaling.main(
            [
                "--policy",
                ",".join(["apf", *(f"seed_{k}={c}" for k, c in enumerate(chosen))]),
                "--episodes",
                str(args.scaling_episodes),
                "--out",
                str(out / "scaling"),
                "--workers",
                str(args.workers),
                "--force",
            ]
        )
    if args.publish is not None:
        sources = [out / "seeds.md", out / "seeds.json", out / "curves.png"]
        if args.scaling_episodes:
            sources += [out / f"scaling{ext}" for ext in SCALING_FILES]
        missing = [q for q in sources if not q.exists()]
        if missing:  # all or nothing: a half publication would mix two runs
            raise SystemExit(f"--publish: {missing[0]} was not written; nothing published")
        dests = published(args.publish, args.scaling_episodes > 0)
        for src, dst in zip(sources, dests, strict=True):
            atomic_write(dst, src.read_bytes())
        print(f"published {', '.join(map(str, dests))}", flush=True)
    print(text)
    return data


#: What ``uasep-report --out <run>/scaling`` writes (the JSON first).
SCALING_FILES = (".md", ".json", ".png")


def scaling_done(out: Path, episodes: int) -> bool:
    """Whether ``<out>/scaling.*`` holds a complete sweep of ``episodes`` per cell."""
    if not all((out / f"scaling{ext}").exists() for ext in SCALING_FILES):
        return False
    try:
        data = json.loads((out / "scaling.json").read_text())
        return int(data["seeds"]["count"]) == episodes
    except (OSError, ValueError, KeyError, TypeError):
        return False


def published(prefix: Path, scaling: bool) -> list[Path]:
    """The files ``--publish PREFIX`` writes: the report, its data, the curves (and scaling).

    Raises:
        SystemExit: ``PREFIX`` has no file name (``.``, ``dir/``).
    """
    name = prefix.name
    if not name or name in (".", ".."):
        raise SystemExit(f"--publish {prefix}: give a file name prefix, e.g. results/seeds_x")
    out = [prefix.with_name(f"{name}.md"), prefix.with_name(f"{name}.json"),
           prefix.with_name(f"{name}_curves.png")]  # fmt: skip
    if scaling:
        out += [prefix.with_name(f"{name}_scaling{ext}") for ext in (".md", ".json", ".png")]
    return out


if __name__ == "__main__":
    main()
