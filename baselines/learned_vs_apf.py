"""The learned policies against the reference controllers on the held-out bank, with targets.

    python baselines/learned_vs_apf.py [--workers 2] [--episodes 500] [--paper-episodes 20]
    python baselines/learned_vs_apf.py --add mvp,orca  # only these, merged into the results

Every controller plays the same encounters (the reference controllers are the registry's,
:func:`uasep_env.policies.reference_controllers`: the three APFs, MVP, ORCA and any
controller registered since): the held-out bank's 500 ``random`` encounters
(:data:`uasep_env.scenarios.HELD_OUT_SEEDS`: crossing, head-on, overtaking, climbing,
multi-obstacle; seeds training never draws) and 20 runs of the ``paper`` scenario
(:data:`~uasep_env.scenarios.HELD_OUT_PAPER_SEEDS`). The learned policies are the policy
checkpoints in ``baselines/checkpoints/`` (``ppo_shared.zip``, ``ppo_residual_apf.zip``),
loaded without unpickling; a residual policy flies the APF's command plus its correction.

Writes ``baselines/results/learned_vs_apf.md`` (the tables the README shows: means with
95 % Student-t intervals, rates with 95 % Wilson intervals, and the targets) and
``learned_vs_apf.json.gz`` (every metric of every episode), and prints the tables.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from uasep_env import make_config
from uasep_env.evaluation import EvaluationResult, evaluate, write_json
from uasep_env.metrics.statistics import (
    MET,
    NOT_MET,
    VERDICT_LEGEND,
    limit_verdict,
    stated_rate_verdict,
)
from uasep_env.policies import load_policy, reference_controllers
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios import HELD_OUT_PAPER_SEEDS, HELD_OUT_SEEDS

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from paper_experiment import ROWS, table  # noqa: E402

CHECKPOINTS = ROOT / "checkpoints"
LEARNED = (
    "ppo_shared",
    "ppo_residual_apf",
    "ppo_residual_apf_set",
    "mappo",
    "ppo_lagrangian",
    "ppo_lagrangian_deviation",
    "mappo_lagrangian",
)
#: Shipped only if it earns its place (issue 29): no "missing" row when absent.
OPTIONAL = ("mappo_lagrangian",)
#: Rows of the tables: the paper's, with the combined loss-of-separation rate first.
TABLE_ROWS = (
    ("episodes with loss of separation (any)", "episode.loss_of_separation", "rate", ".1%"),
    ("episodes with a collision", "episode.collision", "rate", ".1%"),
    *(r for r in ROWS if r[1] != "episode.collision"),
)
TRAINING_BUDGET_S = 3600.0


def compared_policies() -> dict[str, str]:
    """The registered reference controllers and the shipped policies present.

    What every comparison plays. Shipped policies go by name, so that results files name no
    machine's folder.
    """
    shipped = [n for n in LEARNED if (CHECKPOINTS / f"{n}.zip").exists()]
    names = [*reference_controllers(), *shipped]
    return {name: name for name in names}


def targets(bank: EvaluationResult, meta: dict[str, dict]) -> list[tuple[str, str, str]]:
    """The issue's targets: ``(target, measured, verdict)``; ``n/a`` where the policy is missing.

    A rate held to the APF's gets :func:`~uasep_env.metrics.statistics.rate_verdict`'s verdict
    (``met``, ``not met`` or ``not shown``) with the episodes behind it; the other targets
    are ``met`` or ``not met``.
    """
    res = {k: v.aggregate for k, v in bank.results.items()}
    apf = res["apf"]
    out: list[tuple[str, str, str]] = []
    for name in LEARNED:
        if name not in meta:
            if name not in OPTIONAL:
                out.append((f"{name}: trained and shipped", "missing", "n/a"))
            continue
        facts, note = meta[name], ""
        if "reproduces" in facts:  # retrained to a report's checkpoint: the original run's
            rep = facts["reproduces"]  # budget is the recipe's
            facts = rep["original_training"]
            how = (
                "reproduces it bit for bit"
                if rep["held_out"]["identical"]
                else "was retrained from that seed to its checkpoint's agent-steps, not bit for bit"
            )
            note = f" (the original run, {rep['report']} seed {rep['seed']}; this file {how})"
        wall = float(facts.get("wall_s", float("nan")))
        steps = int(facts.get("agent_steps", 0))
        out.append(
            (f"{name}: trains in <= 60 min", f"{wall / 60:.1f} min, {steps:,} agent-steps{note}",
             _met(wall <= TRAINING_BUDGET_S))
        )  # fmt: skip
    for name, what in (("ppo_residual_apf", "residual"), ("ppo_lagrangian", "PPO-Lagrangian")):
        if name in res:
            out += _as_safe_and_closer(what, res[name], apf, cut=0.25)
    if "mappo_lagrangian" in res:
        out += _as_safe_and_closer("MAPPO-Lagrangian", res["mappo_lagrangian"], apf, cut=0.0)
    for name, what in (("ppo_shared", "pure"), ("mappo", "MAPPO")):
        if name in res:
            c = res[name]["episode.collision"]
            out.append(
                (f"{what}: collision rate <= 5 %",
                 f"{c['rate']:.1%} [{c['ci_low']:.1%}, {c['ci_high']:.1%}]",
                 limit_verdict(c, 0.05))
            )  # fmt: skip
    return out


def _met(ok: bool) -> str:
    return MET if ok else NOT_MET


def _as_safe_and_closer(
    what: str, r: dict[str, Any], apf: dict[str, Any], cut: float
) -> list[tuple[str, str, str]]:
    """The targets of a policy held to the APF's safety.

    Collision and loss-of-separation rates no worse than the APF's (judged by
    :func:`~uasep_env.metrics.statistics.rate_verdict` on the Wilson intervals), and mean
    max deviation at least ``cut`` below the APF's.
    """
    out = []
    for key, name in (("episode.collision", "collision"),
                      ("episode.loss_of_separation", "loss-of-separation")):  # fmt: skip
        out.append(
            (f"{what}: {name} rate no worse than the APF's",
             f"{r[key]['rate']:.1%} [{r[key]['ci_low']:.1%}, {r[key]['ci_high']:.1%}] vs "
             f"{apf[key]['rate']:.1%} [{apf[key]['ci_low']:.1%}, {apf[key]['ci_high']:.1%}]",
             stated_rate_verdict(r[key], apf[key]))
        )  # fmt: skip
    dev = r["episode.max_deviation"]
    d, da = dev["mean"], apf["episode.max_deviation"]["mean"]
    goal = f">= {cut * 100:.0f} % below the APF's" if cut else "no larger than the APF's"
    out.append(
        (f"{what}: mean max deviation {goal}",
         f"{d:.1f} m [{dev['ci_low']:.1f}, {dev['ci_high']:.1f}] vs {da:.1f} m "
         f"({(1 - d / da):+.0%} lower)",
         limit_verdict(dev, (1.0 - cut) * da, key="mean"))
    )  # fmt: skip
    return out


class _Stored:
    """A results file's evaluation (plain JSON), read as an :class:`EvaluationResult`.

    :func:`table` and :func:`targets` read only ``results[label].aggregate``.
    """

    def __init__(self, data: dict[str, Any]) -> None:
        self.data = data
        self.results = {k: SimpleNamespace(aggregate=_nan_back(v["aggregate"]))
                        for k, v in data["results"].items()}  # fmt: skip


def _nan_back(aggregate: dict[str, Any]) -> dict[str, Any]:
    """The JSON layout writes a NaN statistic as null; the live aggregate holds NaN."""
    return {
        key: {k: float("nan") if v is None and k != "kind" else v for k, v in stats.items()}
        for key, stats in aggregate.items()
    }


def _read(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise SystemExit(f"{path} does not exist (run without --add or --render first)")
    with gzip.open(path, "rt") as fh:
        return json.load(fh)


def add_policies(
    names: list[str], path: Path, workers: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The results file at ``path`` with ``names`` evaluated on its encounters and merged in.

    Only the named controllers play (on the file's seeds and configs, as a full run plays
    them); every other row is the file's, number for number. Returns ``(meta, scenarios)``.

    Raises:
        SystemExit: If there is no such file.
    """
    stored = _read(path)
    meta = stored.pop("meta")
    order = list(compared_policies())
    for scenario, data in stored.items():
        result = evaluate({n: n for n in names}, make_config(scenario=scenario), data["seeds"],
                          workers=workers).to_dict()  # fmt: skip
        for key in ("results", "policy_specs"):
            data[key] = {**data[key], **result[key]}
        data["policies"] = sorted(data["results"], key=lambda n: (
            order.index(n) if n in order else len(order)))  # fmt: skip
        data["results"] = {n: data["results"][n] for n in data["policies"]}
    return meta, stored


def shipped_meta() -> dict[str, dict]:
    """The training facts of every shipped learned policy (what the targets read)."""
    policies = compared_policies()
    meta = {name: load_policy(CHECKPOINTS / f"{name}.zip").meta.info for name in LEARNED
            if name in policies}  # fmt: skip
    for name in meta:  # train/reproduce.py --ship-to: what a retrained file reproduces
        side = CHECKPOINTS / f"{name}_reproduction.json"
        if side.exists():
            meta[name] = {**meta[name], "reproduces": json.loads(side.read_text())}
    return meta


def render(results: dict[str, Any], meta: dict[str, dict]) -> str:
    """The markdown of the results (``scenario -> EvaluationResult`` or a stored one)."""
    sections = []
    for scenario, result in results.items():
        seeds = result.data["seeds"] if isinstance(result, _Stored) else result.seeds
        what = "held-out bank" if scenario == "random" else "paper scenario"
        sections += [
            f"### {what.capitalize()}: {len(seeds)} `{scenario}` encounters, seeds "
            f"{seeds[0]}-{seeds[-1]}",
            table(result, TABLE_ROWS),
        ]
    if "random" in results:
        body = [list(t) for t in targets(results["random"], meta)]
        sections += [
            "### Targets (held-out bank)",
            VERDICT_LEGEND,
            render_table(["target", "measured", "verdict"], body, markdown=True),
        ]
    return "\n\n".join(sections) + "\n"


def main(argv: list[str] | None = None) -> str:
    """Evaluate, write the results and print the tables."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--episodes", type=int, default=len(HELD_OUT_SEEDS))
    p.add_argument("--paper-episodes", type=int, default=len(HELD_OUT_PAPER_SEEDS))
    p.add_argument("--out", type=Path, default=ROOT / "results")
    p.add_argument(
        "--add",
        default=None,
        help="comma-separated controllers to evaluate and merge into the existing results "
        "(the others' rows are kept as they are; the encounters are the file's)",
    )
    p.add_argument(
        "--render", action="store_true", help="rewrite the .md from the .json.gz (no episodes)"
    )
    args = p.parse_args(argv)
    if not 1 <= args.episodes <= len(HELD_OUT_SEEDS):
        p.error(f"argument --episodes: must be in [1, {len(HELD_OUT_SEEDS)}]")
    if args.render:
        stored = _read(args.out / "learned_vs_apf.json.gz")
        meta = stored.pop("meta")
        text = render({k: _Stored(v) for k, v in stored.items()}, meta)
        atomic_write(args.out / "learned_vs_apf.md", text)
        print(text)
        return text
    if args.add is not None:
        names = [n.strip() for n in args.add.split(",") if n.strip()]
        if bad := [n for n in names if n not in compared_policies()]:
            p.error(f"argument --add: not a compared policy: {bad} ({list(compared_policies())})")
        meta, stored = add_policies(names, args.out / "learned_vs_apf.json.gz", args.workers)
        meta = {**meta, **{n: v for n, v in shipped_meta().items() if n in names}}
        text = render({k: _Stored(v) for k, v in stored.items()}, meta)
        atomic_write(args.out / "learned_vs_apf.md", text)
        write_json({"meta": meta, **stored}, args.out / "learned_vs_apf.json.gz")
        print(text)
        return text

    policies = compared_policies()
    meta = shipped_meta()
    results = {}
    for scenario, seeds in (
        ("random", list(HELD_OUT_SEEDS)[: args.episodes]),
        ("paper", list(HELD_OUT_PAPER_SEEDS)[: args.paper_episodes]),
    ):
        if seeds:
            results[scenario] = evaluate(
                policies, make_config(scenario=scenario), seeds, workers=args.workers
            )
    text = render(results, meta)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write(args.out / "learned_vs_apf.md", text)
    write_json({"meta": meta, **results}, args.out / "learned_vs_apf.json.gz")
    print(text)
    return text


if __name__ == "__main__":
    main()
