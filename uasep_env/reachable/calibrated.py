"""The calibrated prediction (``prediction.fit="calibrated"``): conformal regions per class.

A region of the same form as the other fits (centre, semi-axes (longitudinal, lateral,
vertical), heading), but sized by split conformal prediction on recorded flights instead of
derived from Dubins bounds:

* nominal motion: constant velocity from the obstacle's Kalman estimate (position ``p``,
  ground velocity ``u``). The centre is ``p + kappa h u`` (``kappa = 1/2`` for the swept
  region, the middle of the nominal path over ``[t, t + h]``; ``1`` for the terminal one),
  the heading that of ``u``'s horizontal part;
* shape: semi-axes affine in the estimated horizontal speed ``v``,
  ``axis_k = a_k v + b_k`` (m), one ``(a, b)`` per axis, aircraft class, mode and horizon.
  They are ``q`` times a base shape fitted on the training flights; ``q`` is the conformal
  quantile of the normalised score (how far outside the base shape the real path went) on
  the validation flights, taken at the order statistic of the training-conditional (PAC)
  bound (``docs/reachable_sets.md``, "Calibrated regions").

Nothing is fitted here: the shipped table ``data/prediction_calibration.json`` (built by
``tools/build_prediction_calibration.py``) is read once, with a size and nesting limit, and
checked; a missing, corrupt or other-version table is a :class:`CalibrationTableError` naming
the file. An unknown aircraft class, or a class whose cell had too few calibration windows,
gets the most conservative region: per axis the largest ``a`` and the largest ``b`` over the
calibrated classes, so it contains every class's region (same centre and heading).
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from uasep_env.config.groups import CALIBRATED_HORIZONS
from uasep_env.runtime.jsonio import json_depth
from uasep_env.sim.obstacles import AIRCRAFT_CLASSES, UNKNOWN_CLASS

__all__ = [
    "CALIBRATED_HORIZONS",
    "DEFAULT_TABLE",
    "TABLE_FORMAT",
    "TABLE_VERSION",
    "CalibrationTable",
    "CalibrationTableError",
    "calibrated_region",
    "load_table",
]

#: The shipped calibration table.
DEFAULT_TABLE = Path(__file__).resolve().parents[1] / "data" / "prediction_calibration.json"
TABLE_FORMAT = "uasep-prediction-calibration"
TABLE_VERSION = 1
#: Centre of the region along the nominal path, as a fraction of ``h u`` per mode.
CENTRE_FRACTION = {"swept": 0.5, "terminal": 1.0}
#: Largest table file read (bytes) and deepest JSON nesting accepted.
MAX_TABLE_BYTES = 1 << 20
MAX_TABLE_DEPTH = 12
#: Largest coefficient accepted (``a`` in s, ``b`` and ``inflation_m`` in m): the shipped
#: table's largest are about 73 s and 322 m; a larger one is a corrupt table (1e308 made
#: infinite semi-axes).
MAX_COEFFICIENT = 1e5
_AXES = ("longitudinal", "lateral", "vertical")
_MISSING = "no such file (rebuild: python tools/build_prediction_calibration.py)"


class CalibrationTableError(ValueError):
    """A calibration table that is missing, corrupt, too large or of another version."""


@dataclass(frozen=True, kw_only=True)
class CalibrationTable:
    """The calibration coefficients, ready for :func:`calibrated_region`.

    Attributes:
        path: Where it was read from.
        horizons: The calibrated horizons (s).
        coef: ``{mode: (n_classes, n_horizons, 3, 2)}``: ``(a, b)`` per class code
            (:data:`uasep_env.sim.obstacles.AIRCRAFT_CLASSES`), horizon and axis; the unknown
            class's row (and any class whose cell is not calibrated) is the per-axis maximum
            over the calibrated classes.
        inflation: The inflation the table was calibrated with (m): obstacle radius plus three
            steady-state track standard deviations. A larger run-time inflation is added to
            every semi-axis (the region only grows).
        meta: The table's provenance, as stored.
    """

    path: Path
    horizons: tuple[float, ...]
    coef: dict[str, np.ndarray]
    inflation: float
    meta: dict[str, Any]

    def horizon_index(self, horizon: float) -> int:
        """The column of ``horizon``; a ValueError naming it when it is not calibrated."""
        for i, h in enumerate(self.horizons):
            if abs(h - horizon) < 1e-9:
                return i
        raise ValueError(
            f"invalid config value prediction.horizon={horizon!r}: prediction.fit='calibrated' "
            f"is calibrated at horizons {list(self.horizons)} s only (table {self.path.name})"
        )


def _fail(path: Path, why: str) -> CalibrationTableError:
    return CalibrationTableError(f"calibration table {path}: {why}")


_T = TypeVar("_T")


def _named(path: Path, action: Callable[[], _T]) -> _T:
    """``action()``, a missing or unreadable file named in one line."""
    try:
        return action()
    except FileNotFoundError:
        raise _fail(
            path, "no such file (rebuild: python tools/build_prediction_calibration.py)"
        ) from None
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror})") from None


def _read(path: Path) -> dict[str, Any]:
    def head() -> bytes:
        with open(path, "rb") as fh:
            return fh.read(MAX_TABLE_BYTES + 1)

    raw = _named(path, head)
    if len(raw) > MAX_TABLE_BYTES:
        raise _fail(path, f"larger than the limit of {MAX_TABLE_BYTES:,} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise _fail(path, "is not UTF-8 text") from None
    depth = json_depth(text)
    if depth > MAX_TABLE_DEPTH:
        raise _fail(path, f"nests {depth} levels deep, limit {MAX_TABLE_DEPTH}")
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise _fail(path, f"is not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise _fail(path, "is not a JSON object")
    if data.get("format") != TABLE_FORMAT:
        raise _fail(path, f"format {data.get('format')!r}, expected {TABLE_FORMAT!r}")
    if data.get("version") != TABLE_VERSION:
        raise _fail(path, f"version {data.get('version')!r}, this uasep-env reads {TABLE_VERSION}")
    return data


def _finite_nonneg(path: Path, where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(path, f"{where} is {value!r}, expected a number")
    try:
        number = float(value)
    except OverflowError:  # an integer of hundreds of digits: not printed whole
        raise _fail(
            path, f"{where} is an integer of {len(str(abs(value)))} digits, too large for a float"
        ) from None
    if not (math.isfinite(number) and 0.0 <= number <= MAX_COEFFICIENT):
        raise _fail(path, f"{where} is {value!r}, expected a number in [0, {MAX_COEFFICIENT:g}]")
    return number


def _parse(path: Path, data: dict[str, Any]) -> CalibrationTable:
    try:
        horizons = tuple(float(h) for h in data["horizons"])
        cells = data["cells"]
        inflation = _finite_nonneg(path, "inflation_m", data["inflation_m"])
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        if isinstance(exc, CalibrationTableError):
            raise
        detail = " ".join(str(exc).split())[:120]
        raise _fail(path, f"is malformed ({type(exc).__name__}: {detail})") from None
    if horizons != CALIBRATED_HORIZONS:
        raise _fail(path, f"horizons {list(horizons)}, expected {list(CALIBRATED_HORIZONS)}")
    coef: dict[str, np.ndarray] = {}
    for mode in CENTRE_FRACTION:
        arr = np.full((len(AIRCRAFT_CLASSES), len(horizons), 3, 2), np.nan)
        done = np.zeros((len(AIRCRAFT_CLASSES), len(horizons)), dtype=bool)
        by_class = cells.get(mode) if isinstance(cells, dict) else None
        if not isinstance(by_class, dict):
            raise _fail(path, f"has no cells for mode {mode!r}")
        for name, per_h in by_class.items():
            if name not in AIRCRAFT_CLASSES or name == AIRCRAFT_CLASSES[UNKNOWN_CLASS]:
                raise _fail(path, f"cells.{mode} has an unknown class {name!r}")
            code = AIRCRAFT_CLASSES.index(name)
            for j, h in enumerate(horizons):
                cell = per_h.get(f"{h:g}") if isinstance(per_h, dict) else None
                where = f"cells.{mode}.{name}.{h:g}"
                if not isinstance(cell, dict):
                    raise _fail(path, f"{where} is missing")
                if not cell.get("calibrated", False):
                    continue
                for k, axis in enumerate(_AXES):
                    pair = cell.get(axis)
                    if not (isinstance(pair, list) and len(pair) == 2):
                        raise _fail(path, f"{where}.{axis} is {pair!r}, expected [a, b]")
                    arr[code, j, k] = [_finite_nonneg(path, f"{where}.{axis}", x) for x in pair]
                done[code, j] = True
        if not done.any(axis=0).all():
            raise _fail(path, f"mode {mode!r} has a horizon no class is calibrated at")
        # The most conservative region: per axis and horizon, the largest a and b.
        worst = np.nanmax(np.where(done[..., None, None], arr, np.nan), axis=0)
        arr = np.where(done[..., None, None], arr, worst[None])
        coef[mode] = arr
    meta = {k: v for k, v in data.items() if k != "cells"}
    return CalibrationTable(path=path, horizons=horizons, coef=coef, inflation=inflation, meta=meta)


@lru_cache(maxsize=4)
def _load_cached(path: str, mtime_ns: int, size: int) -> CalibrationTable:
    p = Path(path)
    return _parse(p, _read(p))


def load_table(path: str | os.PathLike[str] = DEFAULT_TABLE) -> CalibrationTable:
    """Read and check a calibration table (cached while the file is unchanged).

    Raises:
        CalibrationTableError: Missing, not a regular file, unreadable, too large, not JSON,
            another format or version, or malformed (the message names the file and the
            bad entry).
    """
    p = Path(path)
    st = _named(p, p.stat)
    if not stat.S_ISREG(st.st_mode):  # before opening: a FIFO's open would block for ever
        raise _fail(p, "is not a regular file (a FIFO, device, socket or folder)")
    return _load_cached(str(p), st.st_mtime_ns, st.st_size)


def calibrated_region(
    aircraft_class: ArrayLike,
    est_pos: ArrayLike,
    est_vel: ArrayLike,
    horizon: float,
    mode: str = "swept",
    inflation: ArrayLike = 0.0,
    table: CalibrationTable | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The calibrated region of obstacles from their estimates.

    Args:
        aircraft_class: ``(...)`` class codes (:data:`uasep_env.sim.obstacles.AIRCRAFT_CLASSES`);
            codes outside the table are treated as unknown.
        est_pos: ``(..., 3)`` estimated positions (m, NED).
        est_vel: ``(..., 3)`` estimated ground velocities (m/s, NED).
        horizon: One of the calibrated horizons (s).
        mode: ``"swept"`` or ``"terminal"``.
        inflation: ``(...)`` run-time inflation (m); what exceeds the table's own is added to
            every semi-axis.
        table: A loaded table (default: the shipped one).

    Returns:
        ``(centre (..., 3), semi_axes (..., 3), heading (...))``: semi-axes ordered
        (longitudinal, lateral, vertical) (m), heading from north towards east (rad).

    Raises:
        ValueError: An uncalibrated horizon or an unknown mode (named).
    """
    if mode not in CENTRE_FRACTION:
        raise ValueError(f"mode must be 'swept' or 'terminal', got {mode!r}")
    tab = load_table() if table is None else table
    j = tab.horizon_index(float(horizon))
    cls = np.asarray(aircraft_class, dtype=np.int64)
    cls = np.where((cls >= 0) & (cls < len(AIRCRAFT_CLASSES)), cls, UNKNOWN_CLASS)
    pos = np.asarray(est_pos, dtype=np.float64)
    vel = np.asarray(est_vel, dtype=np.float64)
    ab = tab.coef[mode][cls, j]  # (..., 3, 2)
    speed = np.hypot(vel[..., 0], vel[..., 1])
    extra = np.maximum(np.asarray(inflation, dtype=np.float64) - tab.inflation, 0.0)
    axes = ab[..., 0] * speed[..., None] + ab[..., 1] + extra[..., None]
    centre = pos + (CENTRE_FRACTION[mode] * float(horizon)) * vel
    heading = np.arctan2(vel[..., 1], vel[..., 0])
    return centre, axes, heading
