"""Tables and figure of ``baselines/real_prediction.py`` (the results file and the plot)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_output

FITS = ("enclosing", "paper")


def _pct(x: float) -> str:
    return f"{100.0 * x:.1f} %"


def _vol(x: float) -> str:
    return f"{x:.3g}"


def render_markdown(res: dict[str, Any]) -> str:
    """The results file: the containment table and the excluded pairs."""
    cfgd = res["config"]
    lines = [
        "# Reachable-set prediction on recorded aircraft",
        "",
        f"Written by `python baselines/real_prediction.py` (seed {res['seed']}); method and "
        "reading in [`docs/real_traffic.md`](../../docs/real_traffic.md).",
        f"Swept region; default bounds w_max = {cfgd['obstacle.max_turn_rate']} rad/s, "
        f"vz_max = {cfgd['obstacle.max_climb_rate']} m/s; fitted: the smallest common scale "
        f"of both (sqrt(2) grid) with {_pct(res['target'])} containment. Volumes: median, m³.",
        "",
        "## Containment",
        "",
        "| class | horizon (s) | windows | enclosing | paper | enclosing volume | "
        "paper volume | fitted scale (enclosing) | fitted containment | fitted volume | "
        "fitted scale (paper) | fitted containment (paper) | fitted volume (paper) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    summary = [
        "## Summary",
        "",
        "| class | horizon (s) | windows | enclosing | paper | enclosing, horizontal only | "
        "bound scale for 95 % (enclosing) | volume at 95 % (m³) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for cls, c in res["classes"].items():
        for row in c["horizons"]:
            if "excluded" in row:
                continue
            ft = row["enclosing_fitted"]
            scale = f"{ft['scale']:.3g}" if ft["reached"] else "not reached"
            vol = _vol(ft["median_volume_m3"]) if ft["reached"] else "-"
            summary.append(
                f"| {cls} | {row['horizon_s']:g} | {row['windows']} | "
                f"{_pct(row['enclosing']['containment'])} | {_pct(row['paper']['containment'])} | "
                f"{_pct(row['enclosing_horizontal'])} | {scale} | {vol} |"
            )
    lines[5:5] = [*summary, ""]
    excluded = []
    for cls, c in res["classes"].items():
        for row in c["horizons"]:
            h = f"{row['horizon_s']:g}"
            if "excluded" in row:
                excluded.append(f"| {cls} | {h} | {row['windows']} | {row['excluded']} |")
                continue
            cells = [cls, h, str(row["windows"])]
            cells += [_pct(row[f]["containment"]) for f in FITS]
            cells += [_vol(row[f]["median_volume_m3"]) for f in FITS]
            for f in FITS:
                ft = row[f"{f}_fitted"]
                scale = f"{ft['scale']:.3g}" + ("" if ft["reached"] else " (not reached)")
                cells += [scale, _pct(ft["containment"]), _vol(ft["median_volume_m3"])]
            lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Excluded",
        "",
        "| class | horizon (s) | windows | why |",
        "|---|---|---|---|",
        *excluded,
        "",
        "## Observed",
        "",
        "| class | tracks | median speed (m/s) | p95 turn rate (rad/s) | p95 vertical speed (m/s) "
        "| median spacing (s) | median estimate error (m) |",
        "|---|---|---|---|---|---|---|",
    ]
    for cls, c in res["classes"].items():
        o = c["observed"]
        lines.append(
            f"| {cls} | {c['tracks']} | {o['median_speed_m_s']:.1f} | "
            f"{o['p95_turn_rate_rad_s']:.3f} | {o['p95_vertical_speed_m_s']:.2f} | "
            f"{o['median_spacing_s']:g} | {o['median_estimate_error_m']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def plot(res: dict[str, Any], path: Path) -> None:
    """Containment with the default and the fitted bounds, per class and horizon."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    markers = {"glider": "o", "helicopter": "s", "fixed_wing": "^"}
    for cls, c in res["classes"].items():
        rows = [r for r in c["horizons"] if "excluded" not in r]
        if not rows:
            continue
        h = [r["horizon_s"] for r in rows]
        for fit, style in (("enclosing", "-"), ("paper", "--")):
            axes[0].plot(
                h, [100 * r[fit]["containment"] for r in rows], style,
                marker=markers[cls], label=f"{cls}, {fit}",
            )  # fmt: skip
            vol = [
                r[f"{fit}_fitted"]["median_volume_m3"] if r[f"{fit}_fitted"]["reached"] else np.nan
                for r in rows
            ]
            axes[1].plot(h, vol, style, marker=markers[cls], label=f"{cls}, {fit}")
    axes[0].set(xlabel="horizon (s)", ylabel="containment, default bounds (%)", ylim=(0, 100))
    axes[1].set(
        xlabel="horizon (s)", ylabel="median volume, bounds fitted to 95 % (m³)", yscale="log"
    )
    axes[1].set_title("missing: 95 % not reached at any scale", fontsize=8)
    axes[0].legend(fontsize=7)
    fig.suptitle("Reachable ellipsoids on recorded aircraft (swept region)")
    fig.tight_layout()
    with atomic_output(path) as fh:
        fig.savefig(fh, format="png", dpi=120)
    plt.close(fig)
