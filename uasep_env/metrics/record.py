"""The input of the metrics: one recorded episode (:class:`EpisodeRecord`), validated.

Frame: NED (x north, y east, z down); metres, seconds, m/s, m/s^2. All arrays are numpy float64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["EpisodeRecord", "check_scalar"]


def _as_float_array(name: str, value: ArrayLike) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float64 array ({exc})") from exc
    return arr


def _check_shape(name: str, arr: np.ndarray, shape: tuple[int | None, ...]) -> None:
    ok = arr.ndim == len(shape) and all(
        want is None or have == want for have, want in zip(arr.shape, shape, strict=False)
    )
    if not ok:
        want_txt = "(" + ", ".join("?" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want_txt}, got {arr.shape}")


def check_scalar(name: str, value: float, *, positive: bool = False) -> float:
    """Return ``value`` as a finite float (``> 0`` if ``positive``); ValueError naming ``name``."""
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a real number, got {value!r}") from exc
    if not math.isfinite(out):
        raise ValueError(f"{name}: must be finite, got {out}")
    if positive and out <= 0.0:
        raise ValueError(f"{name}: must be > 0, got {out}")
    return out


@dataclass(frozen=True, eq=False, kw_only=True)
class EpisodeRecord:
    """One recorded episode of a formation flight among obstacles (NED frame, SI units).

    Arrays are converted to numpy (float64, ``obstacle_active`` bool) and validated in
    ``__post_init__``; every problem raises :class:`ValueError` whose message starts with the
    name of the offending field. ``T`` is the number of samples, ``N`` the number of UAVs
    (``N >= 1``) and ``M`` the number of obstacles (``M >= 0``).

    Attributes:
        time: (T,) sample times (s), strictly increasing with uniform step ``dt``.
        dt: Sample step (s), ``> 0``; must match ``diff(time)`` (relative tolerance 1e-6).
        uav_pos: (T, N, 3) true UAV positions (m).
        uav_vel: (T, N, 3) true UAV velocities (m/s).
        uav_acc: (T, N, 3) applied UAV accelerations (m/s^2).
        planned_pos: (T, N, 3) planned position of each UAV at each sample (m).
        obstacle_pos: (T, M, 3) true obstacle positions (m); may be non-finite where the
            obstacle is inactive.
        obstacle_active: (T, M) bool, True where the obstacle is present.
        region_distance: (T, N, M) signed distance (m, negative inside) from each UAV to each
            obstacle's predicted reachable region; may be non-finite where inactive.
        collision_distance: Collision distance (m), ``> 0``: a UAV-UAV or UAV-obstacle centre
            distance below it is a collision.
        uav_separation: UAV-UAV loss-of-separation threshold (m), ``> collision_distance``.
        obstacle_separation: UAV-obstacle loss-of-separation threshold (m),
            ``>= collision_distance``.
        deviation_threshold: A UAV is off its planned trajectory when its deviation is
            ``> deviation_threshold`` (m), ``> 0``.
        settle_time: Samples before this time (s) are ignored by the deviation, timeline,
            fluctuation and path-length statistics; must not exceed ``time[-1]``.
        uav_names: Optional UAV names (N unique strings); default ``("uav_0", "uav_1", ...)``.
        step_cost: Optional (T-1, N) cost of each UAV in each step (the cost channel,
            :mod:`uasep_env.interface.costs`): row ``k`` is the cost of the step from sample
            ``k`` to sample ``k + 1``; finite and ``>= 0``. None (a record made without the
            cost channel) leaves the cost metrics NaN.
    """

    time: NDArray[np.float64]
    dt: float
    uav_pos: NDArray[np.float64]
    uav_vel: NDArray[np.float64]
    uav_acc: NDArray[np.float64]
    planned_pos: NDArray[np.float64]
    obstacle_pos: NDArray[np.float64]
    obstacle_active: NDArray[np.bool_]
    region_distance: NDArray[np.float64]
    collision_distance: float
    uav_separation: float
    obstacle_separation: float
    deviation_threshold: float = 1.0
    settle_time: float = 0.0
    uav_names: tuple[str, ...] | None = None
    step_cost: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        """Convert and validate every field; raise ValueError naming the bad field."""
        setf = object.__setattr__

        dt = check_scalar("dt", self.dt, positive=True)
        setf(self, "dt", dt)

        time = _as_float_array("time", self.time)
        _check_shape("time", time, (None,))
        n_t = time.shape[0]
        if n_t < 1:
            raise ValueError("time: needs at least one sample")
        if not np.all(np.isfinite(time)):
            raise ValueError("time: contains non-finite values")
        if n_t > 1:
            steps = np.diff(time)
            if np.any(steps <= 0.0):
                raise ValueError("time: must be strictly increasing")
            if not np.allclose(steps, dt, rtol=1e-6, atol=1e-9 * dt):
                raise ValueError(
                    f"time: step must be uniform and equal to dt={dt}, got steps in "
                    f"[{steps.min()}, {steps.max()}]"
                )
        setf(self, "time", time)

        uav_pos = _as_float_array("uav_pos", self.uav_pos)
        _check_shape("uav_pos", uav_pos, (n_t, None, 3))
        n_uav = uav_pos.shape[1]
        if n_uav < 1:
            raise ValueError("uav_pos: needs at least one UAV")
        for name in ("uav_pos", "uav_vel", "uav_acc", "planned_pos"):
            arr = uav_pos if name == "uav_pos" else _as_float_array(name, getattr(self, name))
            _check_shape(name, arr, (n_t, n_uav, 3))
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name}: contains non-finite values")
            setf(self, name, arr)

        obstacle_pos = _as_float_array("obstacle_pos", self.obstacle_pos)
        _check_shape("obstacle_pos", obstacle_pos, (n_t, None, 3))
        n_obs = obstacle_pos.shape[1]

        active_raw = np.asarray(self.obstacle_active)
        _check_shape("obstacle_active", active_raw, (n_t, n_obs))
        if active_raw.dtype != np.bool_:
            if active_raw.size and not (
                np.issubdtype(active_raw.dtype, np.number)
                and np.all((active_raw == 0) | (active_raw == 1))
            ):
                raise ValueError("obstacle_active: must be boolean (or 0/1)")
            active_raw = active_raw.astype(bool)
        active = np.ascontiguousarray(active_raw, dtype=bool)
        setf(self, "obstacle_active", active)

        if not np.all(np.isfinite(obstacle_pos[active])):
            raise ValueError("obstacle_pos: non-finite values where the obstacle is active")
        setf(self, "obstacle_pos", obstacle_pos)

        region = _as_float_array("region_distance", self.region_distance)
        _check_shape("region_distance", region, (n_t, n_uav, n_obs))
        if np.any(np.isnan(region) & active[:, None, :]):
            raise ValueError("region_distance: NaN where the obstacle is active")
        setf(self, "region_distance", region)

        coll = check_scalar("collision_distance", self.collision_distance, positive=True)
        usep = check_scalar("uav_separation", self.uav_separation, positive=True)
        osep = check_scalar("obstacle_separation", self.obstacle_separation, positive=True)
        if usep <= coll:
            raise ValueError(f"uav_separation: must be > collision_distance ({coll}), got {usep}")
        if osep < coll:
            raise ValueError(
                f"obstacle_separation: must be >= collision_distance ({coll}), got {osep}"
            )
        setf(self, "collision_distance", coll)
        setf(self, "uav_separation", usep)
        setf(self, "obstacle_separation", osep)

        thr = check_scalar("deviation_threshold", self.deviation_threshold, positive=True)
        setf(self, "deviation_threshold", thr)
        settle = check_scalar("settle_time", self.settle_time)
        if settle > time[-1] + 1e-9 * dt:
            raise ValueError(f"settle_time: {settle} s is after the last sample ({time[-1]} s)")
        setf(self, "settle_time", settle)

        if self.uav_names is None:
            names = tuple(f"uav_{i}" for i in range(n_uav))
        else:
            if isinstance(self.uav_names, str):
                raise ValueError("uav_names: expected a sequence of str, got a single str")
            names = tuple(self.uav_names)
            if len(names) != n_uav:
                raise ValueError(f"uav_names: expected {n_uav} names, got {len(names)}")
            if not all(isinstance(n, str) and n for n in names):
                raise ValueError("uav_names: names must be non-empty str")
            if len(set(names)) != n_uav:
                raise ValueError("uav_names: names must be unique")
        setf(self, "uav_names", names)

        if self.step_cost is not None:
            cost = _as_float_array("step_cost", self.step_cost)
            _check_shape("step_cost", cost, (n_t - 1, n_uav))
            if not np.all(np.isfinite(cost)) or np.any(cost < 0.0):
                raise ValueError("step_cost: must be finite and >= 0")
            setf(self, "step_cost", cost)

    @property
    def n_steps(self) -> int:
        """Number of samples T."""
        return int(self.time.shape[0])

    @property
    def n_uavs(self) -> int:
        """Number of UAVs N."""
        return int(self.uav_pos.shape[1])

    @property
    def n_obstacles(self) -> int:
        """Number of obstacles M."""
        return int(self.obstacle_pos.shape[1])

    @property
    def names(self) -> tuple[str, ...]:
        """UAV names (always set after validation)."""
        assert self.uav_names is not None
        return self.uav_names

    def settled_mask(self) -> NDArray[np.bool_]:
        """Return the (T,) mask of samples with ``time >= settle_time`` (1e-9 dt tolerance)."""
        return self.time >= self.settle_time - 1e-9 * self.dt

    def first_settled_index(self) -> int:
        """Return the index of the first sample with ``time >= settle_time``."""
        return int(np.argmax(self.settled_mask()))
