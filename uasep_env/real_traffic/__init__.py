"""Recorded low-altitude tracks of gliders, helicopters and fixed-wing aircraft.

The tracks come from the ``traffic`` 2.13 package's sample flights (ADS-B recordings; licence
and provenance in ``uasep_env/data/REAL_TRAFFIC_LICENSE.md``), converted by
``tools/build_real_traffic.py`` (rules: :mod:`uasep_env.real_traffic.build`) into NED metres
about each track's first sample, at their original timestamps. Every track belongs to one
split (``"train"``, ``"validation"``, ``"test"``), by recorded flight, so none is in two.

    from uasep_env import real_traffic
    gliders = real_traffic.tracks(split="test", aircraft_class="glider")
    gliders[0].times, gliders[0].positions        # s, m NED about gliders[0].origin

For a batched replay model: :meth:`RealTrafficDataset.draw_segments` draws segments
deterministically from a :class:`numpy.random.Generator`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.real_traffic.build import CLASSES, SPLITS
from uasep_env.real_traffic.fileformat import (
    FORMAT_VERSION,
    RealTrafficFileError,
    read_npz,
)

__all__ = [
    "CLASSES",
    "DEFAULT_PATH",
    "FORMAT_VERSION",
    "SPLITS",
    "RealTrafficDataset",
    "RealTrafficFileError",
    "Segments",
    "Track",
    "load",
    "tracks",
]

#: The shipped dataset.
DEFAULT_PATH = Path(__file__).resolve().parents[1] / "data" / "real_traffic.npz"


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, kw_only=True)
class Track:
    """One recorded track, with its provenance.

    Attributes:
        times: ``(n,)`` time of each sample after the first (s), rising.
        positions: ``(n, 3)`` positions NED about :attr:`origin` (m).
        velocities: ``(n, 3)`` reported ground velocity NED in the origin's frame (m/s).
        source: Sample file in the ``traffic`` wheel.
        icao24: The aircraft's 24-bit ICAO address (hex).
        callsign: The callsign most often broadcast over the track.
        first_timestamp: UNIX time of the first sample (s).
        origin: ``(latitude deg, longitude deg, barometric altitude m)`` of the first sample.
        aircraft_class: One of :data:`CLASSES` (the ``"real_traffic"`` rows of
            :data:`uasep_env.sim.obstacles.AIRCRAFT_TABLE`).
        class_rule: How the class was decided (sample category, designator or speed rule).
        split: ``"train"``, ``"validation"`` or ``"test"``.
        flight: The recorded flight it belongs to (``"<category>/<sample>:<icao24>"``); the
            split is by flight.
        index: Position of the track in the dataset.
    """

    times: np.ndarray = field(repr=False)
    positions: np.ndarray = field(repr=False)
    velocities: np.ndarray = field(repr=False)
    source: str
    icao24: str
    callsign: str
    first_timestamp: float
    origin: tuple[float, float, float]
    aircraft_class: str
    class_rule: str
    split: str
    flight: str
    index: int

    @property
    def timestamps(self) -> np.ndarray:
        """``(n,)`` UNIX time of every sample (s)."""
        return self.first_timestamp + self.times

    @property
    def duration(self) -> float:
        """Time from the first to the last sample (s)."""
        return float(self.times[-1])


@dataclass(frozen=True, kw_only=True)
class Segments:
    """A batch of resampled track segments (:meth:`RealTrafficDataset.draw_segments`).

    Attributes:
        track: ``(n,)`` dataset index of each segment's track.
        start: ``(n,)`` start time within the track (s).
        positions: ``(n, k, 3)`` positions NED about the track's origin (m), at
            ``start + dt * arange(k)``, linearly interpolated between samples.
        velocities: ``(n, k, 3)`` reported velocities, interpolated likewise (m/s).
    """

    track: np.ndarray
    start: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray


class RealTrafficDataset:
    """The tracks of one real-traffic file, read without pickle and checked.

    Args:
        path: The ``.npz`` file (default: the shipped one).

    Raises:
        FileNotFoundError: The file does not exist (named).
        RealTrafficFileError: Corrupt, too large, or another format version (named).
    """

    def __init__(self, path: str | os.PathLike[str] = DEFAULT_PATH) -> None:
        self.path = Path(path)
        arrays, meta = read_npz(self.path)
        self.meta: dict[str, Any] = meta
        start = arrays["track_start"]
        t = arrays["time_ms"] / 1000.0
        pos = arrays["pos_cm"] / 100.0
        vel = arrays["vel_cms"] / 100.0
        out = []
        for k, rec in enumerate(meta["tracks"]):
            sl = slice(int(start[k]), int(start[k + 1]))
            try:
                out.append(
                    Track(
                        times=_frozen(t[sl]),
                        positions=_frozen(pos[sl]),
                        velocities=_frozen(vel[sl]),
                        source=str(rec["source"]),
                        icao24=str(rec["icao24"]),
                        callsign=str(rec["callsign"]),
                        first_timestamp=int(rec["first_timestamp_ms"]) / 1000.0,
                        origin=tuple(float(x) for x in rec["origin"]),  # type: ignore[arg-type]
                        aircraft_class=str(rec["aircraft_class"]),
                        class_rule=str(rec["class_rule"]),
                        split=str(rec["split"]),
                        flight=str(rec["flight"]),
                        index=k,
                    )
                )
            except (KeyError, TypeError, ValueError, OverflowError, IndexError) as exc:
                raise RealTrafficFileError(
                    f"{self.path}: track record {k} is malformed ({type(exc).__name__}: "
                    f"{' '.join(str(exc).split())[:120]})"
                ) from exc
            if len(out[-1].origin) != 3 or not np.isfinite(out[-1].origin).all():
                raise RealTrafficFileError(f"{self.path}: track {k}: origin is not 3 numbers")
            if out[-1].aircraft_class not in CLASSES or out[-1].split not in SPLITS:
                raise RealTrafficFileError(
                    f"{self.path}: track {k} has class {out[-1].aircraft_class!r} and split "
                    f"{out[-1].split!r}; expected one of {CLASSES} and {SPLITS}"
                )
        self.tracks: tuple[Track, ...] = tuple(out)

    def select(self, split: str | None = None, aircraft_class: str | None = None) -> list[Track]:
        """The tracks of one split and/or class (``None``: all), in dataset order.

        Raises:
            ValueError: An unknown split or class (named).
        """
        if split is not None and split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS} or None, got {split!r}")
        if aircraft_class is not None and aircraft_class not in CLASSES:
            raise ValueError(
                f"aircraft_class must be one of {CLASSES} or None, got {aircraft_class!r}"
            )
        return [
            tr
            for tr in self.tracks
            if (split is None or tr.split == split)
            and (aircraft_class is None or tr.aircraft_class == aircraft_class)
        ]

    def draw_segments(
        self,
        rng: np.random.Generator,
        n: int,
        duration: float,
        dt: float,
        *,
        split: str | None = None,
        aircraft_class: str | None = None,
        max_gap: float = 12.0,
    ) -> Segments:
        """Draw ``n`` segments of ``duration`` seconds, resampled every ``dt`` seconds.

        A segment lies where consecutive samples are at most ``max_gap`` apart; among all such
        places of the selected tracks, its start is uniform in time. Deterministic given
        ``rng``'s state (one ``random`` draw of ``n`` values).

        Args:
            rng: The generator (the episode's).
            n: Number of segments.
            duration: Length of each segment (s), positive.
            dt: Resampling step (s), positive.
            split: Split to draw from (``None``: all).
            aircraft_class: Class to draw from (``None``: all).
            max_gap: Longest interval between samples interpolated over (s).

        Raises:
            ValueError: Bad sizes (named), or no selected track has a long enough stretch.
        """
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        for name, val in (("duration", duration), ("dt", dt), ("max_gap", max_gap)):
            if not np.isfinite(val) or val <= 0:
                raise ValueError(f"{name} must be positive and finite, got {val!r}")
        idx, first, room, cum = self._spans(split, aircraft_class, duration, max_gap)
        if cum[-1] > 0:
            u = rng.random(n) * cum[-1]
            which = np.minimum(np.searchsorted(cum, u, side="right"), len(idx) - 1)
            start = first[which] + np.clip(u - (cum[which] - room[which]), 0.0, room[which])
        else:  # every stretch is exactly `duration` long: pick one uniformly
            which = np.minimum((rng.random(n) * len(idx)).astype(int), len(idx) - 1)
            start = first[which]
        k = int(np.floor(duration / dt + 1e-9)) + 1
        steps = dt * np.arange(k)
        pos = np.empty((n, k, 3))
        vel = np.empty((n, k, 3))
        for i in range(n):
            tr = self.tracks[int(idx[which[i]])]
            times = start[i] + steps
            for ax in range(3):
                pos[i, :, ax] = np.interp(times, tr.times, tr.positions[:, ax])
                vel[i, :, ax] = np.interp(times, tr.times, tr.velocities[:, ax])
        return Segments(track=idx[which], start=start, positions=pos, velocities=vel)

    def _spans(
        self, split: str | None, aircraft_class: str | None, duration: float, max_gap: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Stretches without a gap over ``max_gap``: track, first time, room, cumulative room.

        Computed once per arguments (a replayed scenario draws many segments; the dataset is
        immutable).
        """
        key = (split, aircraft_class, duration, max_gap)
        cache = self.__dict__.setdefault("_span_cache", {})
        if key not in cache:
            spans = []
            for tr in self.select(split, aircraft_class):
                cuts = np.flatnonzero(np.diff(tr.times) > max_gap)
                lo = np.concatenate([[0], cuts + 1])
                hi = np.concatenate([cuts, [len(tr.times) - 1]])
                for a, b in zip(lo, hi, strict=True):
                    if tr.times[b] - tr.times[a] >= duration:
                        spans.append((tr.index, tr.times[a], tr.times[b] - duration))
            if not spans:
                raise ValueError(
                    f"no {split or 'any'}-split {aircraft_class or 'any-class'} track has "
                    f"{duration} s without a gap over {max_gap} s"
                )
            idx = np.array([s[0] for s in spans])
            first = np.array([s[1] for s in spans])
            room = np.array([s[2] for s in spans]) - first
            cache[key] = (idx, first, room, np.cumsum(room))
        return cache[key]


@lru_cache(maxsize=4)
def _cached(path: Path) -> RealTrafficDataset:
    return RealTrafficDataset(path)


def load(path: str | os.PathLike[str] | None = None) -> RealTrafficDataset:
    """The dataset at ``path`` (default: the shipped file; cached per path)."""
    return _cached(Path(path) if path is not None else DEFAULT_PATH)


def tracks(
    split: str | None = None,
    aircraft_class: str | None = None,
    *,
    path: str | os.PathLike[str] | None = None,
) -> list[Track]:
    """The recorded tracks of one split and/or aircraft class (``None``: all).

    Args:
        split: ``"train"``, ``"validation"``, ``"test"`` or ``None``.
        aircraft_class: One of :data:`CLASSES` or ``None``.
        path: Another real-traffic file (default: the shipped one).

    Returns:
        The tracks in dataset order (their arrays are read-only).

    Raises:
        ValueError: An unknown split or class.
        FileNotFoundError: ``path`` does not exist.
        RealTrafficFileError: The file is corrupt, too large or of another format version.
    """
    return load(path).select(split, aircraft_class)
