"""The CBF: CBF-QP and the CBF-shielded shipped policies against the APF on the held-out bank.

    python baselines/shielded_vs_apf.py [--workers 1] [--episodes 500]
    python baselines/shielded_vs_apf.py --render  # rewrite the .md from the .json.gz

Plays ``cbf-qp`` and every shipped policy under the CBF shield (``ppo_shared+cbf``,
``ppo_residual_apf+cbf``, ``mappo+cbf``; :class:`~uasep_env.policies.shield.Shielded`) on
the held-out bank of ``baselines/learned_vs_apf.py`` (the 500 ``random`` encounters of
:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`), and sets them beside that script's APF and
unshielded rows, read from ``baselines/results/learned_vs_apf.json.gz`` (same seeds, same
metrics: nothing of that file is recomputed or changed). With ``--episodes`` below 500
the reference rows are recomputed on the same episodes instead.

Writes ``baselines/results/shielded_vs_apf.md`` (means with 95 % Student-t intervals,
rates with 95 % Wilson intervals, and the targets: each shielded policy's collision rate no
worse than the APF's, judged by :func:`~uasep_env.metrics.statistics.rate_verdict`) and
``shielded_vs_apf.json.gz`` (every metric of every episode of the new rows, and under
``meta`` the command and its wall time), and prints them. ``--render`` plays no episode: it
writes the ``.md`` again from the stored ``.json.gz`` and the reference rows.
"""

from __future__ import annotations

import argparse
import gzip
import json
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from uasep_env import make_config
from uasep_env.evaluation import evaluate, write_json
from uasep_env.metrics.statistics import VERDICT_LEGEND, stated_rate_verdict
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios import HELD_OUT_SEEDS

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

from learned_vs_apf import CHECKPOINTS, LEARNED, _nan_back  # noqa: E402
from paper_experiment import _cell  # noqa: E402

REFERENCE = ROOT / "results" / "learned_vs_apf.json.gz"
#: The rows of the table (label, dotted metric, statistic, format).
TABLE_ROWS = (
    ("episodes with a collision", "episode.collision", "rate", ".1%"),
    ("episodes with loss of separation (any)", "episode.loss_of_separation", "rate", ".1%"),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", "mean", ".1f"),
    ("min UAV-UAV separation (m)", "episode.min_uav_separation", "mean", ".1f"),
    ("max deviation from plan (m)", "episode.max_deviation", "mean", ".1f"),
    ("RMS deviation, worst UAV (m)", "episode.max_rms_deviation", "mean", ".1f"),
    ("longest conflict resolution (s)", "episode.max_conflict_duration", "mean", ".1f"),
)


def shielded_policies() -> list[str]:
    """``cbf-qp`` and the shipped policies present, shielded."""
    return ["cbf-qp", *(f"{n}+cbf" for n in LEARNED if (CHECKPOINTS / f"{n}.zip").exists())]


def reference_rows(episodes: int, workers: int) -> tuple[dict[str, dict[str, Any]], str]:
    """The APF's and the unshielded policies' aggregates, and where they come from."""
    names = ["apf", *(n for n in LEARNED if (CHECKPOINTS / f"{n}.zip").exists())]
    if episodes == len(HELD_OUT_SEEDS) and REFERENCE.exists():
        with gzip.open(REFERENCE, "rt") as f:
            stored = json.load(f)["random"]["results"]
        return {n: stored[n]["aggregate"] for n in names}, f"`{REFERENCE.relative_to(ROOT.parent)}`"
    seeds = list(HELD_OUT_SEEDS)[:episodes]
    result = evaluate(names, make_config(scenario="random"), seeds, workers=workers)
    return {n: r.aggregate for n, r in result.results.items()}, "recomputed here"


def render(
    new: dict[str, dict[str, Any]],
    ref: dict[str, dict[str, Any]],
    source: str,
    seeds: list[int],
    made_by: str,
) -> str:
    """The results file: the table and the targets, from the aggregates (live or stored).

    ``made_by`` is the provenance sentence (the command and its wall time).
    """
    rows = {**ref, **new}
    order = ["apf", "cbf-qp"] + [x for n in LEARNED if n in ref for x in (n, f"{n}+cbf")]
    order = [p for p in order if p in rows]
    body = [  # an undefined mean (no episode had the event) reads n/a, stored or fresh
        [name, *(_cell(rows[p], key, stat, fmt).replace("nan", "n/a") for p in order)]
        for name, key, stat, fmt in TABLE_ROWS
    ]
    apf = ref["apf"]
    targets = []
    for name in [n for n in new if n != "apf"]:
        c, ca = new[name]["episode.collision"], apf["episode.collision"]
        targets.append(
            [
                f"{name}: collision rate no worse than the APF's",
                f"{c['rate']:.1%} [{c['ci_low']:.1%}, {c['ci_high']:.1%}] vs "
                f"{ca['rate']:.1%} [{ca['ci_low']:.1%}, {ca['ci_high']:.1%}]",
                stated_rate_verdict(c, ca),
            ]
        )
    text = "\n\n".join(
        [
            f"### Held-out bank: {len(seeds)} `random` encounters, seeds {seeds[0]}-{seeds[-1]}",
            f"{made_by} The APF's and the unshielded rows: {source}.",
            render_table(["metric", *order], body, markdown=True),
            "### Targets (held-out bank)",
            VERDICT_LEGEND,
            render_table(["target", "measured", "verdict"], targets, markdown=True),
        ]
    )
    return text + "\n"


def _made_by(command: str, wall_s: float) -> str:
    return f"Made by `{command}` ({wall_s:.0f} s of wall time on a shared 2-core machine)."


#: The provenance sentence of a results file written before the JSON kept its ``meta``.
_MADE_BY = re.compile(r"^Made by `[^`]+` \([^)]*\)\.", re.MULTILINE)


def rerender(out: Path) -> str:
    """``--render``: the ``.md`` from ``shielded_vs_apf.json.gz``, playing no episode.

    The reference rows are :func:`reference_rows`' at the stored episode count (read from
    ``learned_vs_apf.json.gz`` at 500). The provenance is the JSON's ``meta``, or, for a file
    written before it kept one, the sentence of the ``.md`` it replaces.

    Raises:
        SystemExit: If the stored JSON (or the provenance) is missing.
    """
    path = out / "shielded_vs_apf.json.gz"
    if not path.is_file():
        raise SystemExit(f"{path} does not exist (run without --render first)")
    with gzip.open(path, "rt") as fh:
        stored = json.load(fh)
    data = stored["random"]
    if "meta" in stored:
        made_by = _made_by(stored["meta"]["command"], stored["meta"]["wall_s"])
    else:
        md = out / "shielded_vs_apf.md"
        found = _MADE_BY.search(md.read_text()) if md.is_file() else None
        if found is None:
            raise SystemExit(f"{path} has no meta and {md} no 'Made by' sentence to keep")
        made_by = found.group(0)
    seeds = list(data["seeds"])
    if len(seeds) != len(HELD_OUT_SEEDS):
        raise SystemExit(f"--render: {path} holds {len(seeds)} episodes; only a full run "
                         "(500) reads its reference rows without playing")  # fmt: skip
    ref, source = reference_rows(len(seeds), workers=1)
    new = {n: _nan_back(r["aggregate"]) for n, r in data["results"].items()}
    return render(new, {n: _nan_back(a) for n, a in ref.items()}, source, seeds, made_by)


def main(argv: list[str] | None = None) -> str:
    """Evaluate, write the results and print the tables."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--episodes", type=int, default=len(HELD_OUT_SEEDS))
    p.add_argument("--out", type=Path, default=ROOT / "results")
    p.add_argument(
        "--render", action="store_true", help="rewrite the .md from the .json.gz (no episodes)"
    )
    args = p.parse_args(argv)
    if not 1 <= args.episodes <= len(HELD_OUT_SEEDS):
        p.error(f"argument --episodes: must be in [1, {len(HELD_OUT_SEEDS)}]")
    if args.render:
        text = rerender(args.out)
        atomic_write(args.out / "shielded_vs_apf.md", text)
        print(text)
        return text
    t0 = time.perf_counter()
    seeds = list(HELD_OUT_SEEDS)[: args.episodes]
    result = evaluate(
        shielded_policies(), make_config(scenario="random"), seeds, workers=args.workers
    )
    new = {n: r.aggregate for n, r in result.results.items()}
    ref, source = reference_rows(args.episodes, args.workers)
    command = "python baselines/shielded_vs_apf.py " + shlex.join(
        sys.argv[1:] if argv is None else argv
    )
    wall_s = time.perf_counter() - t0
    text = render(new, ref, source, seeds, _made_by(command, wall_s))
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write(args.out / "shielded_vs_apf.md", text)
    write_json(
        {"meta": {"command": command, "wall_s": wall_s}, "random": result},
        args.out / "shielded_vs_apf.json.gz",
    )
    print(text)
    return text


if __name__ == "__main__":
    main()
