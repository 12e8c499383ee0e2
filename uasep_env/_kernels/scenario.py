"""A batch of episodes' geometry: :func:`uasep_env.scenarios.batch_geometry.scenario_geometry`.

A partial reset builds a dozen episodes a step; in numpy that is a few hundred calls on
arrays of a dozen rows. The trigonometry is the generator's, Python's ``math`` functions
(the C library's, which numba calls too), so the numbers are the same on any CPU.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from uasep_env._kernels.common import _JIT, _maximum, _minimum, _norm3, frozen


@numba.njit(inline="always", **_JIT)
def _py_max(a, b):  # noqa: ANN001, ANN202
    """Python's ``max(a, b)``: ``a`` unless ``b > a``."""
    return b if b > a else a


@numba.njit(inline="always", **_JIT)
def _py_min(a, b):  # noqa: ANN001, ANN202
    """Python's ``min(a, b)``: ``a`` unless ``b < a``."""
    return b if b < a else a


@numba.njit(inline="always", **_JIT)
def _locate(e, t, cruise_speed, cum, n_seg):  # noqa: ANN001, ANN202
    """``PlannedTrajectory.locate`` of row ``e`` at time ``t``: ``(arc length, segment)``."""
    s = _minimum(cruise_speed * _maximum(t, 0.0), cum[e, n_seg])
    idx = 0
    for k in range(1, cum.shape[1] - 1):
        if cum[e, k] <= s:
            idx += 1
    return s, min(idx, n_seg - 1)


@numba.njit(inline="always", **_JIT)
def _separated(pos, n, separation):  # noqa: ANN001, ANN202
    """Whether no two of the ``n`` points of ``pos`` are within ``separation`` (NaN: no)."""
    for i in range(n):
        for j in range(i + 1, n):  # each pair once: a difference and its negative, one norm
            d = _norm3(pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1], pos[i, 2] - pos[j, 2])
            if not d >= separation:
                return False
    return True


@numba.njit(**_JIT)
def _geometry_rows(  # noqa: ANN202
    lay, ob, slots, cruise_speed, separation, floor, ceiling,  # noqa: ANN001
    n_plan, timeline, altitude, band_half, shrink,  # noqa: ANN001
    wp, cum, direction, offsets, uav_pos, uav_vel, pos, heading, climb, hold, band,  # noqa: ANN001
    edges, start, cand,  # noqa: ANN001
):  # fmt: skip
    """Every row of ``scenario_geometry``; False where a row needs the general path."""
    b, n, m = lay.shape[0], slots.shape[1], ob.shape[1]
    turns = (n_plan - 1) // 3
    n_seg = turns + 1
    legs = cruise_speed * timeline
    for e in range(b):
        # The plan (_plans): legs between the sorted turn places, headings turned in order.
        for k in range(turns):  # the places sorted (np.sort's values): each to its rank
            x = lay[e, 1 + 2 * turns + k]
            rank = 1
            for j in range(turns):
                y = lay[e, 1 + 2 * turns + j]
                if y < x or (y == x and j < k):
                    rank += 1
            edges[rank] = x
        edges[0] = 0.0
        edges[turns + 1] = 1.0
        wp[e, 0, 0] = 0.0
        wp[e, 0, 1] = 0.0
        wp[e, 0, 2] = -altitude
        h = lay[e, 0]
        for k in range(n_seg):
            if k > 0:
                taken = 1.0 if lay[e, turns + k] < 0.5 else 0.0
                h = h + lay[e, k] * taken
            leg = (edges[k + 1] - edges[k]) * legs
            wp[e, k + 1, 0] = wp[e, k, 0] + leg * math.cos(h)
            wp[e, k + 1, 1] = wp[e, k, 1] + leg * math.sin(h)
            wp[e, k + 1, 2] = wp[e, k, 2] + leg * 0.0
        # PlannedTrajectory: arc lengths and unit directions (no padding segment here).
        cum[e, 0] = 0.0
        for k in range(n_seg):
            s0 = wp[e, k + 1, 0] - wp[e, k, 0]
            s1 = wp[e, k + 1, 1] - wp[e, k, 1]
            s2 = wp[e, k + 1, 2] - wp[e, k, 2]
            seg_len = _norm3(s0, s1, s2)
            if not seg_len > 1e-9:
                return False
            cum[e, k + 1] = cum[e, k] + seg_len
            norm = _maximum(seg_len, 1e-12)
            d0, d1, d2 = s0 / norm, s1 / norm, s2 / norm
            direction[e, k, 0] = d0
            direction[e, k, 1] = d1
            direction[e, k, 2] = d2
            # segment_offsets: the frame along the segment (rotation_from_velocity), whose
            # fallbacks (slower than min_frame_speed, or vertical) a unit level direction
            # never takes.
            horiz = math.hypot(d0, d1)
            ct, st = d0 / horiz, d1 / horiz
            hh = _maximum(horiz, 1e-12)
            r = math.hypot(hh, d2)
            cp, sp = hh / r, -d2 / r
            for i in range(n):
                v0, v1, v2 = slots[e, i, 0], slots[e, i, 1], slots[e, i, 2]
                offsets[e, k, i, 0] = (-st * v0 + (cp * ct) * v1) + (-ct * sp) * v2
                offsets[e, k, i, 1] = (ct * v0 + (cp * st) * v1) + (-st * sp) * v2
                offsets[e, k, i, 2] = (0.0 * v0 + (-sp) * v1) + (-cp) * v2
        # The UAVs' starts: the slots at t = 0 plus the scatter, shrunk where crowded.
        s, idx = _locate(e, 0.0, cruise_speed, cum, n_seg)
        for a in range(3):
            c = wp[e, idx, a] + (s - cum[e, idx]) * direction[e, idx, a]
            for i in range(n):
                start[i, a] = c + offsets[e, idx, i, a]
                uav_pos[e, i, a] = start[i, a] + lay[e, n_plan + 3 * i + a]
                scatter = lay[e, n_plan + 3 * n + 3 * i + a]
                uav_vel[e, i, a] = direction[e, 0, a] * cruise_speed + scatter
        if not _separated(uav_pos[e], n, separation):
            # _separated_start: the largest shrink factor that separates them, else the
            # pattern itself.
            found = False
            for f in shrink:
                for i in range(n):
                    for a in range(3):
                        if f < 1.0:
                            cand[i, a] = start[i, a] + f * (uav_pos[e, i, a] - start[i, a])
                        else:
                            cand[i, a] = uav_pos[e, i, a]
                if _separated(cand, n, separation):
                    found = True
                    break
            for i in range(n):
                for a in range(3):
                    uav_pos[e, i, a] = cand[i, a] if found else start[i, a] + 0.0
        # The obstacles, aimed at a UAV's planned position at the meeting time.
        for j in range(m):
            meet = ob[e, j, 0]
            s, idx = _locate(e, meet, cruise_speed, cum, n_seg)
            who = int(ob[e, j, 1])
            along = s - cum[e, idx]
            d = direction[e, idx]
            t0 = (wp[e, idx, 0] + along * d[0]) + offsets[e, idx, who, 0]
            t1 = (wp[e, idx, 1] + along * d[1]) + offsets[e, idx, who, 1]
            t2 = (wp[e, idx, 2] + along * d[2]) + offsets[e, idx, who, 2]
            h = (math.atan2(d[1], d[0]) + ob[e, j, 5]) + ob[e, j, 6]
            climbs = ob[e, j, 9] != 0.0
            target_alt = -t2
            c = 0.0
            if climbs:
                c = _py_min(
                    _py_max(ob[e, j, 8], (target_alt - ceiling) / meet),
                    (target_alt - floor) / meet,
                )
            p0 = t0 + 0.0
            p1 = t1 + 0.0
            p2 = t2 + (0.0 if climbs else ob[e, j, 7])
            speed = ob[e, j, 4]
            p0 = p0 - speed * math.cos(h) * meet
            p1 = p1 - speed * math.sin(h) * meet
            p2 = p2 + c * meet
            p2 = -_py_min(_py_max(-p2, floor), ceiling)
            pos[e, j, 0] = p0
            pos[e, j, 1] = p1
            pos[e, j, 2] = p2
            heading[e, j] = (h + math.pi) % (2 * math.pi) - math.pi
            climb[e, j] = c
            hold[e, j] = _py_max(0.0, meet - ob[e, j, 10])
            alt = -p2
            band[e, j, 0] = _maximum(_minimum(altitude - band_half, alt), floor)
            band[e, j, 1] = _minimum(_maximum(altitude + band_half, alt), ceiling)
    return True


def scenario_geometry(
    lay: np.ndarray,
    ob: np.ndarray,
    slots: np.ndarray,
    cruise_speed: float,
    extra: float,
    separation: float,
    floor: float,
    ceiling: float,
    *,
    n_plan: int,
    timeline: float,
    altitude: float,
    band_half: float,
    shrink: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Compiled :func:`uasep_env.scenarios.batch_geometry.scenario_geometry`.

    Declines (``NotImplemented``: numpy builds them) plans flown on past the timeline and
    rows with a zero-length segment (which a random plan draws with probability 0).
    """
    if extra > 0.0:
        return NotImplemented
    b, n, m = lay.shape[0], slots.shape[1], ob.shape[1]
    w = (n_plan - 1) // 3 + 2
    wp, cum = np.empty((b, w, 3)), np.empty((b, w))
    direction, offsets = np.empty((b, w - 1, 3)), np.empty((b, w - 1, n, 3))
    uav_pos, uav_vel = np.empty((b, n, 3)), np.empty((b, n, 3))
    pos, band = np.empty((b, m, 3)), np.empty((b, m, 2))
    heading, climb, hold = np.empty((b, m)), np.empty((b, m)), np.empty((b, m))
    ok = _geometry_rows(
        frozen(lay), frozen(ob), frozen(slots), float(cruise_speed), float(separation),
        float(floor), float(ceiling), n_plan, float(timeline), float(altitude),
        float(band_half), frozen(shrink),
        wp, cum, direction, offsets, uav_pos, uav_vel, pos, heading, climb, hold, band,
        np.empty(w), np.empty((n, 3)), np.empty((n, 3)),
    )  # fmt: skip
    if not ok:
        return NotImplemented
    return (wp, cum, direction, offsets, uav_pos, uav_vel, pos, heading, climb, hold, band)
