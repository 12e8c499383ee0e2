"""Build the calibrated prediction's table (``uasep_env/data/prediction_calibration.json``).

    python tools/build_prediction_calibration.py [--out PATH] [--classes glider,dubins]

Split conformal prediction, per aircraft class (Mondrian), mode and horizon, offline. Nothing
here runs in the environment; the environment only reads the table
(:mod:`uasep_env.reachable.calibrated`).

Windows, the way the environment sees an obstacle (``tests/test_real_prediction.py`` checks
the same definitions in the env):

* real classes: every stretch of a recorded track without a gap over
  ``obstacle.replay_max_gap`` (20 s), resampled every ``dt`` by linear interpolation (as the
  replay flies it), measured every ``dt`` with the configured obstacle noise (velocities: the
  replay's central differences) and filtered by the env's obstacle Kalman filter;
* ``dubins``: the synthetic obstacles of the ``random`` family (the held-out bank's), flown by
  :class:`uasep_env.sim.world.World` for 200 s, estimated by the world itself.

A window starts every second, at least 10 s into its stretch, with the whole horizon ahead.
Its real path is the obstacle's true position at every physics step in ``(t, t + h]``
(swept) or at ``t + h`` (terminal). Its score is the largest normalised distance of the path
from the region's centre: ``max_j |D^-1 R^T (p_j - c)|``, ``c = p + kappa h u`` and ``D`` the
base shape ``(lambda_lon v h / 2 + rho, lambda_lat v h / 2 + rho, mu_z h + rho)`` (``v`` the
estimated horizontal speed, ``rho`` the env's inflation). The region ``q D`` holds the path iff
the score is at most ``q``.

Shape: ``lambda`` and ``mu`` from the TRAINING flights (per-axis quantiles of the path's largest
deviation; the quantile level giving the least median volume). Quantile ``q``: from the
VALIDATION flights, the ``k``-th smallest score with ``k`` the larger of the marginal split-
conformal index ``ceil((n + 1)(1 - alpha))`` and the training-conditional (PAC) one, the least
``k`` with ``P(Binomial(n, 1 - alpha) <= k - 1) >= 1 - delta`` (``scipy.stats.binom``). A cell
with ``k > n``, or with fewer than :data:`MIN_CALIBRATION_TRACKS` distinct calibration tracks
(windows of one flight are far from exchangeable), is not calibrated: the env gives that class
the most conservative region. The test flights are never read here.

``--classes`` rebuilds only some classes' cells (the test of this script rebuilds the
helicopter and fixed-wing cells and compares them with the shipped table's; the full rebuild,
about 80 s on 2 shared cores, reproduces the shipped file byte for byte). A table of some
classes only is never written over the shipped one: with a subset, ``--out`` must name
another file (the run stops before building otherwise). It is not merged into the shipped
table either: the table's header (the dataset's provenance, the config, ``alpha``,
``delta``, the seeds) vouches for every cell, and cells of two builds under one header would
make it vouch for what it did not build; a class is added by the full rebuild.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import binom

from uasep_env import real_traffic
from uasep_env.config import EnvConfig, make_config
from uasep_env.config.groups import CALIBRATED_HORIZONS
from uasep_env.reachable.calibrated import (
    CENTRE_FRACTION,
    DEFAULT_TABLE,
    TABLE_FORMAT,
    TABLE_VERSION,
)
from uasep_env.runtime.jsonio import dumps, write_json  # noqa: F401 -- dumps: for the test
from uasep_env.sim.dynamics import measure
from uasep_env.sim.estimation import KalmanModel
from uasep_env.sim.obstacles import AIRCRAFT_TABLE, CALIBRATED_CLASSES, REAL_TRAFFIC_CLASSES
from uasep_env.sim.replay import track_velocities

ROOT = Path(__file__).resolve().parents[1]
ALPHA = 0.05
DELTA = 0.05
SEED = 0
WARMUP_S = 10.0
STRIDE_S = 1.0
#: Longest piece of a stretch filtered as one track (s): an episode's 200 s and a horizon.
PIECE_S = 240.0
#: Quantile levels tried for the base shape (the least median volume on training flights).
SHAPE_LEVELS = (0.5, 0.7, 0.85, 0.95, 0.99)
#: Training windows the shape search uses at most (evenly spaced).
SHAPE_WINDOWS = 3000
#: Synthetic (dubins) episodes per split and the first seed of each: inside the project's
#: training, validation and held-out (test) seed ranges (:mod:`uasep_env.scenarios.seeds`).
DUBINS_EPISODES = 400
#: Least distinct calibration tracks (episodes for dubins) for a cell to be calibrated: windows
#: of one flight are far from exchangeable, so a class seen in fewer is not calibrated on its
#: own and gets the most conservative region.
MIN_CALIBRATION_TRACKS = 5
DUBINS_SEEDS = {"train": 900_000, "validation": 4_000_000, "test": 5_000_000}
#: The classes calibrated, from the aircraft class table (uasep_env.sim.obstacles): each
#: row's ``source`` says where its paths come from (synthetic Dubins episodes or the
#: real-traffic dataset's tracks of that class).
CLASSES = CALIBRATED_CLASSES
REAL_CLASSES = REAL_TRAFFIC_CLASSES
_SOURCE = {c.name: c.source for c in AIRCRAFT_TABLE}


@dataclass
class Paths:
    """Obstacle paths with the env's estimates, one row per stretch or episode.

    Attributes:
        pos: ``(S, K, 3)`` true positions every ``dt`` (m, NED); NaN past a row's end.
        est_pos: ``(S, K, 3)`` estimated positions (m).
        est_vel: ``(S, K, 3)`` estimated ground velocities (m/s).
        length: ``(S,)`` samples of each row.
        source: ``(S,)`` dataset track index (negative for synthetic rows, one per obstacle).
    """

    pos: np.ndarray
    est_pos: np.ndarray
    est_vel: np.ndarray
    length: np.ndarray
    source: np.ndarray


def env_config() -> EnvConfig:
    """The configuration the table is calibrated for (the defaults)."""
    return EnvConfig()


def obstacle_filter(cfg: EnvConfig) -> KalmanModel:
    """The env's obstacle Kalman filter (:class:`uasep_env.sim.world.World`'s)."""
    return KalmanModel(
        cfg.dt,
        max(cfg.obstacle.speed * cfg.obstacle.max_turn_rate, 0.1),
        cfg.noise.obstacle_position_std,
        cfg.noise.obstacle_velocity_std,
    )


def inflation(cfg: EnvConfig) -> float:
    """The env's inflation with no wind: obstacle radius + 3 steady-state track stds (m)."""
    return cfg.obstacle.radius + 3.0 * obstacle_filter(cfg).steady_state_position_std()


def stretches(track: real_traffic.Track, max_gap: float, min_len: float) -> list[tuple]:
    """``(t_first, t_last)`` of the track's stretches without a gap over ``max_gap``."""
    t = track.times
    cuts = np.flatnonzero(np.diff(t) > max_gap)
    lo = np.concatenate([[0], cuts + 1])
    hi = np.concatenate([cuts, [len(t) - 1]])
    return [(t[a], t[b]) for a, b in zip(lo, hi, strict=True) if t[b] - t[a] >= min_len]


def real_paths(tracks: list[real_traffic.Track], cfg: EnvConfig, seed: int) -> Paths:
    """Every stretch of ``tracks`` resampled every ``dt`` and filtered as the env does."""
    dt = cfg.dt
    rows, src = [], []
    min_len = WARMUP_S + min(CALIBRATED_HORIZONS)
    for tr in tracks:
        for a, b in stretches(tr, cfg.obstacle.replay_max_gap, min_len):
            # Pieces of at most PIECE_S, each filtered from its start like an episode's track.
            for a0 in np.arange(a, b - min_len, PIECE_S):
                b0 = min(a0 + PIECE_S, b)
                times = a0 + dt * np.arange(int(np.floor((b0 - a0) / dt + 1e-9)) + 1)
                rows.append(
                    np.stack([np.interp(times, tr.times, tr.positions[:, i]) for i in range(3)], -1)
                )
                src.append(tr.index)
    return _filter(rows, np.array(src, dtype=np.int64), cfg, np.random.default_rng(seed))


def _filter(
    rows: list[np.ndarray], src: np.ndarray, cfg: EnvConfig, rng: np.random.Generator
) -> Paths:
    """Measure and Kalman filter padded rows (velocities: the replay's central differences)."""
    s = len(rows)
    length = np.array([len(r) for r in rows], dtype=np.int64)
    k_max = int(length.max()) if s else 0
    pos = np.full((s, k_max, 3), np.nan)
    vel = np.zeros((s, k_max, 3))
    for i, r in enumerate(rows):
        pos[i, : len(r)] = r
        vel[i, : len(r)] = track_velocities(r, cfg.dt)
    held = np.where(np.isnan(pos), pos[np.arange(s), length - 1][:, None, :], pos)
    kf = obstacle_filter(cfg)
    ps, pv = cfg.noise.obstacle_position_std, cfg.noise.obstacle_velocity_std
    est_p = np.empty_like(pos)
    est_v = np.empty_like(pos)
    ep = np.zeros((s, 1, 3))
    ev = np.zeros((s, 1, 3))
    for k in range(k_max):
        z = rng.standard_normal((s, 1, 6))
        mp, mv = measure(held[:, k, None], vel[:, k, None], ps * z[..., :3], pv * z[..., 3:])
        if k == 0:
            ep[...], ev[...] = mp, mv
        else:
            kf.update(ep, ev, None, mp, mv, np.full(s, k))
        est_p[:, k], est_v[:, k] = ep[:, 0], ev[:, 0]
    return Paths(pos, est_p, est_v, length, src)


def dubins_paths(split: str, cfg: EnvConfig, episodes: int = DUBINS_EPISODES) -> Paths:
    """The ``random`` family's obstacles over 200 s, estimated by the world itself."""
    from uasep_env.sim.world import World

    conf = make_config(scenario="random")
    world = World(conf, n_envs=episodes)
    world.reset(seed=DUBINS_SEEDS[split])
    steps = round(200.0 / conf.dt)
    m = world.n_obstacles
    pos = np.empty((episodes, m, steps + 1, 3))
    est_p, est_v = np.empty_like(pos), np.empty_like(pos)
    zero = np.zeros((episodes, world.n_uavs, 3))
    for k in range(steps + 1):
        if k:
            world.step(zero)
        pos[:, :, k] = world.obstacles.pos
        est_p[:, :, k] = world.obstacle_est_pos
        est_v[:, :, k] = world.obstacle_est_vel
    active = world.obstacles.active.reshape(-1)
    flat = lambda a: a.reshape(-1, steps + 1, 3)[active]  # noqa: E731
    n = int(active.sum())
    # Each synthetic obstacle is its own "track" (source), so the count of calibration tracks
    # is that of obstacles.
    src = -1 - np.arange(n, dtype=np.int64)
    return Paths(flat(pos), flat(est_p), flat(est_v), np.full(n, steps + 1), src)


@dataclass
class Windows:
    """Windows of one horizon: the estimate at ``t`` and the true path after it.

    Attributes:
        row: ``(W,)`` row of :class:`Paths`; ``k``: ``(W,)`` start sample.
        est_pos, est_vel: ``(W, 3)`` the estimate at the start.
    """

    row: np.ndarray
    k: np.ndarray
    est_pos: np.ndarray
    est_vel: np.ndarray


def windows(paths: Paths, horizon: float, dt: float) -> Windows:
    """A window every :data:`STRIDE_S` from :data:`WARMUP_S` on, with ``horizon`` ahead."""
    h = round(horizon / dt)
    stride, first = round(STRIDE_S / dt), round(WARMUP_S / dt)
    rows, ks = [], []
    for i, n in enumerate(paths.length):
        k = np.arange(first, int(n) - h, stride)
        rows.append(np.full(len(k), i))
        ks.append(k)
    row = np.concatenate(rows).astype(np.int64) if rows else np.zeros(0, np.int64)
    k = np.concatenate(ks).astype(np.int64) if ks else np.zeros(0, np.int64)
    return Windows(row, k, paths.est_pos[row, k], paths.est_vel[row, k])


def deviations(paths: Paths, win: Windows, horizon: float, mode: str, dt: float):  # noqa: ANN201
    """Yield each path point's ``(W, 3)`` offset from the centre (lon, lat, vertical)."""
    h = round(horizon / dt)
    centre = win.est_pos + (CENTRE_FRACTION[mode] * horizon) * win.est_vel
    psi = np.arctan2(win.est_vel[:, 1], win.est_vel[:, 0])
    c, s = np.cos(psi), np.sin(psi)
    steps = range(1, h + 1) if mode == "swept" else (h,)
    for j in steps:
        d = paths.pos[win.row, win.k + j] - centre
        yield np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], -1)


def base_shape(win: Windows, horizon: float, lam: np.ndarray, rho: float) -> np.ndarray:
    """``(W, 3)`` base semi-axes ``(lam0 v h/2 + rho, lam1 v h/2 + rho, lam2 h + rho)``."""
    v = np.hypot(win.est_vel[:, 0], win.est_vel[:, 1])
    half = 0.5 * v * horizon
    return np.stack(
        [lam[0] * half + rho, lam[1] * half + rho, np.full_like(v, lam[2] * horizon + rho)], -1
    )


def scores(
    paths: Paths, win: Windows, horizon: float, mode: str, dt: float, lam: np.ndarray, rho: float
) -> np.ndarray:
    """``(W,)`` normalised scores: the region ``q x base`` holds the path iff score <= q."""
    base = base_shape(win, horizon, lam, rho)
    out = np.zeros(len(win.row))
    for d in deviations(paths, win, horizon, mode, dt):
        np.maximum(out, np.sqrt(np.sum((d / base) ** 2, axis=-1)), out=out)
    return out


def fit_shape(
    paths: Paths, win: Windows, horizon: float, mode: str, dt: float, rho: float
) -> dict[str, Any]:
    """The base shape from the training windows: per-axis quantiles of the largest deviation."""
    dev = np.zeros((len(win.row), 3))
    for d in deviations(paths, win, horizon, mode, dt):
        np.maximum(dev, np.abs(d), out=dev)
    v = np.hypot(win.est_vel[:, 0], win.est_vel[:, 1])
    per = np.stack(
        [
            np.maximum(dev[:, 0] - rho, 0.0) / np.maximum(0.5 * v * horizon, 1e-9),
            np.maximum(dev[:, 1] - rho, 0.0) / np.maximum(0.5 * v * horizon, 1e-9),
            np.maximum(dev[:, 2] - rho, 0.0) / horizon,
        ],
        -1,
    )
    # Per-axis quantile levels on an even subsample of the windows (the shape only has to be
    # good; the guarantee comes from the validation quantile, whatever the shape).
    pick = np.unique(np.linspace(0, len(win.row) - 1, min(len(win.row), SHAPE_WINDOWS)).astype(int))
    sub = Windows(win.row[pick], win.k[pick], win.est_pos[pick], win.est_vel[pick])
    pts = list(deviations(paths, sub, horizon, mode, dt))
    best: dict[str, Any] | None = None
    for levels in itertools.product(SHAPE_LEVELS, repeat=3):
        lam = np.maximum([np.quantile(per[:, a], levels[a]) for a in range(3)], 1e-3)
        base = base_shape(sub, horizon, lam, rho)
        sc = np.zeros(len(pick))
        for d in pts:
            np.maximum(sc, np.sqrt(np.sum((d / base) ** 2, axis=-1)), out=sc)
        q = np.quantile(sc, 1.0 - ALPHA)
        vol = float(np.median(np.prod(q * base, axis=-1)))
        if best is None or vol < best["volume"]:
            best = {"level": list(levels), "lam": lam, "volume": vol}
    assert best is not None
    return best


def conformal_index(n: int, alpha: float = ALPHA, delta: float = DELTA) -> tuple[int, int]:
    """``(marginal k, PAC k)``: the order statistics of the two guarantees (1-based)."""
    k_marg = math.ceil((n + 1) * (1.0 - alpha))
    ks = np.arange(1, n + 2)
    ok = binom.cdf(ks - 1, n, 1.0 - alpha) >= 1.0 - delta
    k_pac = int(ks[np.argmax(ok)]) if ok.any() else n + 1
    return k_marg, k_pac


def _up(x: float) -> float:
    """Rounded up to 1e-6 (the table's resolution; rounding up only grows the region)."""
    return math.ceil(x * 1e6) / 1e6


def calibrate_cell(
    train: Paths, val: Paths, horizon: float, mode: str, cfg: EnvConfig
) -> dict[str, Any]:
    """One (class, mode, horizon) cell: shape on training windows, quantile on validation."""
    dt, rho = cfg.dt, inflation(cfg)
    w_tr, w_val = windows(train, horizon, dt), windows(val, horizon, dt)
    n = len(w_val.row)
    cell: dict[str, Any] = {
        "n_train_windows": len(w_tr.row),
        "n_calibration_windows": n,
        "calibration_tracks": len(set(val.source[w_val.row].tolist())),
    }
    if len(w_tr.row) < 20 or n < 1:
        return {**cell, "calibrated": False, "why": "too few windows"}
    if cell["calibration_tracks"] < MIN_CALIBRATION_TRACKS:
        why = f"{cell['calibration_tracks']} calibration tracks < {MIN_CALIBRATION_TRACKS}"
        return {**cell, "calibrated": False, "why": why}
    shape = fit_shape(train, w_tr, horizon, mode, dt, rho)
    sc = np.sort(scores(val, w_val, horizon, mode, dt, shape["lam"], rho))
    k_marg, k_pac = conformal_index(n)
    k = max(k_marg, k_pac)
    cell.update(k_marginal=k_marg, k_pac=k_pac, shape_level=shape["level"])
    if k > n:
        return {**cell, "calibrated": False, "why": f"k={k} > n={n} windows"}
    q = float(sc[k - 1])
    lam = shape["lam"]
    cell.update(
        calibrated=True,
        q=round(q, 9),
        longitudinal=[_up(q * lam[0] * 0.5 * horizon), _up(q * rho)],
        lateral=[_up(q * lam[1] * 0.5 * horizon), _up(q * rho)],
        vertical=[0.0, _up(q * (lam[2] * horizon + rho))],
    )
    return cell


def dataset_provenance() -> dict[str, Any]:
    """The dataset's version and digest."""
    path = real_traffic.DEFAULT_PATH
    ds = real_traffic.load()
    return {
        "file": path.name,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "format_version": real_traffic.FORMAT_VERSION,
        "source": ds.meta.get("source", ds.meta.get("traffic_version")),
    }


def build(
    classes: tuple[str, ...] = CLASSES, horizons: tuple[float, ...] = CALIBRATED_HORIZONS
) -> dict[str, Any]:
    """The table (a JSON-ready dict)."""
    cfg = env_config()
    ds = real_traffic.load()
    cells: dict[str, dict[str, dict[str, Any]]] = {m: {} for m in CENTRE_FRACTION}
    flights: dict[str, dict[str, list[str]]] = {}
    for cls in classes:
        if _SOURCE[cls] == "synthetic":
            tr_p, val_p = dubins_paths("train", cfg), dubins_paths("validation", cfg)
        else:
            tr_t, val_t = ds.select("train", cls), ds.select("validation", cls)
            flights[cls] = {
                "train": sorted({t.flight for t in tr_t}),
                "validation": sorted({t.flight for t in val_t}),
            }
            tr_p, val_p = real_paths(tr_t, cfg, SEED), real_paths(val_t, cfg, SEED + 1)
        for mode in CENTRE_FRACTION:
            cells[mode][cls] = {
                f"{h:g}": calibrate_cell(tr_p, val_p, h, mode, cfg) for h in horizons
            }
        print(f"{cls}: done", file=sys.stderr)
    return {
        "format": TABLE_FORMAT,
        "version": TABLE_VERSION,
        "built_by": "tools/build_prediction_calibration.py",
        "method": "split conformal per class, mode and horizon; shape on train, quantile on "
        "validation at max(marginal, PAC) order statistic",
        "alpha": ALPHA,
        "delta": DELTA,
        "seed": SEED,
        "warmup_s": WARMUP_S,
        "stride_s": STRIDE_S,
        "max_gap_s": cfg.obstacle.replay_max_gap,
        "horizons": list(horizons),
        "inflation_m": _up(inflation(cfg)),
        "config": {
            "dt": cfg.dt,
            "obstacle.radius": cfg.obstacle.radius,
            "noise.obstacle_position_std": cfg.noise.obstacle_position_std,
            "noise.obstacle_velocity_std": cfg.noise.obstacle_velocity_std,
            "prediction.kalman": cfg.prediction.kalman,
        },
        "dataset": dataset_provenance(),
        "flights": flights,
        "dubins": {"scenario": "random", "episodes": DUBINS_EPISODES, "seeds": DUBINS_SEEDS},
        "cells": cells,
    }


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=DEFAULT_TABLE)
    p.add_argument("--classes", default=",".join(CLASSES), help="comma-separated subset")
    args = p.parse_args(argv)
    classes = tuple(c for c in args.classes.split(",") if c)
    bad = [c for c in classes if c not in CLASSES]
    if bad or not classes:
        p.error(f"--classes: unknown class(es) {bad}; choose from {list(CLASSES)}")
    if set(classes) != set(CLASSES) and args.out.resolve() == DEFAULT_TABLE.resolve():
        p.error(
            f"--classes {','.join(classes)} builds a table of some classes only; it would "
            f"replace the shipped table {DEFAULT_TABLE} (every class): name another file "
            "with --out, or rebuild every class"
        )
    write_json(build(classes), args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
