"""Does the calibrated prediction hold on the TEST flights? Containment and volume per class.

    python baselines/real_prediction_calibrated.py [--env-episodes 16] [--no-figure]

``prediction.fit="calibrated"`` (:mod:`uasep_env.reachable.calibrated`, table built by
``tools/build_prediction_calibration.py`` from the training and validation flights only) is
measured here on the test flights only (and on the synthetic obstacles of test seeds for the
``dubins`` class), with the windows of the calibration (same resampling, noise, Kalman
filter, window starts; :mod:`build_prediction_calibration`), swept mode:

* offline: containment (the whole path over ``(t, t + h]`` inside the region), with the
  target ``1 - alpha`` and a 95 % Clopper-Pearson interval over windows (windows of one
  flight are dependent: the interval is optimistic), median and 95th-percentile volume;
  beside two reference regions on the same windows: the Dubins enclosing region with its
  bounds ``(w_max, vz_max)`` scaled on a sqrt(2) grid to the least scale holding 95 %, and
  the sphere of radius ``speed x h`` plus the env's inflation about the estimate;
* in the environment: the real-traffic bank's config (test flights) with
  ``prediction.fit="calibrated"``, the region the world predicts at each step (from 10 s on)
  checked against the obstacle's true position at every physics step of the next ``h``.

Writes ``baselines/results/real_prediction_calibrated.{md,json}`` and
``docs/figures/real_prediction_calibrated.png``.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binomtest

from uasep_env import make_config, reachable, real_traffic
from uasep_env.reachable.calibrated import calibrated_region, load_table
from uasep_env.runtime.atomic import atomic_output, atomic_write
from uasep_env.runtime.jsonio import write_json
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios import REAL_TRAFFIC_TEST_SEEDS
from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK
from uasep_env.sim.obstacles import AIRCRAFT_CLASSES

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import build_prediction_calibration as cal  # noqa: E402

HORIZONS = (5.0, 10.0, 20.0)
CLASSES = ("glider", "helicopter", "fixed_wing", "dubins")
TARGET = 0.95
SCALES = tuple(2.0 ** (k / 2) for k in range(25))  # 1 to 4096, as real_prediction.py
#: Reference regions are measured on every REF_EVERY-th window, the path every REF_POINTS steps.
REF_EVERY = 3
REF_POINTS = 5


def _volume(axes: np.ndarray) -> np.ndarray:
    return (4.0 / 3.0) * np.pi * np.prod(axes, axis=-1)


def _inside_path(
    paths: cal.Paths,
    win: cal.Windows,
    horizon: float,
    dt: float,
    centre: np.ndarray,
    axes: np.ndarray,
    heading: np.ndarray,
    every: int = 1,
) -> np.ndarray:
    """Whether each window's path (every ``every``-th step and the last) is inside."""
    h = round(horizon / dt)
    steps = sorted({*range(every, h + 1, every), h})
    ok = np.ones(len(win.row), dtype=bool)
    for j in steps:
        ok &= reachable.contains(paths.pos[win.row, win.k + j], centre, axes, heading)
    return ok


def _dubins_region(
    win: cal.Windows, horizon: float, scale: float, rho: float, cfg: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The enclosing Dubins region with bounds scaled by ``scale``, as the env places it."""
    speed = np.round(np.hypot(win.est_vel[:, 0], win.est_vel[:, 1]), 1)
    uniq, inv = np.unique(speed, return_inverse=True)
    off, axes = reachable.ellipsoid(
        uniq,
        cfg.obstacle.max_turn_rate * scale,
        cfg.obstacle.max_climb_rate * scale,
        horizon,
        rho,
        mode="swept",
    )
    off, axes = np.asarray(off)[inv.ravel()], axes[inv.ravel()]
    psi = np.arctan2(win.est_vel[:, 1], win.est_vel[:, 0])
    centre = win.est_pos.copy()
    centre[:, 0] += off * np.cos(psi)
    centre[:, 1] += off * np.sin(psi)
    return centre, axes, psi


def _rate(hits: int, n: int) -> dict[str, float]:
    ci = binomtest(hits, n).proportion_ci(0.95, method="exact") if n else None
    return {
        "rate": hits / n if n else float("nan"),
        "ci_low": ci.low if ci else float("nan"),
        "ci_high": ci.high if ci else float("nan"),
    }


def offline(cls: str, horizons: tuple[float, ...] = HORIZONS) -> list[dict[str, Any]]:
    """The class's test windows: calibrated region and the two references, per horizon."""
    cfg = cal.env_config()
    dt, rho = cfg.dt, cal.inflation(cfg)
    if cls == "dubins":
        paths = cal.dubins_paths("test", cfg)
    else:
        paths = cal.real_paths(real_traffic.load().select("test", cls), cfg, cal.SEED + 2)
    code = AIRCRAFT_CLASSES.index(cls)
    rows = []
    for h in horizons:
        win = cal.windows(paths, h, dt)
        n = len(win.row)
        row: dict[str, Any] = {"class": cls, "horizon_s": h, "windows": n}
        row["tracks"] = len(set(paths.source[win.row].tolist())) if n else 0
        if not n:
            rows.append(row)
            continue
        centre, axes, psi = calibrated_region(
            np.full(n, code), win.est_pos, win.est_vel, h, "swept", np.full(n, rho)
        )
        ins = _inside_path(paths, win, h, dt, centre, axes, psi)
        vol = _volume(axes)
        row["calibrated"] = {
            **_rate(int(ins.sum()), n),
            "median_volume_m3": float(np.median(vol)),
            "p95_volume_m3": float(np.percentile(vol, 95)),
        }
        sub = cal.Windows(*(a[::REF_EVERY] for a in (win.row, win.k, win.est_pos, win.est_vel)))
        m = len(sub.row)
        radius = np.linalg.norm(sub.est_vel, axis=-1) * h + rho
        sph_axes = np.repeat(radius[:, None], 3, axis=1)
        ins_s = _inside_path(paths, sub, h, dt, sub.est_pos, sph_axes, np.zeros(m), REF_POINTS)
        row["speed_sphere"] = {
            **_rate(int(ins_s.sum()), m),
            "median_volume_m3": float(np.median(_volume(sph_axes))),
        }
        # The least scale of the Dubins bounds holding TARGET (bisection on the grid).
        lo, hi, found = 0, len(SCALES) - 1, None
        while lo <= hi:
            mid = (lo + hi) // 2
            c, a, p = _dubins_region(sub, h, SCALES[mid], rho, cfg)
            ok = _inside_path(paths, sub, h, dt, c, a, p, REF_POINTS)
            if ok.mean() >= TARGET:
                found, hi = (mid, ok, a), mid - 1
            else:
                lo = mid + 1
        if found is None:
            c, a, p = _dubins_region(sub, h, SCALES[-1], rho, cfg)
            ok = _inside_path(paths, sub, h, dt, c, a, p, REF_POINTS)
            found = (len(SCALES) - 1, ok, a)
        idx, ok, a = found
        c0, a0, p0 = _dubins_region(sub, h, 1.0, rho, cfg)
        ok0 = _inside_path(paths, sub, h, dt, c0, a0, p0, REF_POINTS)
        row["enclosing"] = {
            **_rate(int(ok0.sum()), m),
            "median_volume_m3": float(np.median(_volume(a0))),
        }
        row["enclosing_95"] = {
            **_rate(int(ok.sum()), m),
            "scale": SCALES[idx],
            "reached": bool(ok.mean() >= TARGET),
            "median_volume_m3": float(np.median(_volume(a))),
        }
        row["reference_windows"] = m
        rows.append(row)
        print(f"{cls} {h:g} s: {row['calibrated']['rate']:.1%} of {n}", file=sys.stderr)
    return rows


def in_env(horizon: float, episodes: int, scenario: str = "real_traffic") -> dict[str, Any]:
    """Containment of the world's own calibrated regions, per class, over ``episodes``."""
    from uasep_env.sim.world import World

    conf = (
        copy.deepcopy(REAL_TRAFFIC_BANK) if scenario == "real_traffic" else {"scenario": scenario}
    )
    conf["prediction"] = {"fit": "calibrated", "horizon": horizon}
    cfg = make_config(conf)
    seeds = REAL_TRAFFIC_TEST_SEEDS[0] if scenario == "real_traffic" else cal.DUBINS_SEEDS["test"]
    world = World(cfg, n_envs=episodes)
    world.reset(seed=int(seeds))
    k_max = cfg.max_steps
    hist = {
        name: np.empty((k_max + 1, *getattr(world, name).shape))
        for name in ("pred_center", "pred_axes", "pred_heading")
    }
    pos = np.empty((k_max + 1, *world.obstacles.pos.shape))
    zero = np.zeros((episodes, world.n_uavs, 3))
    for k in range(k_max + 1):
        if k:
            world.step(zero)
        for name in hist:
            hist[name][k] = getattr(world, name)
        pos[k] = world.obstacles.pos
    h = round(horizon / cfg.dt)
    starts = np.arange(round(cal.WARMUP_S / cfg.dt), k_max + 1 - h)
    ok = np.ones((len(starts), *world.obstacles.active.shape), dtype=bool)
    for j in range(1, h + 1):
        ok &= reachable.contains(
            pos[starts + j], hist["pred_center"][starts], hist["pred_axes"][starts],
            hist["pred_heading"][starts],
        )  # fmt: skip
    vol = _volume(hist["pred_axes"][starts])
    active = world.obstacles.active
    out = {}
    for code in np.unique(world.obstacles.aircraft_class[active]):
        sel = (world.obstacles.aircraft_class == code) & active
        okc = ok[:, sel]
        out[AIRCRAFT_CLASSES[int(code)]] = {
            "episodes": int(sel.sum()),
            "windows": int(okc.size),
            **_rate(int(okc.sum()), int(okc.size)),
            "worst_episode": float(okc.mean(axis=0).min()),
            "median_volume_m3": float(np.median(vol[:, sel])),
        }
    return out


def _pct(d: dict[str, Any]) -> str:
    return f"{d['rate']:.1%} [{d['ci_low']:.1%}, {d['ci_high']:.1%}]"


def render(res: dict[str, Any]) -> str:
    """The markdown page."""
    head = [
        "# Calibrated prediction on the test flights",
        "",
        "Written by `python baselines/real_prediction_calibrated.py`; method in "
        "[`docs/reachable_sets.md`](../../docs/reachable_sets.md) and "
        "[`docs/real_traffic.md`](../../docs/real_traffic.md). Swept region, "
        f"target {TARGET:.0%} (alpha = {res['alpha']}, PAC delta = {res['delta']}); intervals: "
        "95 % Clopper-Pearson over windows (windows of one flight are dependent, so they are "
        "optimistic). Volumes in m³. References on every "
        f"{REF_EVERY}rd window, path checked every {REF_POINTS} steps.",
        "",
        "## Offline (test flights; dubins: test seeds)",
        "",
    ]
    body = []
    for r in res["offline"]:
        if "calibrated" not in r:
            body.append([r["class"], f"{r['horizon_s']:g}", "0", *["-"] * 8])
            continue
        c, e, e95, s = r["calibrated"], r["enclosing"], r["enclosing_95"], r["speed_sphere"]
        scale = f"{e95['scale']:.3g}" + ("" if e95["reached"] else " (not reached)")
        body.append(
            [r["class"], f"{r['horizon_s']:g}", str(r["windows"]), str(r["tracks"]), _pct(c),
             f"{c['median_volume_m3']:.3g}", f"{c['p95_volume_m3']:.3g}",
             f"{e['rate']:.1%}, {e['median_volume_m3']:.3g}",
             f"x{scale}: {e95['rate']:.1%}, {e95['median_volume_m3']:.3g}",
             f"{s['rate']:.1%}, {s['median_volume_m3']:.3g}",
             f"{s['median_volume_m3'] / c['median_volume_m3']:.2g}"]
        )  # fmt: skip
    headers = [
        "class", "horizon (s)", "windows", "tracks", "calibrated containment",
        "calibrated median volume", "calibrated p95 volume", "enclosing (default bounds)",
        "enclosing, bounds scaled to 95 %", "speed sphere", "sphere / calibrated volume",
    ]  # fmt: skip
    env_rows = []
    for key, per in res["env"].items():
        scen, h = key.split("@")
        for cls, d in per.items():
            env_rows.append(
                [scen, h, cls, str(d["episodes"]), str(d["windows"]), _pct(d),
                 f"{d['worst_episode']:.1%}", f"{d['median_volume_m3']:.3g}"]
            )  # fmt: skip
    env_headers = [
        "scenario", "horizon (s)", "class", "obstacles", "windows", "containment",
        "worst obstacle", "median volume",
    ]  # fmt: skip
    return "\n".join(
        [
            *head,
            render_table(headers, body, markdown=True),
            "",
            f"## In the environment ({res['env_episodes']} episodes per horizon)",
            "",
            'The world\'s own regions (`prediction.fit="calibrated"`), real-traffic bank config '
            "(test flights) and the `random` family (dubins), from 10 s into the episode.",
            "",
            render_table(env_headers, env_rows, markdown=True),
            "",
        ]
    )


def plot(res: dict[str, Any], path: Path) -> None:
    """Containment against median volume, every predictor, per class (10 s, or the first)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in res["offline"] if "calibrated" in r]
    classes = list(dict.fromkeys(r["class"] for r in rows))
    fig, axs = plt.subplots(1, len(classes), figsize=(4 * len(classes), 3.6), squeeze=False)
    colours = {"calibrated": "C0", "enclosing": "C1", "enclosing_95": "C2", "speed_sphere": "C3"}
    marks = {5.0: "o", 10.0: "s", 20.0: "^"}
    for ax, cls in zip(axs[0], classes, strict=True):
        for r in (r for r in rows if r["class"] == cls):
            for key, colour in colours.items():
                d = r[key]
                ax.scatter(d["median_volume_m3"], d["rate"], color=colour,
                           marker=marks.get(r["horizon_s"], "x"),
                           label=f"{key}, {r['horizon_s']:g} s", alpha=0.85)  # fmt: skip
        ax.axhline(TARGET, color="k", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_title(cls)
        ax.set_xlabel("median volume (m³)")
        ax.set_ylabel("containment (test)")
        ax.set_ylim(0, 1.02)
    axs[0][0].legend(fontsize=6, ncol=1)
    fig.tight_layout()
    with atomic_output(path) as fh:  # all or nothing, like every output
        fig.savefig(fh, format=path.suffix[1:] or "png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env-episodes", type=int, default=16)
    p.add_argument("--out-dir", type=Path, default=ROOT / "baselines" / "results")
    p.add_argument(
        "--figure", type=Path, default=ROOT / "docs" / "figures" / "real_prediction_calibrated.png"
    )
    p.add_argument("--no-figure", action="store_true")
    args = p.parse_args(argv)
    if args.env_episodes < 1:
        p.error(f"--env-episodes must be positive, got {args.env_episodes}")
    table = load_table()
    res: dict[str, Any] = {
        "alpha": table.meta["alpha"],
        "delta": table.meta["delta"],
        "table": table.path.name,
        "env_episodes": args.env_episodes,
        "offline": [row for cls in CLASSES for row in offline(cls)],
        "env": {},
    }
    for h in HORIZONS:
        res["env"][f"real_traffic@{h:g}"] = in_env(h, args.env_episodes)
        res["env"][f"random@{h:g}"] = in_env(h, args.env_episodes, "random")
        print(f"env {h:g} s done", file=sys.stderr)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    write_json(res, args.out_dir / "real_prediction_calibrated.json")
    text = render(res)
    atomic_write(args.out_dir / "real_prediction_calibrated.md", text.encode("utf-8"))
    if not args.no_figure:
        plot(res, args.figure)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
