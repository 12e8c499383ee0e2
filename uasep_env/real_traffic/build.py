"""From the ``traffic`` package's sample flights to the real-traffic file (see ``tools/``).

``tools/build_real_traffic.py`` reads the sample JSON out of the ``traffic`` wheel and calls
:func:`build`; this module holds the rules so that they are tested and documented in one
place (``docs/real_traffic.md``):

* **Records**: a record is used when it has a timestamp, ``icao24``, latitude, longitude,
  barometric altitude, ground speed, track and vertical rate, is not flagged ``onground``
  and its altitude is within [-2,000, 45,000] ft. Barometric altitude is used as the height
  (gliders report no geometric altitude); its offset from the geometric height is nearly
  constant over a track, and tracks are relative to their first sample.
* **Stale reports**: a record at exactly the previous record's latitude, longitude and
  altitude while reporting at least :data:`STALE_KT` of ground speed repeats a stale
  position (some fire-fighting aircraft repeat one position for minutes) and is dropped.
* **Outliers**: a sample whose implied speed from the previous kept sample *and* to the next
  one both exceed :data:`MAX_SPEED` horizontally (or :data:`MAX_CLIMB` vertically) is a spike
  and is dropped (repeated until none is left); duplicated timestamps keep the first record.
* **Gaps**: a track is cut wherever two samples are more than :data:`GAP_S` apart or the
  implied speed between them still exceeds the limits; pieces shorter than
  :data:`MIN_SAMPLES` samples or :data:`MIN_DURATION_S` are dropped.
* **Frames**: each track is in NED metres about its first sample (WGS-84 tangent plane,
  :mod:`~uasep_env.real_traffic.geodesy`); the reported velocity (ground speed, track,
  vertical rate) is rotated from the sample's local NED into the origin's.
* **Classes**: the sample category (``gliders``: glider; ``ambulances``: helicopter); for
  ``firefighting/calfire`` the CAL FIRE radio designator (``A``/``AA`` air attack and ``T``
  tanker: fixed wing; ``C`` copter: helicopter), else a speed rule (an aircraft whose
  airborne ground speed is below 45 kt in more than 5 % of its samples is a helicopter;
  fixed-wing fire aircraft stall well above that). The rule used is stored per track.
* **Splits**: by recorded flight, ``"<category>/<sample>:<icao24>"`` (one aircraft's
  recording in one sample file), so no recorded flight is in two splits (the same airframe
  can be: REGA1 flew ``rega_sg`` and, a day later, ``rega_zh``). Per class, flights are taken
  in the order of the SHA-256 of their id and each goes to the split least filled relative
  to its share of the class's samples
  (:data:`SPLIT_SHARES`: 60 % training, 20 % validation, 20 % test; ties go to test, then
  validation), so a class's first flight is a test one, its second a validation one.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from uasep_env.real_traffic.geodesy import FEET, KNOT, ned_about, ned_rotation
from uasep_env.sim.obstacles import REAL_TRAFFIC_CLASSES

__all__ = [
    "CLASSES",
    "GAP_S",
    "MAX_CLIMB",
    "MAX_SPEED",
    "MIN_DURATION_S",
    "MIN_SAMPLES",
    "SAMPLES",
    "SPLITS",
    "SPLIT_SHARES",
    "assign_splits",
    "build",
]

#: The dataset's aircraft classes: the ``"real_traffic"`` rows of the aircraft class table
#: (:data:`uasep_env.sim.obstacles.AIRCRAFT_TABLE`); :func:`_aircraft_class` assigns them.
CLASSES = REAL_TRAFFIC_CLASSES
SPLITS = ("train", "validation", "test")
#: Target share of each class's samples per split.
SPLIT_SHARES = {"train": 0.6, "validation": 0.2, "test": 0.2}
#: Sample files used (path under ``traffic/data/samples/`` without ``.json.gz``) and their
#: class (``None``: per aircraft, see the module docstring).
SAMPLES: dict[str, str | None] = {
    **{
        f"gliders/{name}": "glider"
        for name in (
            "alpi_italiane",
            "alto_adige",
            "cevennes",
            "danube_valley",
            "franconia",
            "luberon",
            "oxford_cambridge",
            "sisteron",
        )
    },
    "ambulances/rega_sg": "helicopter",
    "ambulances/rega_zh": "helicopter",
    "ambulances/samu31": "helicopter",
    "firefighting/calfire": None,
}
#: A gap longer than this (s) cuts a track.
GAP_S = 60.0
#: Implied speeds over these (m/s) mark a spike: ~340 kt horizontally (faster than any of
#: these aircraft at low level), ~12,000 ft/min vertically.
MAX_SPEED = 175.0
MAX_CLIMB = 60.0
#: Shortest track kept.
MIN_SAMPLES = 10
MIN_DURATION_S = 60.0
ALT_RANGE_FT = (-2000.0, 45000.0)
#: A record at exactly the previous one's position while reporting this ground speed (kt)
#: or more is a stale repeat (the receiver re-sent the last position) and is dropped.
STALE_KT = 20.0
_FIELDS = ("latitude", "longitude", "altitude", "groundspeed", "track", "vertical_rate")
_CALFIRE = (
    (re.compile(r"^AA?\d+$"), "fixed_wing", "CAL FIRE designator A/AA (air attack)"),
    (re.compile(r"^T\d+$"), "fixed_wing", "CAL FIRE designator T (air tanker)"),
    (re.compile(r"^C\d+$"), "helicopter", "CAL FIRE designator C (copter)"),
)
_PREFIX = "traffic/data/samples/"
_SLOW_KT = 45.0
_SLOW_FRACTION = 0.05


def _num(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return float("nan")
    return float(value)


def _records(sample: str, raw: bytes) -> list[dict[str, Any]]:
    try:
        records = json.loads(gzip.decompress(raw))
    except (OSError, ValueError) as exc:
        raise ValueError(f"sample {sample!r}: not gzipped JSON ({exc})") from exc
    if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
        raise ValueError(f"sample {sample!r}: expected a JSON list of records")
    return records


def _spikes(t: np.ndarray, ned: np.ndarray) -> np.ndarray:
    """Keep-mask after removing isolated speed spikes, repeatedly (at most 50 passes)."""
    keep = np.ones(len(t), dtype=bool)
    for _ in range(50):
        idx = np.flatnonzero(keep)
        if len(idx) < 3:
            break
        dt = np.diff(t[idx])
        d = np.diff(ned[idx], axis=0)
        bad = (np.hypot(d[:, 0], d[:, 1]) > MAX_SPEED * dt) | (np.abs(d[:, 2]) > MAX_CLIMB * dt)
        spike = np.zeros(len(idx), dtype=bool)
        spike[1:-1] = bad[:-1] & bad[1:]
        spike[0] = bad[0] and (len(bad) < 2 or not bad[1])  # a bad first sample
        spike[-1] = bad[-1] and (len(bad) < 2 or not bad[-2])
        if not spike.any():
            break
        keep[idx[spike]] = False
    return keep


def _aircraft_class(sample: str, callsigns: list[str], gs_kt: np.ndarray) -> tuple[str, str]:
    fixed = SAMPLES[sample]
    if fixed is not None:
        return fixed, f"sample category {sample.split('/')[0]}"
    for pattern, cls, why in _CALFIRE:
        if any(pattern.match(c) for c in callsigns):
            return cls, why
    slow = float(np.mean(gs_kt < _SLOW_KT))
    cls = "helicopter" if slow > _SLOW_FRACTION else "fixed_wing"
    return cls, f"speed rule ({100 * slow:.1f} % of samples below {_SLOW_KT:g} kt)"


def _aircraft_tracks(
    sample: str, icao: str, recs: list[dict[str, Any]], dropped: dict[str, int]
) -> list[dict[str, Any]]:
    t_ms = np.array([int(r["timestamp"]) for r in recs], dtype=np.int64)
    order = np.argsort(t_ms, kind="stable")
    recs = [recs[i] for i in order]
    t_ms = t_ms[order]
    first = np.ones(len(t_ms), dtype=bool)
    first[1:] = np.diff(t_ms) > 0
    dropped["duplicate_time"] += int(np.sum(~first))
    recs = [r for r, f in zip(recs, first, strict=True) if f]
    t_ms = t_ms[first]
    v = np.array([[_num(r[f]) for f in _FIELDS] for r in recs], dtype=np.float64)
    # A moving aircraft at exactly the previous record's position: a repeated, stale report.
    stale = np.zeros(len(recs), dtype=bool)
    stale[1:] = np.all(v[1:, :3] == v[:-1, :3], axis=1) & (v[1:, 3] >= STALE_KT)
    dropped["stale"] += int(np.sum(stale))
    recs = [r for r, s in zip(recs, stale, strict=True) if not s]
    t_ms, v = t_ms[~stale], v[~stale]
    lat, lon, alt_m = v[:, 0], v[:, 1], v[:, 2] * FEET
    t = (t_ms - t_ms[0]) / 1000.0
    ned = ned_about(lat, lon, alt_m, (float(lat[0]), float(lon[0]), float(alt_m[0])))
    keep = _spikes(t, ned)
    dropped["spike"] += int(np.sum(~keep))
    idx = np.flatnonzero(keep)
    dt = np.diff(t[idx])
    d = np.diff(ned[idx], axis=0)
    cut = (
        (dt > GAP_S)
        | (np.hypot(d[:, 0], d[:, 1]) > MAX_SPEED * dt)
        | (np.abs(d[:, 2]) > MAX_CLIMB * dt)
    )
    pieces = np.split(idx, np.flatnonzero(cut) + 1)
    callsigns = [str(r.get("callsign") or "").strip() for r in recs]
    cls, why = _aircraft_class(sample, sorted({c for c in callsigns if c}), v[keep, 3])
    out = []
    for piece in pieces:
        if len(piece) < MIN_SAMPLES or t[piece[-1]] - t[piece[0]] < MIN_DURATION_S:
            dropped["short_piece"] += len(piece)
            continue
        o = piece[0]
        origin = (float(lat[o]), float(lon[o]), float(alt_m[o]))
        pos = ned_about(lat[piece], lon[piece], alt_m[piece], origin)
        gs, trk = v[piece, 3] * KNOT, np.radians(v[piece, 4])
        local = np.stack([gs * np.cos(trk), gs * np.sin(trk), -v[piece, 5] * FEET / 60.0], -1)
        # Local NED at each sample -> ECEF -> NED at the origin.
        rot = ned_rotation(origin[0], origin[1]) @ np.swapaxes(
            ned_rotation(lat[piece], lon[piece]), -1, -2
        )
        vel = np.einsum("nij,nj->ni", rot, local)
        names = [c for c in (callsigns[i] for i in piece) if c]
        out.append(
            {
                "time_ms": t_ms[piece] - t_ms[o],
                "pos_cm": np.round(pos * 100.0),
                "vel_cms": np.round(vel * 100.0),
                "meta": {
                    "source": f"{_PREFIX}{sample}.json.gz",
                    "icao24": icao,
                    "callsign": max(set(names), key=names.count) if names else "",
                    "first_timestamp_ms": int(t_ms[o]),
                    "origin": [round(origin[0], 7), round(origin[1], 7), round(origin[2], 3)],
                    "aircraft_class": cls,
                    "class_rule": why,
                    "n_samples": len(piece),
                },
            }
        )
    return out


def assign_splits(units: Mapping[str, tuple[str, int]]) -> dict[str, str]:
    """Split each class's flights into training, validation and test (module docstring).

    Args:
        units: ``flight id -> (aircraft class, number of samples)``.

    Returns:
        ``flight id -> split`` (one of :data:`SPLITS`).
    """
    out: dict[str, str] = {}
    for cls in sorted({c for c, _ in units.values()}):
        ids = sorted(
            (u for u, (c, _) in units.items() if c == cls),
            key=lambda u: hashlib.sha256(f"uasep-real-traffic:{u}".encode()).hexdigest(),
        )
        total = sum(units[u][1] for u in ids)
        have = dict.fromkeys(SPLITS, 0)
        for u in ids:
            # The split least filled relative to its share of the class's samples; ties: test,
            # then validation (so a class's first aircraft is a test one).
            split = min(
                ("test", "validation", "train"),
                key=lambda s: have[s] / (SPLIT_SHARES[s] * total),
            )
            out[u] = split
            have[split] += units[u][1]
    return out


def build(
    samples: Mapping[str, bytes], source: Mapping[str, Any]
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Convert sample files into the real-traffic arrays and metadata.

    Args:
        samples: Sample name (a key of :data:`SAMPLES`) -> the ``.json.gz`` bytes.
        source: Provenance of the inputs (package, version, wheel digest), stored as given.

    Returns:
        ``(arrays, meta)`` for :func:`~uasep_env.real_traffic.fileformat.write_npz`.

    Raises:
        ValueError: An unknown sample name or a file that is not a gzipped JSON list.
    """
    unknown = sorted(set(samples) - set(SAMPLES))
    if unknown:
        raise ValueError(f"unknown sample(s) {unknown}; known: {sorted(SAMPLES)}")
    tracks: list[dict[str, Any]] = []
    dropped_all: dict[str, dict[str, int]] = {}
    digests = {}
    for sample in sorted(samples):
        raw = samples[sample]
        digests[sample] = hashlib.sha256(raw).hexdigest()
        records = _records(sample, raw)
        dropped = dict.fromkeys(
            ("missing_field", "on_ground", "altitude_range", "duplicate_time", "spike"), 0
        )
        dropped["stale"] = 0
        dropped["short_piece"] = 0
        by_icao: dict[str, list[dict[str, Any]]] = {}
        for r in records:
            complete = isinstance(r.get("timestamp"), int) and isinstance(r.get("icao24"), str)
            if not complete or not all(np.isfinite(_num(r.get(f))) for f in _FIELDS):
                dropped["missing_field"] += 1
            elif r.get("onground") is True:
                dropped["on_ground"] += 1
            elif not ALT_RANGE_FT[0] <= _num(r["altitude"]) <= ALT_RANGE_FT[1]:
                dropped["altitude_range"] += 1
            else:
                by_icao.setdefault(r["icao24"].lower(), []).append(r)
        for icao in sorted(by_icao):
            tracks.extend(_aircraft_tracks(sample, icao, by_icao[icao], dropped))
        dropped_all[sample] = {"records": len(records), **dropped}
    units: dict[str, tuple[str, int]] = {}
    for tr in tracks:
        m = tr["meta"]
        m["flight"] = f"{m['source'][len(_PREFIX) : -len('.json.gz')]}:{m['icao24']}"
        cls, count = units.get(m["flight"], (m["aircraft_class"], 0))
        units[m["flight"]] = (cls, count + m["n_samples"])
    splits = assign_splits(units)
    for tr in tracks:
        tr["meta"]["split"] = splits[tr["meta"]["flight"]]
    lengths = [len(tr["time_ms"]) for tr in tracks]
    arrays = {
        "time_ms": np.concatenate([tr["time_ms"] for tr in tracks]).astype(np.int64),
        "pos_cm": np.concatenate([tr["pos_cm"] for tr in tracks]).astype(np.int32),
        "vel_cms": np.concatenate([tr["vel_cms"] for tr in tracks]).astype(np.int32),
        "track_start": np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
    }
    meta = {
        "source": {**source, "sample_sha256": digests},
        "processing": {
            "frame": "NED metres about each track's first sample, WGS-84 local tangent plane",
            "height": "barometric altitude (ft) x 0.3048",
            "velocity": "reported ground speed, track, vertical rate, in the origin's NED",
            "gap_s": GAP_S,
            "max_speed_m_s": MAX_SPEED,
            "max_climb_m_s": MAX_CLIMB,
            "min_samples": MIN_SAMPLES,
            "min_duration_s": MIN_DURATION_S,
            "altitude_range_ft": list(ALT_RANGE_FT),
            "stale_kt": STALE_KT,
            "quantisation": "positions cm, velocities cm/s, times ms",
        },
        "split_rule": "by flight id; per class, in the order of sha256('uasep-real-traffic:' "
        "+ flight), each flight goes to the split least filled relative to its share of the "
        "class's samples (train 0.6, validation 0.2, test 0.2; ties: test, validation, train)",
        "dropped": dropped_all,
        "tracks": [tr["meta"] for tr in tracks],
    }
    return arrays, meta
