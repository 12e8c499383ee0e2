"""Formation geometry: the behaviour method of paper eqs. 5-7 and the planned trajectory.

* Eq. 5: the formation centre ``x_o`` is the mean of the UAVs' states.
* Eq. 6: the formation frame has ``Y_f`` along the mean velocity ``v_o`` and ``X_f`` horizontal.
  The extracted ``C = RotZ(theta) RotX(phi)`` is not trustworthy (at ``theta = phi = 0`` it
  maps ``Y_f`` to east while ``theta`` is measured from north), so this module builds the
  rotation from its definition instead: ``Y_f`` = unit(``v_o``), ``X_f`` = horizontal and to
  the right (starboard) of ``Y_f``, ``Z_f = X_f x Y_f`` (up in level flight). ``C`` has
  columns ``(X_f, Y_f, Z_f)`` in NED, is orthonormal with determinant +1, and equals a
  heading rotation times a pitch rotation (``theta`` from north towards east, ``phi`` the climb
  angle). When ``|v_o|`` is below ``min_speed`` the frame is undefined and the planned
  trajectory's heading is used instead (notes).
* Eq. 7: the desired slot ``p_i^d = C p_i^r + p_o``.

Patterns are centred (their mean is removed) because the behaviour method places the
pattern on the mean position: an off-centre pattern would pull the whole formation.

The planned trajectory is a polyline of way-points flown by the formation centre at a
constant cruise speed from ``t = 0``; each UAV's planned position is the planned centre plus
its slot rotated into the planned heading. Deviation is measured from it.
"""

from __future__ import annotations

import math

import numpy as np

from uasep_env._numba import compiled_twin

__all__ = [
    "PlannedTrajectory",
    "formation_center",
    "pattern_slots",
    "planned_state",
    "rotation_from_velocity",
    "segment_offsets",
    "slot_positions",
]


def pattern_slots(
    pattern: str | tuple[tuple[float, float, float], ...], n: int, spacing: float
) -> np.ndarray:
    """Slots ``p_i^r`` of a formation pattern in the formation frame (m), centred.

    Args:
        pattern: ``"paper"`` (line abreast with the middle UAV last, as in section 4:
            ``[-20,0,0], [20,0,0], [0,0,0]`` for three UAVs), ``"line_abreast"``,
            ``"column"``, ``"v"`` / ``"wedge"``, ``"grid"``, ``"circle"``, or explicit slots.
        n: Number of UAVs.
        spacing: Distance between neighbouring slots (m).

    Returns:
        ``(n, 3)`` slots ``(x right, y forward, z up)`` with zero mean.
    """
    s = float(spacing)
    if not isinstance(pattern, str):
        slots = np.asarray(pattern, dtype=float).reshape(n, 3)
    elif pattern == "paper":
        if n == 3:
            slots = np.array([[-s, 0.0, 0.0], [s, 0.0, 0.0], [0.0, 0.0, 0.0]])
        else:
            slots = pattern_slots("line_abreast", n, s)
    elif pattern == "line_abreast":
        slots = np.stack([(np.arange(n) - (n - 1) / 2) * s, np.zeros(n), np.zeros(n)], axis=1)
    elif pattern == "column":
        slots = np.stack([np.zeros(n), -(np.arange(n) - (n - 1) / 2) * s, np.zeros(n)], axis=1)
    elif pattern in ("v", "wedge"):
        i = np.arange(n)
        rank = (i + 1) // 2  # 0, 1, 1, 2, 2, ...
        side = np.where(i % 2 == 1, -1.0, 1.0)
        slots = np.stack([side * rank * s, -rank * s, np.zeros(n)], axis=1)
    elif pattern == "grid":
        cols = math.ceil(math.sqrt(n))
        i = np.arange(n)
        slots = np.stack([(i % cols) * s, -(i // cols) * s, np.zeros(n)], axis=1)
    elif pattern == "circle":
        radius = s / (2.0 * math.sin(math.pi / n))
        ang = 2.0 * math.pi * np.arange(n) / n
        slots = np.stack([radius * np.sin(ang), radius * np.cos(ang), np.zeros(n)], axis=1)
    else:
        raise ValueError(f"unknown formation pattern {pattern!r}")
    return slots - slots.mean(axis=0, keepdims=True)


#: Below this formation speed (m/s) the frame follows the planned path (notes' fallback).
MIN_FRAME_SPEED = 0.5


def formation_center(pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 5: mean position and velocity over the UAV axis (``axis=-2``).

    Args:
        pos: ``(..., n_uavs, 3)`` positions (m).
        vel: ``(..., n_uavs, 3)`` velocities (m/s).

    Returns:
        ``(p_o, v_o)`` each ``(..., 3)``.
    """
    return _mean_over_uavs(pos), _mean_over_uavs(vel)


def _mean_over_uavs(x: np.ndarray) -> np.ndarray:
    """``x.mean(axis=-2)`` to the bit (numpy adds along that axis in order), but faster.

    A reduction over a short middle axis is slow in numpy; a few in-place adds are not.
    """
    n = x.shape[-2]
    if n > 16:
        return x.mean(axis=-2)
    total = x[..., 0, :].copy()
    for i in range(1, n):
        total += x[..., i, :]
    total /= n
    return total


def rotation_from_velocity(
    vel: np.ndarray, fallback: np.ndarray | None = None, min_speed: float = MIN_FRAME_SPEED
) -> np.ndarray:
    """Eq. 6: rotation ``C`` from the formation frame to NED, from a velocity.

    Args:
        vel: ``(..., 3)`` velocity defining ``Y_f`` (m/s).
        fallback: ``(..., 3)`` velocity used where ``|vel| < min_speed`` (e.g. the planned
            velocity); ``None`` falls back to north.
        min_speed: Below this speed the frame is taken from ``fallback`` (m/s).

    Returns:
        ``(..., 3, 3)`` matrices with columns ``X_f, Y_f, Z_f`` in NED.
    """
    vel = np.asarray(vel, dtype=float)
    speed = np.linalg.norm(vel, axis=-1)
    fast = speed >= min_speed
    use = vel
    if not fast.all():
        if fallback is None:
            fallback = np.broadcast_to(np.array([1.0, 0.0, 0.0]), vel.shape)
        use = np.where(fast[..., None], vel, fallback)
    # Heading theta (from north towards east) and climb angle phi (NED z down) as their
    # cosines and sines, straight from the components: no atan2, cos or sin.
    ux, uy, uz = use[..., 0], use[..., 1], use[..., 2]
    horiz = np.hypot(ux, uy)
    level = horiz > 1e-9  # a vertical fallback velocity has no heading: keep north there
    h = np.maximum(horiz, 1e-12)
    if level.all():  # the usual case: the same numbers, a dozen small calls fewer
        ct, st = ux / horiz, uy / horiz
        r = np.hypot(h, uz)
        cp, sp = h / r, -uz / r
    else:
        safe_h = np.where(level, horiz, 1.0)
        ct = np.where(level, ux / safe_h, 1.0)
        st = np.where(level, uy / safe_h, 0.0)
        still = ~level & (np.abs(uz) <= 1e-9)  # no velocity at all: level flight
        r = np.where(still, 1.0, np.hypot(h, uz))
        cp = np.where(still, 1.0, h / r)
        sp = np.where(still, 0.0, -uz / r)
    rot = np.empty((*ct.shape, 3, 3))
    # Column X_f: starboard, horizontal.
    np.negative(st, out=rot[..., 0, 0])
    rot[..., 1, 0] = ct
    rot[..., 2, 0] = 0.0
    # Column Y_f: along the velocity.
    np.multiply(cp, ct, out=rot[..., 0, 1])
    np.multiply(cp, st, out=rot[..., 1, 1])
    np.negative(sp, out=rot[..., 2, 1])
    # Column Z_f = X_f x Y_f (up when level).
    np.multiply(-ct, sp, out=rot[..., 0, 2])
    np.multiply(-st, sp, out=rot[..., 1, 2])
    np.negative(cp, out=rot[..., 2, 2])
    return rot


def rotate(rot: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``rot @ v`` for every vector: ``(E, 3, 3)`` matrices, ``(E, N, 3)`` vectors.

    Written out as three products: ``einsum`` is several times slower at these shapes.
    """
    r = rot[:, None, :, :]
    return (
        r[..., 0] * vectors[..., 0:1]
        + r[..., 1] * vectors[..., 1:2]
        + r[..., 2] * vectors[..., 2:3]
    )


def slot_positions(
    center: np.ndarray, mean_vel: np.ndarray, planned_dir: np.ndarray, pattern: np.ndarray
) -> np.ndarray:
    """Eq. 7: each UAV's desired slot in NED, ``(E, N, 3)`` (m).

    Args:
        center: ``(E, 3)`` formation centre (eq. 5) (m).
        mean_vel: ``(E, 3)`` formation mean velocity (m/s); orients the frame (eq. 6).
        planned_dir: ``(E, 3)`` planned direction, the frame below ``MIN_FRAME_SPEED``.
        pattern: ``(E, N, 3)`` the pattern's slots in the formation frame (m).
    """
    return center[:, None, :] + rotate(rotation_from_velocity(mean_vel, planned_dir), pattern)


def segment_offsets(direction: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Each UAV's slot rotated into NED along each planned segment (m).

    The planned frame is fixed along a segment, so :meth:`PlannedTrajectory.uav_positions`
    is the centre plus the current segment's offsets: the same numbers, bit for bit.

    Args:
        direction: ``(E, S, 3)`` unit segment directions (:attr:`PlannedTrajectory.direction`).
        slots: ``(E, N, 3)`` pattern slots in the formation frame (m).

    Returns:
        ``(E, S, N, 3)`` offsets from the planned centre (m).
    """
    e, n_seg = direction.shape[:2]
    rot = rotation_from_velocity(direction).reshape(e * n_seg, 3, 3)
    return rotate(rot, np.repeat(slots, n_seg, axis=0)).reshape(e, n_seg, *slots.shape[1:])


def _plan_geometry(wp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative arc length ``(E, W)`` and unit segment directions ``(E, W - 1, 3)``."""
    seg = np.diff(wp, axis=1)
    seg_len = np.linalg.norm(seg, axis=-1)
    cum = np.concatenate([np.zeros((wp.shape[0], 1)), np.cumsum(seg_len, axis=1)], axis=1)
    if (seg_len > 1e-9).all():  # no padding: every segment its own direction, in one call
        return cum, seg / np.maximum(seg_len[..., None], 1e-12)
    # Direction of each segment; padding (zero-length) segments inherit the last one.
    direction = np.zeros_like(seg)
    last = np.zeros((wp.shape[0], 3))
    last[:, 0] = 1.0
    for k in range(seg.shape[1]):
        ok = seg_len[:, k] > 1e-9
        last = np.where(ok[:, None], seg[:, k] / np.maximum(seg_len[:, k, None], 1e-12), last)
        direction[:, k] = last
    return cum, direction


class PlannedTrajectory:
    """Batched polyline trajectories flown by the formation centre at cruise speed.

    Args:
        waypoints: ``(n_envs, W, 3)`` way-points (NED, m); consecutive duplicates allowed
            only at the end (padding).
        cruise_speed: ``(n_envs,)`` or scalar speed along the path (m/s).

    The centre's planned position at time ``t`` is the point at arc length
    ``min(cruise_speed * t, length)``; the planned velocity is ``cruise_speed`` along the
    current segment, zero once the end is reached.
    """

    def __init__(self, waypoints: np.ndarray, cruise_speed: np.ndarray | float) -> None:
        wp = np.asarray(waypoints, dtype=float)
        if wp.ndim != 3 or wp.shape[-1] != 3 or wp.shape[1] < 2:
            raise ValueError(f"waypoints must have shape (n_envs, W>=2, 3), got {wp.shape}")
        # Every row is new: the arrays themselves, not masked writes into zeros (a scenario
        # builds one plan per episode, and small-array calls are most of its cost).
        self.waypoints = wp.copy()
        self.cum, self.direction = _plan_geometry(wp)
        self.length = self.cum[:, -1].copy()
        speed = np.asarray(cruise_speed, dtype=float)
        self.cruise_speed = (
            np.full(wp.shape[0], float(speed))
            if speed.ndim == 0
            else np.array(np.broadcast_to(speed, (wp.shape[0],)))
        )
        self._frozen: PlannedTrajectory | None = None

    @classmethod
    def from_geometry(
        cls, waypoints: np.ndarray, cum: np.ndarray, direction: np.ndarray, cruise_speed: float
    ) -> PlannedTrajectory:
        """The plans whose arc lengths and directions are computed already (taken, not copied).

        ``PlannedTrajectory(waypoints, cruise_speed)`` where ``cum`` and ``direction`` are what
        it would compute (a batched scenario's compiled geometry makes them).
        """
        plan = object.__new__(cls)
        plan.waypoints, plan.cum, plan.direction = waypoints, cum, direction
        plan.length = cum[:, -1].copy()
        plan.cruise_speed = np.full(waypoints.shape[0], float(cruise_speed))
        plan._frozen = None
        return plan

    #: The arrays that hold the trajectories (written in place by :meth:`set_rows`).
    _ARRAYS = ("waypoints", "cum", "direction", "length", "cruise_speed")

    def __getstate__(self) -> dict:
        # A copy (copy.deepcopy, pickle) makes its own views (see World.__getstate__).
        return {**self.__dict__, "_frozen": None}

    def frozen(self) -> PlannedTrajectory:
        """This plan over read-only views of its arrays, made once (they show later writes).

        What the compiled kernels read (their inputs are read-only,
        ``uasep_env._kernels.common.frozen``), without a new view of each array every step.
        """
        if self._frozen is None:
            view = object.__new__(PlannedTrajectory)
            for name in self._ARRAYS:
                arr = getattr(self, name).view()
                arr.flags.writeable = False
                setattr(view, name, arr)
            view._frozen = view
            self._frozen = view
        return self._frozen

    def set_rows(
        self, mask: np.ndarray, waypoints: np.ndarray, cruise_speed: np.ndarray | float
    ) -> None:
        """Replace the trajectories of the environments where ``mask`` (per-env reset).

        Args:
            mask: ``(n_envs,)`` bool.
            waypoints: ``(mask.sum(), W, 3)`` new way-points (m).
            cruise_speed: ``(mask.sum(),)`` or scalar cruise speed (m/s).
        """
        wp = np.asarray(waypoints, dtype=float)
        cum, direction = _plan_geometry(wp)
        self.waypoints[mask] = wp
        self.cum[mask] = cum
        self.length[mask] = cum[:, -1]
        self.direction[mask] = direction
        self.cruise_speed[mask] = np.broadcast_to(
            np.asarray(cruise_speed, dtype=float), (wp.shape[0],)
        )

    def copy_rows(self, mask: np.ndarray, other: PlannedTrajectory) -> None:
        """Replace the trajectories where ``mask`` by ``other``'s (one row per selected env).

        ``mask``: ``(n_envs,)`` bool, or the selected rows' indices in increasing order.

        :meth:`set_rows` with ``other``'s way-points and speeds, its geometry not computed
        again.
        """
        self.waypoints[mask] = other.waypoints
        self.cum[mask] = other.cum
        self.length[mask] = other.length
        self.direction[mask] = other.direction
        self.cruise_speed[mask] = other.cruise_speed

    def center(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Planned centre position and velocity at times ``t`` (``(n_envs,)``, s)."""
        pos, vel, _ = self.center_and_direction(t)
        return pos, vel

    def locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Planned arc length (m) and segment index at times ``t``, ``(n_envs,)`` each."""
        s = np.minimum(self.cruise_speed * np.maximum(t, 0.0), self.length)
        n_seg = self.direction.shape[1]
        return s, np.minimum((self.cum[:, 1:-1] <= s[:, None]).sum(axis=1), n_seg - 1)

    def center_and_direction(
        self, t: np.ndarray, located: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`center` and :meth:`heading_velocity` at once (one segment lookup).

        Args:
            t: ``(n_envs,)`` times (s).
            located: ``self.locate(t)`` if the caller has it already.
        """
        s, idx = self.locate(t) if located is None else located
        rows = np.arange(len(s))
        start = self.waypoints[rows, idx]
        d = self.direction[rows, idx]
        pos = start + (s - self.cum[rows, idx])[:, None] * d
        moving = (self.cruise_speed * t < self.length)[:, None]
        vel = np.where(moving, self.cruise_speed[:, None] * d, 0.0)
        return pos, vel, d

    def heading_velocity(self, t: np.ndarray) -> np.ndarray:
        """Unit direction of the planned path at ``t`` (kept after the end)."""
        _, idx = self.locate(t)
        return self.direction[np.arange(len(idx)), idx]

    def uav_positions(
        self,
        t: np.ndarray,
        slots: np.ndarray,
        center: tuple[np.ndarray, np.ndarray] | None = None,
        direction: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each UAV's planned position and velocity at ``t``.

        Args:
            t: ``(n_envs,)`` times (s).
            slots: ``(n_envs, n_uavs, 3)`` pattern slots in the formation frame (m).
            center: ``self.center(t)`` if the caller has it already.
            direction: ``self.heading_velocity(t)`` if the caller has it already.

        Returns:
            ``(pos, vel)`` each ``(n_envs, n_uavs, 3)``.
        """
        center, vel = self.center(t) if center is None else center
        direction = self.heading_velocity(t) if direction is None else direction
        rot = rotation_from_velocity(direction)  # (E, 3, 3)
        pos = center[:, None, :] + rotate(rot, slots)
        return pos, np.broadcast_to(vel[:, None, :], pos.shape)

    def finished(self, t: np.ndarray) -> np.ndarray:
        """Whether the centre's plan has reached its last way-point at ``t``."""
        return self.cruise_speed * t >= self.length - 1e-9


@compiled_twin("plan_now")
def planned_state(
    plan: PlannedTrajectory, t: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The plan at ``t``: centre, direction, and each UAV's position and velocity.

    Args:
        plan: The planned trajectories.
        t: ``(E,)`` times (s).
        offsets: ``(E, W - 1, N, 3)`` the slots rotated along each segment
            (:func:`segment_offsets`) (m).

    Returns:
        ``(E, 3)`` planned centre (m) and unit direction, ``(E, N, 3)`` planned UAV
        positions (m) and velocities (m/s): :meth:`PlannedTrajectory.uav_positions` with the
        segment's rotated slots looked up rather than rotated again.
    """
    located = plan.locate(t)
    center, center_vel, direction = plan.center_and_direction(t, located)
    pos = center[:, None, :] + offsets[np.arange(len(t)), located[1]]
    vel = np.empty_like(pos)
    vel[...] = center_vel[:, None, :]
    return center, direction, pos, vel
