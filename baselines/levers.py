"""The levers toward a learned policy past the best classical controller, side by side.

    python baselines/levers.py                     # baselines/results/levers.md
    python baselines/levers.py --interventions 32  # the shield's interventions on the APF

Each lever is one flag or config of a recipe, trained with three seeds by ``train/seeds.py``
at its reference recipe's flags (its command at the top of its seed study,
``baselines/results/seeds_lever_*_v3.md``; two ran fewer agent-steps, the table says them);
this script reads the studies' JSON (no episode is played) and writes, per lever, the held-
out IQM across seeds with its 95 % stratified bootstrap interval beside its reference
recipe's and the best classical controller's row of the leaderboard
(``baselines/results/bench/bench.json``, the same 500 held-out encounters).
``--interventions N`` flies the APF (a zero residual) under the CBF shield on the first
``N`` validation encounters and prints how many of each agent's steps the shield changed
(what ``--cost shield`` counts; the limit of the shield lever is set from it).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"

#: ``(lever, the flags it adds, its seed study, its reference study)``; references first.
LEVERS = (
    ("residual PPO on the APF (reference)", "-", "seeds_residual_apf_lean_v3", None),
    ("residual on MVP (region)", "--action-mode residual_mvp_region",
     "seeds_lever_mvp_base_v3", "seeds_residual_apf_lean_v3"),
    ("residual PPO-Lagrangian (reference)", "-", "seeds_lagrangian_residual_lean_v3", None),
    ("deviation term with its slope far out", "--config \"... reward.deviation=0.4 "
     "reward.deviation_scale=100\"", "seeds_lever_deviation_v3",
     "seeds_lagrangian_residual_lean_v3"),
    ("trained under the shield", "--shield cbf --cost shield --cost-limit 185",
     "seeds_lever_shield_v3", "seeds_lagrangian_residual_lean_v3"),
    ("cost limit below the APF's", "--cost-limit apf-rate", "seeds_lever_cost_limit_v3",
     "seeds_lagrangian_residual_lean_v3"),
)  # fmt: skip

_METRICS = (
    ("episode.collision", "collisions", "rate"),
    ("episode.loss_of_separation", "loss of separation", "rate"),
    ("episode.max_deviation", "max deviation (m)", "mean"),
)


def _steps(study: dict) -> str:
    steps = sorted({t["agent_steps"] for t in study["training"].values() if "agent_steps" in t})
    return "-".join(f"{s:,}" for s in steps) if steps else "-"


def _minutes(study: dict) -> str:
    walls = [t["wall_s"] / 60 for t in study["training"].values() if "wall_s" in t]
    return f"{min(walls):.1f}-{max(walls):.1f}" if walls else "-"


def rows(results: Path = RESULTS) -> tuple[list[list[str]], list[str]]:
    """The table's rows and the studies not found (a lever not trained yet)."""
    out, missing = [], []
    from uasep_env.benchmark.output import _mean, _rate
    from uasep_env.benchmark.verdict import best_classical
    from uasep_env.training.seed_report import iqm_cell

    bench = json.loads((results / "bench" / "bench.json").read_text())
    best = best_classical(bench)
    if best is not None:
        row = bench["results"]["held_out"][best]["default"]
        # The leaderboard's row as bench.md writes it.
        cells = [
            (_rate if kind == "rate" else _mean)(row[k.split(".")[1]]) for k, _, kind in _METRICS
        ]
        out.append(
            [f"{best} (the leaderboard's best classical controller)", "-", "-", "-", *cells, "-"]
        )
    for lever, flags, name, ref in LEVERS:
        path = results / f"{name}.json"
        if not path.exists():
            missing.append(name)
            continue
        study = json.loads(path.read_text())
        agg = study["across_seeds"]
        change = "-"
        if ref is not None and (results / f"{ref}.json").exists():
            base = json.loads((results / f"{ref}.json").read_text())["across_seeds"]
            a, b = agg["episode.max_deviation"]["iqm"], base["episode.max_deviation"]["iqm"]
            change = f"{(a - b) / b:+.0%}" if b and not math.isnan(a) else "-"
        out.append([lever, f"`{flags}`" if flags != "-" else "-", _steps(study), _minutes(study),
                    *(iqm_cell(agg[k], kind) for k, _, kind in _METRICS), change])  # fmt: skip
    return out, missing


def render(results: Path = RESULTS) -> str:
    """``levers.md``: the command, the table and what is missing."""
    from uasep_env.runtime.tables import render_table

    table, missing = rows(results)
    headers = ["lever", "flags", "agent-steps a seed", "train (min a seed)",
               *(label for _, label, _ in _METRICS), "max deviation vs its reference"]  # fmt: skip
    text = [
        "# Levers toward a learned policy past the best classical controller",
        "",
        "Made by `python baselines/levers.py` from the seed studies' JSON (each lever's "
        "command at the top of its `seeds_*.md`; three training seeds each, the reference "
        "recipe's flags, the agent-steps in the table). Held-out bank, 500 `random` encounters "
        "(seeds 5,000,000-5,000,499): IQM across seeds of the per-family scores with 95 % "
        "stratified bootstrap intervals; the classical row is the leaderboard's (rates with "
        "Wilson, means with Student-t intervals, the same encounters).",
        "",
        "## Held-out bank",
        "",
        render_table(headers, table, markdown=True),
        "",
    ]
    if missing:
        text += [f"Not trained yet: {', '.join(missing)}.", ""]
    return "\n".join(text)


def interventions(episodes: int) -> float:
    """Mean count of shield interventions per agent-episode of the APF (a zero residual)."""
    import numpy as np

    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.scenarios import VALIDATION_SEEDS
    from uasep_env.training.shield_loop import ShieldInLoop

    cfg = make_config(scenario="random", action={"mode": "residual_apf"})
    core, shield = EnvCore(cfg, episodes), ShieldInLoop(cfg)
    obs = core.reset(seed=next(iter(VALIDATION_SEEDS)))  # environment e: that seed + e
    count = np.zeros((episodes, cfg.n_uavs))
    done = np.zeros(episodes, dtype=bool)
    while not done.all():
        flown = shield.act(np.zeros((episodes, cfg.n_uavs, 3), np.float32), obs)
        count += shield.interventions.reshape(episodes, -1) * ~done[:, None]
        res = core.step(flown)
        obs, done = res.obs, done | res.terminated | res.truncated
    return float(count.mean())


def main(argv: list[str] | None = None) -> None:
    """Write ``levers.md``, or print the shield's interventions on the APF."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "--interventions", type=int, default=0, metavar="N",
        help="print the APF's shield interventions per agent-episode on N encounters",
    )  # fmt: skip
    p.add_argument("--out", type=Path, default=RESULTS / "levers.md")
    args = p.parse_args(argv)
    if args.interventions < 0:
        p.error(f"argument --interventions: must be >= 0, got {args.interventions}")
    if args.interventions:
        n = interventions(args.interventions)
        print(f"the APF under the CBF shield: {n:.1f} interventions per agent-episode "
              f"({args.interventions} validation encounters)")  # fmt: skip
        return
    from uasep_env.runtime.atomic import atomic_write

    atomic_write(args.out, render())
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
