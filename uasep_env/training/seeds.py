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
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from uasep_env.runtime.atomic import atomic_copy, atomic_write
from uasep_env.runtime.runfiles import read_json_inside
from uasep_env.runtime.runlock import RunFolderBusy, claim_run_folder
from uasep_env.training import selection as select_checkpoint
from uasep_env.training.args import HelpFormatter, OneLineParser, non_negative_int, positive_int
from uasep_env.training.seed_report import (
    AS_SAFE_AS_APF,
    CURVE_COLUMNS,
    METRICS,
    across_seeds,
    family_scores,
    iqm_cell,
    plot_curves,
    read_curve,
    recipe_args,
    render_report,
    report,
    rerender,
    seed_dir,
    targets,
)

# The report's names are importable from the driver too (train/seeds.py and its tests).
__all__ = [
    "AS_SAFE_AS_APF",
    "CURVE_COLUMNS",
    "MAX_SEEDS",
    "METRICS",
    "RECIPES",
    "SEED_STRIDE",
    "across_seeds",
    "build_parser",
    "command_line",
    "family_scores",
    "held_out",
    "iqm_cell",
    "main",
    "plot_curves",
    "published",
    "read_curve",
    "recipe_args",
    "recipe_env",
    "render_report",
    "report",
    "rerender",
    "scaling_done",
    "seed_dir",
    "select_all",
    "ship",
    "split_recipe_args",
    "targets",
    "train_all",
    "train_command",
]

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
#: Training seed of run ``k`` is ``SEED_STRIDE * k`` (its environments ``+ e``, e < stride).
SEED_STRIDE = 1000
#: Most training seeds a driver runs (seed k trains on SEED_STRIDE * k + e).
MAX_SEEDS = 100


def _python() -> list[str]:
    return [sys.executable]


def recipe_env() -> dict[str, str]:
    """The environment a recipe runs in: this driver's package on the path, one OpenMP thread."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


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
    from uasep_env.training.shield_loop import deployed

    cfg = make_config(scenario="random")
    policies: dict[str, Any] = {"apf": "apf"}
    # As deployed: a checkpoint trained under the shield plays shielded.
    policies |= {f"seed_{k}": deployed(p) for k, p in enumerate(chosen)}
    return evaluate(policies, cfg, list(HELD_OUT_SEEDS)[:episodes], workers=workers)


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
        return read_json_inside(args.from_json.parent, args.from_json)
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
        atomic_copy(chosen[shipped["seed"]], args.ship_to)
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
            atomic_copy(src, dst)
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
        data = read_json_inside(out, out / "scaling.json")
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
