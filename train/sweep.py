"""A small grid sweep of the PPO recipes at a short budget, to choose their defaults.

    python train/sweep.py --recipe residual_apf --grid log_std_init=-1,-0.5 \
        --grid residual_scale=0.5,1 --timesteps 3000000 --parallel 2

Every setting of the grid is one run of ``train/ppo_shared.py`` (a subprocess, all
settings on the same seed) in ``<out>/<setting>/``; each is scored on its validation
encounters (``--eval-episodes``, :data:`uasep_env.scenarios.VALIDATION_SEEDS`, never the
held-out bank). The table (``<out>/sweep.csv`` and ``sweep.md``) lists, per setting, the
training window's last figures and the validation collision rate, loss-of-separation
rate and mean max deviation. Runs already finished (a ``validation.json``) are reused.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from uasep_env.runtime.atomic import atomic_output, atomic_write

HERE = Path(__file__).resolve().parent


def _grid(items: list[str]) -> list[dict[str, str]]:
    axes = []
    for item in items:
        key, _, values = item.partition("=")
        if not key or not values:
            raise SystemExit(f"--grid: expected KEY=V1,V2,..., got {item!r}")
        axes.append([(key, v) for v in values.split(",")])
    return [dict(combo) for combo in itertools.product(*axes)]


def _run(setting: dict[str, str], args: argparse.Namespace) -> dict:
    name = "_".join(f"{k}={v}" for k, v in setting.items()) or "default"
    out = Path(args.out) / name
    if not (out / "validation.json").exists():
        cmd = [
            sys.executable,
            str(HERE / "ppo_shared.py"),
            "--action-mode", args.recipe,
            "--total-timesteps", str(args.timesteps),
            "--eval-episodes", str(args.eval_episodes),
            "--out-dir", str(out),
            "--checkpoint-every", str(10 * args.timesteps),
            "--no-progress",
            *args.extra,
        ]  # fmt: skip
        for k, v in setting.items():
            cmd += ["--" + k.replace("_", "-"), v]
        # A killed run continues from its last checkpoint; otherwise its files are replaced.
        latest = out / "checkpoints" / "latest"
        cmd += ["--resume", str(latest)] if latest.exists() else ["--overwrite"]
        out.mkdir(parents=True, exist_ok=True)
        with (out / "log.txt").open("a") as log:
            subprocess.run(cmd, check=True, stdout=log, stderr=subprocess.STDOUT)
    summary = json.loads((out / "validation.json").read_text())
    val = summary["validation"]["learned"]
    train = summary["training"]
    return {
        "setting": name,
        "agent_steps": train["agent_steps"],
        "wall_min": round(train["wall_s"] / 60, 1),
        "train_return": round(train.get("return_mean", float("nan")), 1),
        "train_collision_rate": round(train.get("collision_rate", float("nan")), 3),
        "val_collision_rate": round(val["collision"], 3),
        "val_los_rate": round(val["loss_of_separation"], 3),
        "val_max_deviation_m": round(val["max_deviation"], 1),
        "apf_val_max_deviation_m": round(summary["validation"]["apf"]["max_deviation"], 1),
    }


def main(argv: list[str] | None = None) -> list[dict]:
    """Run the grid; write and print the table."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--recipe", choices=("direct", "residual_apf"), default="residual_apf")
    p.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2")
    p.add_argument("--timesteps", type=int, default=3_000_000)
    p.add_argument("--eval-episodes", type=int, default=40)
    p.add_argument("--parallel", type=int, default=2)
    p.add_argument("--out", default="runs/sweep")
    p.add_argument("extra", nargs="*", help="more ppo_shared.py flags, after --")
    args = p.parse_args(argv)
    settings = _grid(args.grid) or [{}]
    with ThreadPoolExecutor(max_workers=args.parallel) as pool:
        rows = list(pool.map(lambda s: _run(s, args), settings))
    out = Path(args.out)
    with atomic_output(out / "sweep.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    head = list(rows[0])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(r[k]) for k in head) + " |" for r in rows]
    atomic_write(out / "sweep.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    return rows


if __name__ == "__main__":
    main()
