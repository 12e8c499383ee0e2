"""The real-traffic prediction check (``baselines/real_prediction.py``) on single tracks."""

import sys
from pathlib import Path

import numpy as np
import pytest

from uasep_env import real_traffic as rt
from uasep_env.config import EnvConfig

BASELINES = Path(__file__).resolve().parents[1] / "baselines"
sys.path.insert(0, str(BASELINES))

import real_prediction as rp  # noqa: E402


def _synthetic(turn_rate: float, speed: float = 30.0, climb: float = 0.0) -> rt.Track:
    """A track flown exactly at constant speed, turn rate and climb, sampled every second."""
    t = np.arange(0.0, 200.0, 1.0)
    psi = turn_rate * t
    if turn_rate:
        x, y = speed / turn_rate * np.sin(psi), speed / turn_rate * (1 - np.cos(psi))
    else:
        x, y = speed * t, 0.0 * t
    pos = np.stack([x, y, -climb * t], -1)
    vel = np.stack([speed * np.cos(psi), speed * np.sin(psi), np.full_like(t, -climb)], -1)
    return rt.Track(
        times=t, positions=pos, velocities=vel, source="synthetic", icao24="000000",
        callsign="TEST", first_timestamp=0.0, origin=(0.0, 0.0, 0.0),
        aircraft_class="glider", class_rule="test", split="test", flight="synthetic", index=0,
    )  # fmt: skip


def test_straight_flight_is_contained_and_circling_is_not():
    cfg = EnvConfig()
    straight = rp.validate_track(_synthetic(0.0), cfg, seed=0, horizons=(10.0,))["10"]
    assert straight["windows"] == 200 - 10 - 10  # warm-up and the last horizon
    assert straight["enclosing"] >= 0.95
    # A 0.2 rad/s thermal circle is 15x the default turn-rate bound: mostly outside.
    circling = rp.validate_track(_synthetic(0.2), cfg, seed=0, horizons=(10.0,))["10"]
    assert circling["enclosing"] < 0.3
    # A 3 m/s climb leaves the 0.5 m/s vertical bound within 10 s.
    climbing = rp.validate_track(_synthetic(0.0, climb=3.0), cfg, seed=0, horizons=(10.0,))
    assert climbing["10"]["enclosing"] < 0.05


def test_one_real_track_runs_deterministically():
    cfg = EnvConfig()
    track = max(rt.tracks(aircraft_class="helicopter"), key=lambda t: len(t.times))
    a = rp.validate_track(track, cfg, seed=1, horizons=(5.0, 20.0))
    assert a == rp.validate_track(track, cfg, seed=1, horizons=(5.0, 20.0))
    for row in a.values():
        assert row["windows"] > 100
        for fit in rp.FITS:
            assert 0.0 <= row[fit] <= 1.0 and row[f"{fit}_volume_m3"] > 0.0
    assert a["20"]["enclosing_volume_m3"] > a["5"]["enclosing_volume_m3"]


def test_windows_hold_the_recorded_path_after_t0():
    cfg = EnvConfig()
    track = _synthetic(0.0)
    est_p, est_v = rp.estimate(track, cfg, np.random.default_rng(0))
    win = rp.windows(track, est_p, est_v, 5.0)
    first = win.points[win.owner == 0]
    # t0 = 10 s: the samples at 11..15 s; the last is the position at t0 + h.
    assert np.allclose(first[:, 0], 30.0 * np.arange(11, 16))
    assert np.all(np.abs(est_p[10:] - track.positions[10:]) < 15.0)  # the filter tracks


def test_class_table_and_exclusions():
    cfg = EnvConfig()
    tracks = rt.tracks(split="test", aircraft_class="helicopter")
    res = rp.evaluate_class(tracks, cfg, seed=0, horizons=(0.5, 10.0), min_windows=10)
    rows = {r["horizon_s"]: r for r in res["horizons"]}
    assert "median sample spacing" in rows[0.5]["excluded"]
    ten = rows[10.0]
    assert ten["enclosing_fitted"]["reached"]
    assert ten["enclosing_fitted"]["containment"] >= rp.TARGET
    assert ten["enclosing_fitted"]["scale"] >= 1.0
    if ten["enclosing"]["containment"] < rp.TARGET:
        assert ten["enclosing_fitted"]["median_volume_m3"] > ten["enclosing"]["median_volume_m3"]
    md = rp.render_markdown({"seed": 0, "target": rp.TARGET, "config": {
        "obstacle.max_turn_rate": 0.013, "obstacle.max_climb_rate": 0.5}, "classes": {
        "helicopter": res}})  # fmt: skip
    assert "## Summary" in md and "| helicopter | 10 |" in md and "| helicopter | 0.5 |" in md


def test_bad_arguments_are_named():
    with pytest.raises(SystemExit):
        rp.main(["--max-gap", "0"])
