"""The shipped real-traffic dataset: loader, provenance, units, split, bad files, the build."""

import gzip
import io
import json
import os
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from uasep_env import real_traffic as rt
from uasep_env.real_traffic import build as rtb
from uasep_env.real_traffic import fileformat as rtf
from uasep_env.real_traffic.geodesy import ecef, ned_about

ROOT = Path(__file__).resolve().parents[1]
WHEEL = Path(os.environ.get("UASEP_TRAFFIC_WHEEL", "/tmp/trafficdl/traffic-2.13-py3-none-any.whl"))


# ------------------------------------------------------------------ loader and provenance
def test_tracks_are_typed_read_only_and_start_at_their_origin():
    tracks = rt.tracks()
    assert len(tracks) >= 100
    for tr in tracks:
        n = len(tr.times)
        assert n >= rtb.MIN_SAMPLES
        assert tr.positions.shape == (n, 3) and tr.velocities.shape == (n, 3)
        assert tr.times[0] == 0.0 and np.all(np.diff(tr.times) > 0)
        assert np.all(np.diff(tr.times) <= rtb.GAP_S)  # split at gaps
        assert np.allclose(tr.positions[0], 0.0)
        assert not tr.positions.flags.writeable
        assert tr.timestamps[0] == tr.first_timestamp
    with pytest.raises(ValueError):
        tracks[0].positions[0, 0] = 1.0


def test_provenance_fields():
    meta = rt.load().meta
    assert meta["source"]["package"] == "traffic" and meta["source"]["version"] == "2.13"
    assert set(meta["source"]["sample_sha256"]) == set(rtb.SAMPLES)
    for tr in rt.tracks():
        assert tr.source.startswith("traffic/data/samples/") and tr.source.endswith(".json.gz")
        assert tr.source[len("traffic/data/samples/") : -len(".json.gz")] in rtb.SAMPLES
        assert len(tr.icao24) == 6 and int(tr.icao24, 16) >= 0
        assert tr.callsign
        assert 1.5e9 < tr.first_timestamp < 1.7e9  # 2017-2023
        lat, lon, alt = tr.origin
        assert -90 <= lat <= 90 and -180 <= lon <= 180 and -700 < alt < 14000
        assert tr.aircraft_class in rt.CLASSES and tr.class_rule
        assert tr.flight.endswith(f":{tr.icao24}")
    classes = {tr.source.split("/")[3]: set() for tr in rt.tracks()}
    for tr in rt.tracks():
        classes[tr.source.split("/")[3]].add(tr.aircraft_class)
    assert classes["gliders"] == {"glider"} and classes["ambulances"] == {"helicopter"}


@pytest.mark.parametrize(
    ("cls", "lo", "hi"), [("glider", 15, 60), ("helicopter", 20, 90), ("fixed_wing", 35, 130)]
)
def test_speeds_are_physical_and_positions_match_reported_velocities(cls, lo, hi):
    tracks = rt.tracks(aircraft_class=cls)
    gs = np.concatenate([np.hypot(t.velocities[:, 0], t.velocities[:, 1]) for t in tracks])
    assert lo < np.median(gs) < hi  # m/s
    assert np.percentile(gs, 99.9) < rtb.MAX_SPEED
    assert np.percentile(np.abs(np.concatenate([t.velocities[:, 2] for t in tracks])), 99) < 30
    # Units agree: displacement over a short interval ~ the mean reported velocity (m, s):
    # within 1 % for gliders and helicopters; the fire-fighting aircraft move ~11 % more
    # than their reported ground speed says (a property of that recording, docs/real_traffic.md).
    ratios = []
    for t in tracks:
        dt = np.diff(t.times)
        ok = dt <= 12
        moved = np.linalg.norm(np.diff(t.positions[:, :2], axis=0), axis=1)[ok]
        mean_v = 0.5 * (t.velocities[1:, :2] + t.velocities[:-1, :2])[ok]
        ratios.append(moved / np.maximum(np.linalg.norm(mean_v, axis=1) * dt[ok], 1e-9))
    tol = 0.15 if cls == "fixed_wing" else 0.02
    assert abs(np.median(np.concatenate(ratios)) - 1.0) < tol


# ------------------------------------------------------------------ split
def test_split_is_by_flight_disjoint_complete_and_covers_every_class_in_test():
    tracks = rt.tracks()
    per_split = {s: rt.tracks(split=s) for s in rt.SPLITS}
    assert sum(len(v) for v in per_split.values()) == len(tracks)
    ids = [tr.index for v in per_split.values() for tr in v]
    assert sorted(ids) == list(range(len(tracks)))  # each track in exactly one split
    flights = {s: {tr.flight for tr in v} for s, v in per_split.items()}
    assert not (flights["train"] & flights["test"])
    assert not (flights["train"] & flights["validation"])
    assert not (flights["validation"] & flights["test"])
    for cls in rt.CLASSES:
        assert rt.tracks(split="test", aircraft_class=cls), cls
        assert all(tr.split == "test" for tr in rt.tracks(split="test", aircraft_class=cls))
    # The stored split is the documented rule applied to the stored flights.
    units: dict = {}
    for tr in tracks:
        c, n = units.get(tr.flight, (tr.aircraft_class, 0))
        units[tr.flight] = (c, n + len(tr.times))
    rule = rtb.assign_splits(units)
    assert all(rule[tr.flight] == tr.split for tr in tracks)


def test_assign_splits_gives_test_then_validation_first():
    units = {f"f{i}": ("glider", 10 * (i + 1)) for i in range(5)} | {"h": ("helicopter", 3)}
    out = rtb.assign_splits(units)
    assert out["h"] == "test"
    assert {out[f"f{i}"] for i in range(5)} == set(rt.SPLITS)
    assert out == rtb.assign_splits(dict(reversed(units.items())))  # order-free


def test_draw_segments_is_deterministic_and_respects_the_selection():
    ds = rt.load()
    a = ds.draw_segments(np.random.default_rng(3), 8, 30.0, 0.5, split="test")
    b = ds.draw_segments(np.random.default_rng(3), 8, 30.0, 0.5, split="test")
    assert a.positions.shape == (8, 61, 3)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.track, b.track)
    assert all(ds.tracks[i].split == "test" for i in a.track)
    tr = ds.tracks[int(a.track[0])]
    assert np.allclose(a.positions[0, 0, 0], np.interp(a.start[0], tr.times, tr.positions[:, 0]))
    with pytest.raises(ValueError, match="n must be"):
        ds.draw_segments(np.random.default_rng(0), 0, 30.0, 0.5)
    with pytest.raises(ValueError, match="duration"):
        ds.draw_segments(np.random.default_rng(0), 1, -1.0, 0.5)
    with pytest.raises(ValueError, match="no test-split"):
        ds.draw_segments(np.random.default_rng(0), 1, 1e6, 0.5, split="test")


# ------------------------------------------------------------------ bad input
def test_unknown_selection_values_and_keywords():
    with pytest.raises(ValueError, match="'testing'"):
        rt.tracks(split="testing")
    with pytest.raises(ValueError, match="'plane'"):
        rt.tracks(aircraft_class="plane")
    with pytest.raises(TypeError):
        rt.tracks(splt="test")


def test_missing_file_is_named(tmp_path):
    path = tmp_path / "nope.npz"
    with pytest.raises(FileNotFoundError, match=r"nope\.npz"):
        rt.tracks(path=path)


def test_corrupt_file_is_named(tmp_path):
    path = tmp_path / "bad.npz"
    path.write_bytes(b"not a zip at all" * 10)
    with pytest.raises(rt.RealTrafficFileError, match=r"bad\.npz"):
        rt.RealTrafficDataset(path)
    # A truncated copy of the real file.
    path.write_bytes(rt.DEFAULT_PATH.read_bytes()[:5000])
    with pytest.raises(rt.RealTrafficFileError, match=r"bad\.npz"):
        rt.RealTrafficDataset(path)


def _rewrite(src: Path, dst: Path, replace: dict) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for name in zin.namelist():
            data = replace.get(name, zin.read(name))
            zout.writestr(name, data)


def _npy(arr, allow_pickle=False) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr, allow_pickle=allow_pickle)
    return buf.getvalue()


def test_other_format_version_is_named(tmp_path):
    path = tmp_path / "v9.npz"
    _rewrite(rt.DEFAULT_PATH, path, {"format_version.npy": _npy(np.int64(9))})
    with pytest.raises(rt.RealTrafficFileError, match=r"v9\.npz.*format_version 9"):
        rt.RealTrafficDataset(path)
    # Another version may hold other members: still named by its version, not as corrupt.
    with zipfile.ZipFile(path, "a") as z:
        z.writestr("heading_cdeg.npy", _npy(np.zeros(3, np.int32)))
    with pytest.raises(rt.RealTrafficFileError, match=r"v9\.npz.*format_version 9"):
        rt.RealTrafficDataset(path)


def test_pickled_member_is_refused_not_loaded(tmp_path):
    path = tmp_path / "pickle.npz"
    obj = np.array([{"evil": 1}], dtype=object)
    _rewrite(rt.DEFAULT_PATH, path, {"meta.npy": _npy(obj, allow_pickle=True)})
    with pytest.raises(rt.RealTrafficFileError, match="meta"):
        rt.RealTrafficDataset(path)


def test_inconsistent_arrays_are_refused(tmp_path):
    path = tmp_path / "short.npz"
    _rewrite(rt.DEFAULT_PATH, path, {"time_ms.npy": _npy(np.arange(5, dtype=np.int64))})
    with pytest.raises(rt.RealTrafficFileError, match=r"short\.npz"):
        rt.RealTrafficDataset(path)


def test_size_limits_bound_memory(tmp_path, monkeypatch):
    monkeypatch.setattr(rtf, "MAX_MEMBER_BYTES", 1000)
    with pytest.raises(rt.RealTrafficFileError, match="limit"):
        rt.RealTrafficDataset(rt.DEFAULT_PATH)
    # A member whose header claims a small size but inflates to more is cut at the limit.
    path = tmp_path / "bomb.npz"
    _rewrite(rt.DEFAULT_PATH, path, {})
    monkeypatch.setattr(rtf, "MAX_FILE_BYTES", 100)
    with pytest.raises(rt.RealTrafficFileError, match=r"bomb\.npz"):
        rt.RealTrafficDataset(path)


def test_zip_directory_is_checked_before_inflating(tmp_path):
    # The checks the policy checkpoints have (uasep_env.runtime.boundedzip): a duplicate or an
    # unexpected member, and a member that inflates far more than data does.
    dup = tmp_path / "dup.npz"
    _rewrite(rt.DEFAULT_PATH, dup, {})
    with zipfile.ZipFile(dup, "a") as z, pytest.warns(UserWarning, match="Duplicate name"):
        z.writestr("meta.npy", _npy(np.zeros(3, np.uint8)))
    with pytest.raises(rt.RealTrafficFileError, match=r"dup\.npz: duplicate member"):
        rt.RealTrafficDataset(dup)
    extra = tmp_path / "extra.npz"
    _rewrite(rt.DEFAULT_PATH, extra, {})
    with zipfile.ZipFile(extra, "a") as z:
        z.writestr("payload.npy", b"x")
    with pytest.raises(rt.RealTrafficFileError, match=r"unexpected member.*payload"):
        rt.RealTrafficDataset(extra)
    bomb = tmp_path / "ratio.npz"
    zeros = _npy(np.zeros(2_000_000, np.int64))  # 16 MB that deflate to ~16 KB
    with zipfile.ZipFile(rt.DEFAULT_PATH) as zin, zipfile.ZipFile(bomb, "w") as zout:
        for name in zin.namelist():
            data = zeros if name == "time_ms.npy" else zin.read(name)
            zout.writestr(name, data, compress_type=zipfile.ZIP_DEFLATED)
    with pytest.raises(rt.RealTrafficFileError, match=r"time_ms\.npy: compression ratio"):
        rt.RealTrafficDataset(bomb)


# ------------------------------------------------------------------ build
def test_geodesy_round_numbers():
    # At the equator 0.01 deg of latitude is M * 0.01 deg (M = a (1 - e^2), the meridian
    # radius), 0.01 deg of longitude a * 0.01 deg; straight up is minus down.
    ned = ned_about([0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 100.0], (0.0, 0.0, 0.0))
    rad = np.radians(0.01)
    assert abs(ned[0, 0] - 6335439.327 * rad) < 0.01 and abs(ned[0, 1]) < 1e-6
    assert abs(ned[1, 1] - 6378137.0 * rad) < 0.01 and abs(ned[1, 0]) < 1e-6
    assert np.allclose(ned[2], [0.0, 0.0, -100.0], atol=1e-6)
    assert np.isclose(np.linalg.norm(ecef(0.0, 0.0, 0.0)), 6378137.0)


def _fake_sample(seed: int = 0) -> bytes:
    """A glider-like file: 200 s at 4 s, a spike, a stale repeat, a 100 s gap, 150 s more."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([np.arange(0, 200, 4), np.arange(300, 452, 4)]) * 1000 + 1558600000000
    recs = []
    for i, ms in enumerate(t):
        s = (ms - t[0]) / 1000.0
        recs.append(
            {
                "icao24": "3c0001",
                "callsign": "D-TEST",
                "timestamp": int(ms),
                "latitude": 45.0 + 30.0 * s / 111000.0,
                "longitude": 5.0 + float(rng.normal(0, 1e-6)),
                "altitude": 3000.0 + s,
                "groundspeed": 58.0,
                "track": 0.0,
                "vertical_rate": 60.0,
            }
        )
        if i == 10:
            recs[-1]["latitude"] += 0.5  # a 55 km spike
    recs.insert(21, dict(recs[20], timestamp=recs[20]["timestamp"] + 1000))  # stale repeat
    recs.append({"icao24": "3c0001", "timestamp": int(t[-1]) + 4000})  # missing fields
    return gzip.compress(json.dumps(recs).encode(), mtime=0)


def test_build_is_deterministic_and_applies_the_rules(tmp_path):
    raw = _fake_sample()
    arrays, meta = rtb.build({"gliders/luberon": raw}, {"package": "test"})
    dropped = meta["dropped"]["gliders/luberon"]
    assert dropped["spike"] == 1 and dropped["stale"] == 1 and dropped["missing_field"] == 1
    assert len(meta["tracks"]) == 2  # cut at the 100 s gap
    assert [m["n_samples"] for m in meta["tracks"]] == [49, 38]
    first = meta["tracks"][0]
    assert first["icao24"] == "3c0001" and first["callsign"] == "D-TEST"
    assert first["first_timestamp_ms"] == 1558600000000 and first["aircraft_class"] == "glider"
    pos = arrays["pos_cm"][: arrays["track_start"][1]] / 100.0
    dt = np.diff(arrays["time_ms"][: arrays["track_start"][1]]) / 1000.0
    assert np.allclose(np.diff(pos[:, 0]) / dt, 30.0, atol=0.5)  # 30 m/s north
    # 1 ft/s up, less the tangent plane leaving the curved Earth (v^2 t / R < 0.03 m/s).
    assert np.allclose(np.diff(pos[:, 2]) / dt, -0.3048, atol=0.04)
    vel = arrays["vel_cms"][: arrays["track_start"][1]] / 100.0
    assert np.allclose(vel, [58 * 1852 / 3600, 0.0, -0.3048], atol=0.04)  # kt, ft/min
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    rtf.write_npz(a, arrays, meta)
    arrays2, meta2 = rtb.build({"gliders/luberon": raw}, {"package": "test"})
    rtf.write_npz(b, arrays2, meta2)
    assert a.read_bytes() == b.read_bytes()
    ds = rt.RealTrafficDataset(a)
    assert len(ds.tracks) == 2 and ds.tracks[1].split in rt.SPLITS
    with pytest.raises(ValueError, match="unknown sample"):
        rtb.build({"gliders/nowhere": raw}, {})
    with pytest.raises(ValueError, match="gzipped JSON"):
        rtb.build({"gliders/luberon": b"garbage"}, {})


@pytest.mark.skipif(not WHEEL.is_file(), reason=f"traffic 2.13 wheel not at {WHEEL}")
def test_shipped_file_is_a_rebuild_of_the_wheel(tmp_path):
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import build_real_traffic
    finally:
        sys.path.remove(str(ROOT / "tools"))
    out = tmp_path / "rebuilt.npz"
    build_real_traffic.build_from_wheel(WHEEL, out)
    assert out.read_bytes() == rt.DEFAULT_PATH.read_bytes()


def test_shipped_file_is_small_and_in_package_data():
    assert rt.DEFAULT_PATH.stat().st_size < 2 * 2**20
    text = (ROOT / "pyproject.toml").read_text()
    assert "data/*.npz" in text
