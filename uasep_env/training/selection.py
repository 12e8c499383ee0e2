"""Pick a run's best checkpoint on the validation encounters (never the held-out bank).

    python -m uasep_env.training.selection runs/ppo_residual_apf --episodes 100 --copy-to ship.zip

(``python train/select_checkpoint.py`` in a clone; ``uasep-seeds`` runs it on every seed.)

Every ``checkpoints/step_*/policy.zip`` of the run (and the final ``policy.zip``) plays
the first ``--episodes`` encounters of :data:`uasep_env.scenarios.VALIDATION_SEEDS`, beside
the APF on the same seeds. The choice, safety first: the checkpoints whose rates of early
ends (a collision or a lost UAV), collisions and losses of separation are no higher than
the APF's (or, if none is, the one lowest in those rates, in that order), and of those
the lowest mean max deviation. Writes ``<run>/selection.csv`` (one row per checkpoint)
and prints the choice. A checkpoint trained under the shield (``--shield cbf``) plays shielded,
as it is deployed (:func:`uasep_env.training.shield_loop.deployed`).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path
from typing import Any

from uasep_env import make_config
from uasep_env.evaluation import EvaluationResult, evaluate
from uasep_env.policies import load_policy
from uasep_env.runtime.atomic import atomic_copy, atomic_output
from uasep_env.scenarios import VALIDATION_SEEDS
from uasep_env.training.curves import read_rows
from uasep_env.training.shield_loop import deployed

KEYS = ("terminated", "collision", "loss_of_separation", "max_deviation")


def _figures(result: EvaluationResult, label: str) -> dict[str, float]:
    agg = result.results[label].aggregate
    return {k: float(agg[f"episode.{k}"]["mean"]) for k in KEYS}


def choose(rows: list[dict[str, Any]], apf: dict[str, float]) -> dict[str, Any]:
    """The rule, safety first: among the rows no less safe than the APF, the least deviation.

    Args:
        rows: Candidates, each with the figures of :data:`KEYS` (rates and the mean max
            deviation on the same validation encounters as ``apf``).
        apf: The APF's figures on those encounters.

    Returns:
        The chosen row: of those whose early-end, collision and loss-of-separation rates are
        all at most the APF's, the one with the lowest mean max deviation; if none is, the
        one lowest in those rates, in that order (ties: the earlier row).
    """
    if not rows:
        raise ValueError("no candidates to choose from")
    pool = [r for r in rows if all(r[k] <= apf[k] for k in KEYS[:3])]
    if not pool:
        return min(rows, key=lambda r: tuple(r[k] for k in KEYS[:3]))
    return min(pool, key=lambda r: r["max_deviation"])


def read_selection(run: Path) -> tuple[list[dict[str, Any]], dict[str, float]]:
    """A run's ``selection.csv``: its checkpoints' rows and the APF's figures.

    Raises:
        FileNotFoundError: The run has not been through selection.
        ValueError: The table has no APF row or a figure is not a number (named).
    """
    table = read_rows(run / "selection.csv", root=run)
    rows, apf = [], None
    where = run / "selection.csv"
    for line, r in enumerate(table, start=2):
        try:
            figs = {k: float(r[k]) for k in KEYS}
            name = r["policy"]
            steps = None if name == "apf" or not r.get("agent_steps") else int(r["agent_steps"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(
                f"{where}, line {line}: needs a policy, an integer agent_steps and numeric "
                f"{', '.join(KEYS)}; got {dict(r)!r:.200}"
            ) from None
        if name == "apf":
            apf = figs
        else:
            rows.append({"policy": name, "agent_steps": steps, **figs})
    if apf is None:
        raise ValueError(f"{run / 'selection.csv'}: no apf row")
    return rows, apf


def main(argv: list[str] | None = None) -> Path:
    """Evaluate the checkpoints, write the table, return the chosen policy file."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("run", type=Path)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--copy-to", type=Path, default=None)
    args = p.parse_args(argv)
    paths = sorted(
        args.run.glob("checkpoints/step_*/policy.zip"),
        key=lambda q: int(q.parent.name.removeprefix("step_")),
    )
    if (args.run / "policy.zip").exists():
        paths.append(args.run / "policy.zip")
    if not paths:
        p.error(f"no checkpoints under {args.run}")
    cfg = make_config(scenario="random")
    seeds = list(VALIDATION_SEEDS)[: args.episodes]
    metas = {str(q): load_policy(q, cfg).meta for q in paths}
    policies = {"apf": "apf"} | {str(q): deployed(q, metas[str(q)]) for q in paths}
    result = evaluate(policies, cfg, seeds, workers=args.workers)
    apf = _figures(result, "apf")
    rows = []
    for q in paths:
        f = _figures(result, str(q))
        info = metas[str(q)].info
        safe = all(f[k] <= apf[k] for k in KEYS[:3])
        rows.append({"policy": str(q), "agent_steps": info.get("agent_steps"), **f, "safe": safe})
    best = choose(rows, apf)
    with atomic_output(args.run / "selection.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
        w.writerow({"policy": "apf", "agent_steps": "", **apf, "safe": ""})
    print(f"APF on {len(seeds)} validation encounters: {apf}")
    for r in rows:
        mark = "*" if r is best else " "
        print(f"{mark} {r['policy']}: {r['agent_steps']} steps, "
              f"{', '.join(f'{k} {r[k]:.3f}' for k in KEYS)}, safe={r['safe']}")  # fmt: skip
    chosen = Path(best["policy"])
    if args.copy_to is not None:
        atomic_copy(chosen, args.copy_to)
        print(f"copied {chosen} -> {args.copy_to}")
    return chosen


if __name__ == "__main__":
    main()
