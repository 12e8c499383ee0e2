"""The seed protocol's report: across-seed statistics, targets, the report and its curves.

:mod:`uasep_env.training.seeds` trains, selects and evaluates the seeds; this module turns
their held-out figures into ``seeds.md`` / ``seeds.json``: every seed's figures, the
interquartile mean across seeds with its stratified bootstrap interval, the targets with
their verdicts (:mod:`uasep_env.metrics.statistics`) and the learning curves.
"""

from __future__ import annotations

import math
import sys
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
from uasep_env.runtime.runfiles import read_json_inside
from uasep_env.training.curves import read_rows

#: Recipes whose targets are the APF's safety (and, for the constrained ones, its formation).
AS_SAFE_AS_APF = ("residual_apf", "lagrangian", "lagrangian_residual", "mappo_lagrangian")
#: (dotted aggregate key, label, kind) reported per seed and across seeds.
METRICS = (
    ("episode.collision", "collisions", "rate"),
    ("episode.loss_of_separation", "loss of separation", "rate"),
    ("episode.terminated", "early ends", "rate"),
    ("episode.max_deviation", "max deviation (m)", "mean"),
    ("episode.min_obstacle_distance", "min UAV-obstacle distance (m)", "mean"),
)
CURVE_COLUMNS = ("return_mean", "collision_rate", "loss_of_separation_rate", "max_deviation_mean")


def seed_dir(out: Path, k: int) -> Path:
    """The run folder of seed ``k``."""
    return out / f"seed_{k}"


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
        return read_json_inside(run, run / "validation.json")["training"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def recipe_args(out: Path) -> dict[str, Any]:
    """The options seed 0 trained with, as its selected checkpoint records them.

    The run's own fields (:data:`~uasep_env.training.args.PER_RUN`) are left out: every
    seed shares the rest, and ``train/reproduce.py`` gives them back as flags, so that a
    report is retrained as it was even after the recipe's defaults moved. Empty when the
    checkpoint does not record them, or there is none.
    """
    from uasep_env.training.args import PER_RUN
    from uasep_env.training.checkpoint_readers import read_policy_inside

    path = seed_dir(out, 0) / "selected.zip"
    if not path.exists():
        return {}
    meta = read_policy_inside(seed_dir(out, 0), path)[0]
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
            "interval (seeds resampled within each scenario family)." + _shield_sentence(data),
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


def _shield_sentence(data: dict[str, Any]) -> str:
    """A report's word on the shield its seeds trained under (and play under), if any."""
    shield = (data.get("recipe_args") or {}).get("shield", "none")
    if shield in (None, "none"):
        return ""
    return (
        f" Trained under the {shield.upper()} shield (`--shield {shield}`) and evaluated under it: "
        f"every seed's checkpoint plays as `<checkpoint>+{shield}`."
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
        data = read_json_inside(path.parent, path)
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
    rows = read_rows(path, root=path.parent)
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
