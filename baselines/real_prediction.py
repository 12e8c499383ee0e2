"""Does the reachable-set prediction hold for real aircraft? Containment on recorded tracks.

For every recorded track of :mod:`uasep_env.real_traffic` and every recorded sample time
``t0`` with enough recorded future, the aircraft's state is estimated the way the env
estimates an obstacle's: measurements every ``config.dt`` with the configured obstacle noise
(``noise.obstacle_position_std``, ``noise.obstacle_velocity_std``), filtered by the env's
Kalman filter (:class:`uasep_env.sim.estimation.KalmanModel`, process noise
``max(v w_max, 0.1)`` as in the env, ``v`` the track's median ground speed). The reachable
ellipsoid (:func:`uasep_env.reachable.ellipsoid`, ``mode="swept"`` like the env's region:
every point reachable *within* the horizon) is placed on the estimate like the env places it
(centre ahead along the estimated heading, at the estimated height) with the env's inflation
(``obstacle.radius`` + 3 steady-state track standard deviations; no wind), and the speed
taken from the estimate. A window is *contained* when every real position of the aircraft in
``(t0, t0 + h]`` is inside: the recorded samples and the position at ``t0 + h`` interpolated
between the samples around it. The ellipsoid is convex, so this is the same as the whole
piecewise-linear recorded path being inside.

Measurements between samples are linearly interpolated, only over gaps of at most
``--max-gap`` seconds (12 by default: about the gliders' sampling; the fire-fighting
aircraft's ~20-30 s sampling leaves few usable stretches). A (class, horizon) pair is
reported only when the horizon is at least the class's median sample spacing within usable
stretches (shorter horizons would test interpolated chords rather than recorded positions)
and it has at least ``--min-windows`` windows.

Bounds: the config's (``obstacle.max_turn_rate``, ``obstacle.max_climb_rate``), and per class
the smallest common scale of both (on a sqrt(2) grid up to 4096) that contains 95 % of the
windows, with its volume. Speeds are rounded to 0.1 m/s to share ellipsoid fits.

    python baselines/real_prediction.py                      # table, json and figure
    python baselines/real_prediction.py --seed 1 --no-figure
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env import reachable, real_traffic
from uasep_env.config import EnvConfig
from uasep_env.real_traffic import Track
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.jsonio import write_json
from uasep_env.sim.estimation import KalmanModel

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_prediction_report import plot, render_markdown

ROOT = Path(__file__).resolve().parents[1]
HORIZONS = (5.0, 10.0, 20.0)
FITS = ("enclosing", "paper")
MAX_GAP_S = 12.0
WARMUP_S = 10.0
TARGET = 0.95
#: Bound scales tried for the fitted bounds: sqrt(2)^k, k = 0..24 (1 to 4096).
SCALES = tuple(2.0 ** (k / 2) for k in range(25))
_BLOCK = 512  # Kalman steps per block of interpolated measurements


@dataclass
class Windows:
    """Prediction windows of one horizon: the estimate at ``t0`` and the real path after it.

    Attributes:
        est_pos: ``(W, 3)`` estimated positions at ``t0`` (m, NED about the track's origin).
        est_vel: ``(W, 3)`` estimated velocities (m/s).
        points: ``(P, 3)`` real positions in ``(t0, t0 + h]`` (m).
        owner: ``(P,)`` window of each point, non-decreasing; every window has at least one.
        track: ``(W,)`` dataset index of each window's track.
    """

    est_pos: np.ndarray
    est_vel: np.ndarray
    points: np.ndarray
    owner: np.ndarray
    track: np.ndarray

    @property
    def n(self) -> int:
        """Number of windows."""
        return len(self.est_pos)


def _stretches(track: Track, max_gap: float) -> list[tuple[int, int]]:
    """``(first, last)`` sample indices of the stretches without a gap over ``max_gap``."""
    cuts = np.flatnonzero(np.diff(track.times) > max_gap)
    lo = np.concatenate([[0], cuts + 1])
    hi = np.concatenate([cuts, [len(track.times) - 1]])
    return [(int(a), int(b)) for a, b in zip(lo, hi, strict=True) if b > a]


def kalman_for(track: Track, cfg: EnvConfig) -> KalmanModel:
    """The env's obstacle filter for this aircraft (process noise from its median speed)."""
    speed = float(np.median(np.hypot(track.velocities[:, 0], track.velocities[:, 1])))
    nz = cfg.noise
    return KalmanModel(
        cfg.dt,
        max(speed * cfg.obstacle.max_turn_rate, 0.1),
        nz.obstacle_position_std,
        nz.obstacle_velocity_std,
    )


def estimate(
    track: Track, cfg: EnvConfig, rng: np.random.Generator, max_gap: float = MAX_GAP_S
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman estimates at every recorded sample time (NaN outside usable stretches).

    All stretches of the track are filtered at once (one env each), from their first sample,
    with measurements every ``cfg.dt``: the recorded position and reported velocity,
    interpolated, plus the configured obstacle noise (drawn from ``rng``).

    Returns:
        ``(est_pos, est_vel)``, each ``(n_samples, 3)``.
    """
    times = track.times
    n = len(times)
    est_p = np.full((n, 3), np.nan)
    est_v = np.full((n, 3), np.nan)
    spans = _stretches(track, max_gap)
    if not spans:
        return est_p, est_v
    dt = cfg.dt
    kf = kalman_for(track, cfg)
    first = np.array([a for a, _ in spans])
    last = np.array([b for _, b in spans])
    t_start, t_end = times[first], times[last]
    e = len(spans)
    steps = int(np.ceil(np.max(t_end - t_start) / dt + 1e-9)) + 1
    # Samples of the stretches, by the Kalman step that lands on them (times are whole ms).
    sample_env = np.concatenate([np.full(b - a + 1, i) for i, (a, b) in enumerate(spans)])
    sample_idx = np.concatenate([np.arange(a, b + 1) for a, b in spans])
    sample_step = np.rint((times[sample_idx] - t_start[sample_env]) / dt).astype(np.int64)
    on_grid = np.abs(t_start[sample_env] + sample_step * dt - times[sample_idx]) < 1e-6
    sample_env, sample_idx, sample_step = (
        sample_env[on_grid],
        sample_idx[on_grid],
        sample_step[on_grid],
    )
    order = np.argsort(sample_step, kind="stable")
    sample_env, sample_idx, sample_step = sample_env[order], sample_idx[order], sample_step[order]
    # One np.interp for every stretch: each on its own stretch of a common time axis.
    shift = (np.arange(e) * (np.max(t_end - t_start) + 10.0 * max_gap + 1.0))[:, None]
    flat_t = np.concatenate(
        [times[a : b + 1] - times[a] + shift[i, 0] for i, (a, b) in enumerate(spans)]
    )
    flat_x = np.concatenate(
        [np.hstack([track.positions[a : b + 1], track.velocities[a : b + 1]]) for a, b in spans]
    )
    ps, pv = cfg.noise.obstacle_position_std, cfg.noise.obstacle_velocity_std
    est_pos = np.zeros((e, 1, 3))
    est_vel = np.zeros((e, 1, 3))
    ptr = 0
    for b0 in range(0, steps, _BLOCK):
        k = np.arange(b0, min(b0 + _BLOCK, steps))
        q = np.minimum(k[None, :] * dt, (t_end - t_start)[:, None]) + shift  # (e, K)
        truth = np.stack([np.interp(q, flat_t, flat_x[:, j]) for j in range(6)], axis=-1)
        noise = rng.standard_normal((len(k), e, 6))
        for j, step in enumerate(k):
            mp = truth[:, j, None, :3] + ps * noise[j, :, None, :3]
            mv = truth[:, j, None, 3:] + pv * noise[j, :, None, 3:]
            if step == 0 or not cfg.prediction.kalman:
                est_pos[...], est_vel[...] = mp, mv
            else:
                kf.update(est_pos, est_vel, None, mp, mv, np.full(e, step))
            stop = np.searchsorted(sample_step, step, side="right")
            if stop > ptr:
                envs, idx = sample_env[ptr:stop], sample_idx[ptr:stop]
                est_p[idx], est_v[idx] = est_pos[envs, 0], est_vel[envs, 0]
                ptr = stop
    return est_p, est_v


def windows(
    track: Track,
    est_pos: np.ndarray,
    est_vel: np.ndarray,
    horizon: float,
    max_gap: float = MAX_GAP_S,
    warmup: float = WARMUP_S,
) -> Windows:
    """The prediction windows of one track at one horizon.

    A window starts at a recorded sample with an estimate, at least ``warmup`` after its
    stretch's start, and whose stretch lasts at least ``horizon`` more.
    """
    times = track.times
    ep, ev, pts, own, trk = [], [], [], [], []
    w = 0
    for a, b in _stretches(track, max_gap):
        t_a, t_b = times[a], times[b]
        for i in range(a, b + 1):
            t0 = times[i]
            if t0 < t_a + warmup or t0 + horizon > t_b or not np.isfinite(est_pos[i, 0]):
                continue
            j = int(np.searchsorted(times, t0 + horizon, side="right"))  # first after t0+h
            inside = track.positions[i + 1 : j]
            end = np.array(
                [
                    np.interp(t0 + horizon, times[a : b + 1], track.positions[a : b + 1, ax])
                    for ax in range(3)
                ]
            )
            # The position at t0 + h, unless a sample is exactly there.
            p = inside if times[j - 1] == t0 + horizon else np.vstack([inside, end[None]])
            ep.append(est_pos[i])
            ev.append(est_vel[i])
            pts.append(p)
            own.append(np.full(len(p), w))
            trk.append(track.index)
            w += 1
    if not w:
        z3 = np.zeros((0, 3))
        return Windows(z3, z3, z3, np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    return Windows(np.array(ep), np.array(ev), np.vstack(pts), np.concatenate(own), np.array(trk))


def concat(parts: Sequence[Windows]) -> Windows:
    """One :class:`Windows` from several (window numbers shifted)."""
    offsets = np.cumsum([0, *[p.n for p in parts]])
    return Windows(
        np.vstack([p.est_pos for p in parts]) if parts else np.zeros((0, 3)),
        np.vstack([p.est_vel for p in parts]) if parts else np.zeros((0, 3)),
        np.vstack([p.points for p in parts]) if parts else np.zeros((0, 3)),
        np.concatenate([p.owner + o for p, o in zip(parts, offsets, strict=False)])
        if parts
        else np.zeros(0, dtype=int),
        np.concatenate([p.track for p in parts]) if parts else np.zeros(0, dtype=int),
    )


def inflation(cfg: EnvConfig, kf: KalmanModel) -> float:
    """The env's radius around the reachable set: ``obstacle.radius`` + 3 track stds (m)."""
    return cfg.obstacle.radius + 3.0 * kf.steady_state_position_std()


def contained(
    win: Windows,
    horizon: float,
    turn_rate: float,
    climb_rate: float,
    radius: np.ndarray,
    fit: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Whether each window's real path is inside its predicted ellipsoid, and its volume.

    Args:
        win: The windows.
        horizon: Prediction horizon (s).
        turn_rate: ``w_max`` (rad/s).
        climb_rate: ``vz_max`` (m/s).
        radius: ``(W,)`` inflation per window (m).
        fit: ``"enclosing"`` or ``"paper"``.

    Returns:
        ``(inside (W,) bool, volume (W,) m^3)``.
    """
    speed = np.round(np.hypot(win.est_vel[:, 0], win.est_vel[:, 1]), 1)
    heading = np.arctan2(win.est_vel[:, 1], win.est_vel[:, 0])
    key = np.stack([speed, np.round(radius, 3)], axis=-1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    off_u, axes_u = reachable.ellipsoid(
        uniq[:, 0], turn_rate, climb_rate, horizon, uniq[:, 1], mode="swept", fit=fit
    )
    off, axes = np.asarray(off_u)[inv], axes_u[inv]
    center = win.est_pos.copy()
    center[:, 0] += off * np.cos(heading)
    center[:, 1] += off * np.sin(heading)
    o = win.owner
    inside_pt = reachable.contains(win.points, center[o], axes[o], heading[o])
    starts = np.flatnonzero(np.r_[True, o[1:] != o[:-1]])
    inside = np.logical_and.reduceat(inside_pt, starts)
    volume = (4.0 / 3.0) * np.pi * np.prod(axes, axis=-1)
    return inside, volume


def validate_track(
    track: Track,
    cfg: EnvConfig,
    seed: int = 0,
    horizons: Sequence[float] = HORIZONS,
    max_gap: float = MAX_GAP_S,
) -> dict[str, dict[str, Any]]:
    """Containment of the default-bound prediction on one track (the script's core).

    Returns:
        ``{str(horizon): {"windows": n, "<fit>": containment fraction or None, ...}}``.
    """
    rng = np.random.default_rng([seed, track.index])
    est_p, est_v = estimate(track, cfg, rng, max_gap)
    kf = kalman_for(track, cfg)
    out: dict[str, dict[str, Any]] = {}
    for h in horizons:
        win = windows(track, est_p, est_v, h, max_gap)
        row: dict[str, Any] = {"windows": win.n}
        for fit in FITS:
            if win.n:
                ins, vol = contained(
                    win,
                    h,
                    cfg.obstacle.max_turn_rate,
                    cfg.obstacle.max_climb_rate,
                    np.full(win.n, inflation(cfg, kf)),
                    fit,
                )
                row[fit] = float(ins.mean())
                row[f"{fit}_volume_m3"] = float(np.median(vol))
            else:
                row[fit] = row[f"{fit}_volume_m3"] = None
        out[f"{h:g}"] = row
    return out


def _observed(tracks: Sequence[Track], max_gap: float) -> dict[str, float]:
    """What the class does: median speed, 95th percentiles of |turn rate| and |vertical speed|."""
    speed, turn, climb, spacing = [], [], [], []
    for tr in tracks:
        v = tr.velocities
        gs = np.hypot(v[:, 0], v[:, 1])
        speed.append(gs)
        climb.append(np.abs(v[:, 2]))
        dt = np.diff(tr.times)
        ok = (dt <= max_gap) & (gs[1:] > 5.0) & (gs[:-1] > 5.0)
        psi = np.arctan2(v[:, 1], v[:, 0])
        dpsi = np.angle(np.exp(1j * np.diff(psi)))
        turn.append(np.abs(dpsi[ok]) / dt[ok])
        spacing.append(dt[dt <= max_gap])
    cat = np.concatenate
    return {
        "median_speed_m_s": float(np.median(cat(speed))),
        "p95_turn_rate_rad_s": float(np.percentile(cat(turn), 95)) if len(cat(turn)) else math.nan,
        "p95_vertical_speed_m_s": float(np.percentile(cat(climb), 95)),
        "median_spacing_s": float(np.median(cat(spacing))) if len(cat(spacing)) else math.inf,
    }


def evaluate_class(
    tracks: Sequence[Track],
    cfg: EnvConfig,
    seed: int,
    horizons: Sequence[float] = HORIZONS,
    max_gap: float = MAX_GAP_S,
    min_windows: int = 100,
) -> dict[str, Any]:
    """Containment and volume per horizon and fit, default and fitted bounds, for one class."""
    obs = _observed(tracks, max_gap)
    per_h: dict[float, list[Windows]] = {h: [] for h in horizons}
    radii: dict[float, list[np.ndarray]] = {h: [] for h in horizons}
    errors = []
    for tr in tracks:
        est_p, est_v = estimate(tr, cfg, np.random.default_rng([seed, tr.index]), max_gap)
        err = np.linalg.norm(est_p - tr.positions, axis=1)
        errors.append(err[np.isfinite(err)])
        r = inflation(cfg, kalman_for(tr, cfg))
        for h in horizons:
            win = windows(tr, est_p, est_v, h, max_gap)
            per_h[h].append(win)
            radii[h].append(np.full(win.n, r))
    err = np.concatenate(errors)
    # How far the env's filter is from the recorded position at the sample times (m).
    obs["median_estimate_error_m"] = float(np.median(err)) if len(err) else math.nan
    w0, vz0 = cfg.obstacle.max_turn_rate, cfg.obstacle.max_climb_rate
    rows = []
    for h in horizons:
        win = concat(per_h[h])
        row: dict[str, Any] = {"horizon_s": h, "windows": win.n, "tracks": len(set(win.track))}
        if h < obs["median_spacing_s"]:
            row["excluded"] = f"horizon < median sample spacing {obs['median_spacing_s']:g} s"
        elif win.n < min_windows:
            row["excluded"] = f"fewer than {min_windows} windows"
        if "excluded" in row:
            rows.append(row)
            continue
        radius = np.concatenate(radii[h])
        # Diagnostic: the real path with its heights replaced by the estimate's (horizontal only).
        flat = Windows(win.est_pos, win.est_vel, win.points.copy(), win.owner, win.track)
        flat.points[:, 2] = win.est_pos[win.owner, 2]
        ins, _ = contained(flat, h, w0, vz0, radius, "enclosing")
        row["enclosing_horizontal"] = float(ins.mean())
        for fit in FITS:
            ins, vol = contained(win, h, w0, vz0, radius, fit)
            row[fit] = {"containment": float(ins.mean()), "median_volume_m3": float(np.median(vol))}
            fitted: dict[str, Any] = {"scale": None}
            for s in SCALES:
                ins, vol = contained(win, h, w0 * s, vz0 * s, radius, fit)
                fitted = {
                    "scale": s,
                    "turn_rate_rad_s": w0 * s,
                    "climb_rate_m_s": vz0 * s,
                    "containment": float(ins.mean()),
                    "median_volume_m3": float(np.median(vol)),
                }
                if ins.mean() >= TARGET:
                    break
            else:
                fitted["reached"] = False
            fitted.setdefault("reached", True)
            row[f"{fit}_fitted"] = fitted
        rows.append(row)
    return {"tracks": len(tracks), "observed": obs, "horizons": rows}


def run(seed: int = 0, max_gap: float = MAX_GAP_S, min_windows: int = 100) -> dict[str, Any]:
    """Every class of the shipped dataset (all splits): the results written by :func:`main`."""
    cfg = EnvConfig()
    out: dict[str, Any] = {
        "seed": seed,
        "max_gap_s": max_gap,
        "warmup_s": WARMUP_S,
        "target": TARGET,
        "mode": "swept",
        "config": {
            "dt": cfg.dt,
            "obstacle.max_turn_rate": cfg.obstacle.max_turn_rate,
            "obstacle.max_climb_rate": cfg.obstacle.max_climb_rate,
            "obstacle.radius": cfg.obstacle.radius,
            "noise.obstacle_position_std": cfg.noise.obstacle_position_std,
            "noise.obstacle_velocity_std": cfg.noise.obstacle_velocity_std,
        },
        "classes": {},
    }
    for cls in real_traffic.CLASSES:
        trs = real_traffic.tracks(aircraft_class=cls)
        out["classes"][cls] = evaluate_class(trs, cfg, seed, HORIZONS, max_gap, min_windows)
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="measurement-noise seed")
    parser.add_argument("--max-gap", type=float, default=MAX_GAP_S, help="interpolation limit (s)")
    parser.add_argument("--min-windows", type=int, default=100, help="windows to report a pair")
    parser.add_argument("--out-dir", type=Path, default=ROOT / "baselines" / "results")
    parser.add_argument(
        "--figure", type=Path, default=ROOT / "docs" / "figures" / "real_prediction.png"
    )
    parser.add_argument("--no-figure", action="store_true", help="skip the figure")
    args = parser.parse_args(argv)
    if not (0.0 < args.max_gap <= 60.0):
        parser.error(f"--max-gap must be in (0, 60] s, got {args.max_gap}")
    if args.min_windows < 1:
        parser.error(f"--min-windows must be positive, got {args.min_windows}")
    res = run(args.seed, args.max_gap, args.min_windows)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    write_json(res, args.out_dir / "real_prediction.json")
    md = atomic_write(args.out_dir / "real_prediction.md", render_markdown(res))
    if not args.no_figure:
        plot(res, args.figure)
    print(md.read_text(encoding="utf-8").split("## Containment")[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
