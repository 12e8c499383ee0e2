"""The leaderboard's outputs: the JSON to submit or diff, the Markdown table, the figure."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

__all__ = ["figure", "markdown", "to_json", "write_outputs"]

#: The table's columns after the policy: heading and how a row's cell is written.
COLUMNS = (
    "collision rate",
    "LoS rate",
    "max deviation (m)",
    "conflict time (s)",
    "episode cost",
    "deviation at equal safety (m)",
)


def to_json(board: dict[str, Any]) -> str:
    """Strict JSON, keys sorted and indented: the same suite gives the same bytes."""
    from uasep_env.runtime.jsonio import to_plain

    return (
        json.dumps(to_plain(board, strict=True), sort_keys=True, indent=1, allow_nan=False) + "\n"
    )


def _rate(s: dict[str, Any]) -> str:
    if s["rate"] is None:
        return "-"
    return f"{s['rate']:.1%} [{s['ci_low']:.1%}, {s['ci_high']:.1%}]"


def _mean(s: dict[str, Any], digits: int = 1) -> str:
    if s["mean"] is None or not math.isfinite(s["mean"]):
        return "-"
    lo, hi = s["ci_low"], s["ci_high"]
    ci = f" [{lo:.{digits}f}, {hi:.{digits}f}]" if lo is not None and hi is not None else ""
    return f"{s['mean']:.{digits}f}{ci}"


def _equal(eq: dict[str, Any], kind: str) -> str:
    if eq["deviation"] is None:
        return f"- ({eq.get('reason', 'not reached')})"
    if kind != "swept":
        return f"{eq['deviation']:.1f} (single point)"
    setting = eq["setting"]
    where = (
        f"between {setting[0]:g} and {setting[1]:g}" if isinstance(setting, list)
        else f"at {setting:g}"
    )  # fmt: skip
    return f"{eq['deviation']:.1f} ({where})"


def _fronts(settings: dict[str, Any]) -> str:
    banks = settings.get("front_banks")
    if not settings["front"]:
        return "skipped"
    if banks is None or list(banks) == list(settings["banks"]):
        return "swept"
    return "swept on " + ", ".join(banks)


def markdown(board: dict[str, Any]) -> str:
    """One table per bank; every rate and mean with its 95 % interval."""
    from uasep_env.runtime.tables import render_table

    s = board["settings"]
    out = [
        "# uasep-bench leaderboard",
        "",
        f"`{' '.join(board['command'])}` (uasep-env {board['versions']['uasep_env']}, "
        f"env v{board['versions']['env']}; episodes per bank: {s['episodes'] or 'all'}; "
        f"fronts: {_fronts(s)})",
        "",
        "Rates with 95 % Wilson intervals, means with 95 % Student-t intervals. Deviation at "
        "equal safety: the least max deviation along the policy's front (its knob swept) with "
        "a loss-of-separation (LoS) rate within the bank's budget and no collision. env: "
        "the env version a row played (a learned policy plays the one it was trained in).",
    ]
    from uasep_env.benchmark.verdict import sentences

    verdict = sentences(board)
    if verdict:
        # Read from the numbers below (uasep_env.benchmark.verdict), never written by hand.
        out += ["", "## Verdict", "", *(f"* {line}" for line in verdict)]
    for bank, info in board["banks"].items():
        seeds, budget = info["seeds"], info["budget"]
        last = seeds["first"] + seeds["count"] - 1
        out += [
            "",
            f"## {info['title']} (`{bank}`)",
            "",
            f"{seeds['count']} episodes, seeds {seeds['first']}-{last}"
            f" ({info['seed_range']}); LoS budget {budget['loss_of_separation']:.1%} "
            f"({budget['source']})",
            "",
        ]
        rows = []
        for label, r in board["results"][bank].items():
            d = r["default"]
            kind = r.get("front_kind", board["policies"][label]["front"])
            rows.append([
                label, f"-v{r.get('env_version', board['versions']['env'])}",
                _rate(d["collision"]), _rate(d["loss_of_separation"]),
                _mean(d["max_deviation"]), _mean(d["conflict_time"]), _mean(d["cost"], 2),
                _equal(r["equal_safety"], kind),
            ])  # fmt: skip
        out += render_table(["policy", "env", *COLUMNS], rows, markdown=True).splitlines()
    return "\n".join(out) + "\n"


def figure(board: dict[str, Any], path: Path) -> Path:
    """Every policy's front (max deviation against LoS rate, with intervals), a panel per bank."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from uasep_env.runtime.atomic import atomic_output

    banks = list(board["banks"])
    cols = min(4, len(banks))
    rows = math.ceil(len(banks) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    n_rows = max(len(r) for r in board["results"].values())
    colours = plt.get_cmap("tab10" if n_rows <= 10 else "tab20")
    env = board["versions"]["env"]
    for ax, bank in zip(axes.flat, banks, strict=False):
        for i, (label, r) in enumerate(board["results"][bank].items()):
            earlier = r.get("env_version", env) != env  # another env: hollow, named so
            name = f"{label} (-v{r['env_version']})" if earlier else label
            pts = [p for p in r["front"] if p["max_deviation"]["mean"] is not None]
            if not pts:
                continue
            x = [p["loss_of_separation"]["rate"] for p in pts]
            y = [p["max_deviation"]["mean"] for p in pts]
            xe = [
                [xi - p["loss_of_separation"]["ci_low"] for xi, p in zip(x, pts, strict=True)],
                [p["loss_of_separation"]["ci_high"] - xi for xi, p in zip(x, pts, strict=True)],
            ]
            ye = [[yi - (p["max_deviation"]["ci_low"] if p["max_deviation"]["ci_low"] is not None
                         else yi) for yi, p in zip(y, pts, strict=True)],
                  [(p["max_deviation"]["ci_high"] if p["max_deviation"]["ci_high"] is not None
                    else yi) - yi for yi, p in zip(y, pts, strict=True)]]  # fmt: skip
            c = colours(i % colours.N)
            ax.errorbar(x, y, xerr=xe, yerr=ye, fmt="o-", ms=3, lw=0.8, color=c, alpha=0.8,
                        label=name, mfc="none" if earlier else c)  # fmt: skip
        ax.axvline(board["banks"][bank]["budget"]["loss_of_separation"], color="k", ls=":", lw=0.8)
        ax.set_title(board["banks"][bank]["title"], fontsize=9)
        ax.set_xlabel("loss-of-separation rate")
        ax.set_ylabel("max deviation (m)")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(banks) :]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle("uasep-bench: each policy's front (bars: 95 % intervals; dotted: LoS budget)")
    fig.tight_layout()
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
    return Path(path)


def write_outputs(board: dict[str, Any], out: Path, with_figure: bool) -> list[Path]:
    """Write ``OUT/bench.json``, ``OUT/bench.md`` and (``with_figure``) ``OUT/bench.png``."""
    from uasep_env.runtime.atomic import atomic_write

    written = [
        atomic_write(out / "bench.json", to_json(board)),
        atomic_write(out / "bench.md", markdown(board)),
    ]
    if with_figure:
        written.append(figure(board, out / "bench.png"))
    return written
