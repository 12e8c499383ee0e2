"""Retrain the checkpoint a seeds report chose and check it against the report, bit for bit.

    python train/reproduce.py baselines/results/seeds_residual_apf.json --out-dir runs/repro
    python train/reproduce.py REPORT --seed 1 --out-dir runs/repro_s1 --ship-to my.zip

A training run is deterministic given its seed and its agent-steps (seeded environments, one
torch thread; tested in ``tests/test_reproduce.py``); the wall-clock budget only decides where
a run stops. So the checkpoint that ``train/seeds.py`` chose for seed ``k`` (``--seed``,
default: the one the report shipped) is retrained by running the report's recipe with
``--seed 1000*k`` and the report's recorded options (``recipe_args``, every one written out
as a flag, so that a later change of the recipe's defaults does not change the run; a report
without them runs the recipe's current defaults) until it saves the checkpoint at that
agent-step count, from scratch (a resumed run is not bit-exact). The wall budget is lifted
(``--max-minutes``) so that a loaded machine still reaches the step count.

Then the checkpoint plays the report's held-out encounters and every per-seed figure of the
report (counts, sums, means, intervals) is compared with the published one: all equal, or the
script exits 1 naming the differences. ``<out-dir>/reproduction.json`` records the
comparison. ``--ship-to`` copies a reproduced checkpoint (never one that differs) and writes
``<stem>_reproduction.json`` beside it: which report and seed it reproduces, and the original
run's training facts (its wall time and agent-steps), which the reproduction's own
``policy.zip`` cannot carry. A run folder that already holds the checkpoint is not retrained.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import seeds as seeds_driver  # noqa: E402

from uasep_env.training.args import (  # noqa: E402
    HelpFormatter,
    OneLineParser,
    non_negative_int,
    positive_int,
)

#: The figures of one metric compared with the report (all must be equal).
FIELDS = ("n", "n_valid", "successes", "sum", "mean", "ci_low", "ci_high")


def chosen_checkpoint(report: dict[str, Any], seed: int | None) -> tuple[int, dict[str, Any]]:
    """``(seed, row)`` of the checkpoint the report chose for ``seed``.

    The row is the report's validation figures of that checkpoint, with its ``policy`` and
    ``agent_steps``.

    Raises:
        ValueError: The report has no such seed, or its choice is not a step checkpoint.
    """
    picks = report["shipped"]["validation"]["seeds"]
    k = int(report["shipped"]["seed"]) if seed is None else seed
    by_seed = {int(p["seed"]): p for p in picks}
    if k not in by_seed:
        raise ValueError(f"--seed {k}: the report has seeds {sorted(by_seed)}")
    pick = by_seed[k]
    name = Path(pick["policy"]).parent.name
    if not name.startswith("step_"):
        raise ValueError(
            f"seed {k}: the chosen policy {pick['policy']!r} is a run's final policy, not a "
            "step checkpoint; retrain with the report's own command instead"
        )
    return k, pick


#: What :func:`train_command` sets itself, whatever the report's recipe options say.
_SET_HERE = ("torch_threads", "total_timesteps", "max_minutes")


def train_command(
    recipe: str, run: Path, k: int, steps: int, extra: list[str], options: dict[str, Any]
) -> list[str]:
    """The recipe's command that saves ``checkpoints/step_<steps>`` of seed ``k``.

    ``options`` are the report's recipe options (``recipe_args``; empty for a report that
    predates them: the recipe's current defaults), every one written out as a flag; ``extra``
    (the flags after ``--``) come last and win.
    """
    from uasep_env.training.args import PER_RUN, to_argv

    # A checkpoint is saved only below the step budget, so the run goes one step further
    # (to the end of that rollout) and stops there.
    return [
        sys.executable, str(HERE / seeds_driver.RECIPES[recipe]), "--out-dir", str(run),
        "--seed", str(seeds_driver.SEED_STRIDE * k), "--torch-threads", "1", "--no-progress",
        "--total-timesteps", str(steps + 1), "--max-minutes", "100000",
        *to_argv(options, skip=PER_RUN + _SET_HERE), *extra,
    ]  # fmt: skip


def compare(now: dict[str, Any], published: dict[str, Any]) -> list[str]:
    """Every figure of ``published`` (per metric) that ``now`` does not equal exactly."""
    bad = []
    for key, stats in published.items():
        for field in FIELDS:
            if field not in stats:
                continue
            a, b = now.get(key, {}).get(field), stats[field]
            same = a == b or (
                isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
            )
            if not same:
                bad.append(f"{key}.{field}: {a!r}, published {b!r}")
    return bad


def build_parser() -> argparse.ArgumentParser:
    """This script's flags (validated: a bad value is one line naming the flag)."""
    p = OneLineParser(description=__doc__, formatter_class=HelpFormatter)
    p.add_argument("report", type=Path, help="a seeds report (train/seeds.py's seeds.json)")
    p.add_argument("--seed", type=non_negative_int, default=None,
                   help="the report's seed to retrain (None: the one it shipped)")  # fmt: skip
    p.add_argument("--out-dir", type=Path, required=True, help="the retrained run's folder")
    p.add_argument("--workers", type=positive_int, default=1, help="evaluation processes")
    p.add_argument("--ship-to", type=Path, default=None, help="copy a reproduced checkpoint here")
    p.add_argument("--force", action="store_true", help="replace the --ship-to files")
    return p


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Retrain (unless done), compare, optionally ship; return the comparison."""
    from uasep_env import make_config
    from uasep_env.evaluation import evaluate
    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.runtime.jsonio import dumps

    argv, extra = seeds_driver.split_recipe_args(argv)
    p = build_parser()
    args = p.parse_args(argv)
    try:
        report = json.loads(args.report.read_text())
        k, pick = chosen_checkpoint(report, args.seed)
        steps, recipe = int(pick["agent_steps"]), str(report["recipe"])
        bank = report["held_out_seeds"]
        published = report["per_seed"][f"seed_{k}"]
        options = report.get("recipe_args", {})
        if not isinstance(options, dict) or not all(
            isinstance(v, bool | int | float | str) for v in options.values()
        ):
            raise ValueError(f"recipe_args is not a table of flag values: {options!r:.80}")
    except (OSError, ValueError, KeyError, TypeError) as e:
        p.error(f"{args.report}: not a seeds report with a chosen checkpoint ({e})")
    ship = [] if args.ship_to is None else [args.ship_to, sidecar(args.ship_to)]
    taken = [q for q in ship if q.exists()]
    if taken and not args.force:
        p.error(f"{taken[0]} exists (pass --force to replace it)")

    run = args.out_dir / f"seed_{k}"
    checkpoint = run / "checkpoints" / f"step_{steps}" / "policy.zip"
    cmd = train_command(recipe, run, k, steps, extra, options)
    if not checkpoint.exists():
        if run.exists():
            p.error(f"{run} exists without {checkpoint}: a resumed run is not bit-exact; "
                    "remove the folder to retrain from scratch")  # fmt: skip
        args.out_dir.mkdir(parents=True, exist_ok=True)
        env = {**seeds_driver.recipe_env(), "OMP_NUM_THREADS": "1"}
        print(f"seed {k}: {' '.join(cmd[1:])}", flush=True)
        with (args.out_dir / f"seed_{k}.log").open("a") as log:
            subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, check=True)
        if not checkpoint.exists():
            raise SystemExit(f"training ended without {checkpoint}")

    seeds = list(range(int(bank["first"]), int(bank["first"]) + int(bank["count"])))
    label = f"seed_{k}"
    result = evaluate({label: str(checkpoint)}, make_config(scenario="random"), seeds,
                      workers=args.workers)  # fmt: skip
    now = json.loads(dumps(result.results[label].aggregate))
    bad = compare(now, published)
    record = {
        "report": args.report.as_posix(),
        "seed": k,
        "agent_steps": steps,
        "checkpoint": checkpoint.relative_to(args.out_dir).as_posix(),
        "command": "python train/reproduce.py " + " ".join(map(str, argv)),
        "training_command": "python "
        + " ".join(
            Path(c).relative_to(ROOT).as_posix() if c.startswith(str(ROOT)) else c for c in cmd[1:]
        ),
        "held_out": {"seeds": bank, "identical": not bad, "differences": bad},
        "original_training": report.get("training", {}).get(label, {}),
        # How it was chosen (on validation encounters only), as the report gives it.
        "validation": {"apf": report["shipped"]["validation"].get("apf"), "chosen": pick},
    }
    atomic_write(args.out_dir / "reproduction.json", dumps(record, indent=1))
    if bad:
        print(f"NOT reproduced: {len(bad)} figures differ, e.g. {bad[:3]}", flush=True)
        raise SystemExit(1)
    print(f"reproduced: seed {k}'s checkpoint at {steps:,} agent-steps flies the report's "
          f"{len(seeds)} held-out encounters with every figure identical", flush=True)  # fmt: skip
    if args.ship_to is not None:
        atomic_write(args.ship_to, checkpoint.read_bytes())
        atomic_write(sidecar(args.ship_to), dumps(record, indent=1))
        print(f"copied {checkpoint} -> {args.ship_to}", flush=True)
    return record


def sidecar(ship_to: Path) -> Path:
    """Where ``--ship-to`` records what the shipped file reproduces."""
    return ship_to.with_name(f"{ship_to.stem}_reproduction.json")


if __name__ == "__main__":
    main()
