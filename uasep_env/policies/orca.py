"""Optimal Reciprocal Collision Avoidance (ORCA) in 3D, as in RVO2-3D.

After van den Berg, Guy, Lin and Manocha, "Reciprocal n-body collision avoidance" (ISRR 2009 /
STAR 70, 2011) and the RVO2-3D library (UNC). For every neighbour ``j`` (an observed UAV or
obstacle) with relative position ``p = p_j - p_i``, relative velocity ``v_rel = v_i - v_j`` and
combined radius ``R``, the velocity obstacle truncated at the time horizon ``tau`` is the cone
of relative velocities that bring the two within ``R`` before ``tau``. ``u`` is the smallest
change of ``v_rel`` that leaves it (onto the cut-off sphere of centre ``p / tau`` and radius
``R / tau``, or onto the cone's side; inside ``R`` already, onto the sphere of one step), and
the ORCA half-space is

    ``{v : (v - (v_i + r u)) . n >= 0}``, ``n = u / |u|`` (the outward normal),

with ``r`` the agent's responsibility: 1/2 between UAVs (both avoid: reciprocal), 1 against
an obstacle (it does not avoid). The new velocity is the one closest to the preferred
velocity inside every half-space and the max-speed sphere: the small program (quadratic
objective) of :func:`solve_orca_lp`, solved exactly over every active set (RVO2's
incremental algorithm lost nearly parallel planes); if the half-spaces leave no velocity
(dense traffic),
RVO2's fallback picks the velocity that violates them least (the 4-D program of
``linearProgram4``: minimise the largest violation).

The preferred velocity tracks the plan: the velocity the shared plan tracking
(:func:`~uasep_env.policies.nominal.plan_tracking`) would reach over ``response_time``,
``v_pref = v + a_nom T``; the command is ``(v_new - v) / T``, bounded as every controller's
(:func:`~uasep_env.policies.nominal.bounded_action`). Without a binding constraint ORCA
therefore flies the plan tracking exactly.

Batched: the half-spaces of every agent of every environment are built in numpy; an agent
whose preferred velocity (within the speed sphere) satisfies them all takes it (most agents,
most steps); the others, a few per step, solve their program in a loop over the agent's
few constraints in plain Python floats (documented choice: the incremental algorithm is
sequential; each agent's result depends on its own row only, so batched equals per-agent).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.config.checks import check, check_positive
from uasep_env.policies.nominal import norm, plan_tracking
from uasep_env.policies.registry import register_policy
from uasep_env.policies.tracking import TrackingController

__all__ = ["ORCA", "ORCAParams", "orca_planes", "solve_orca_lp"]

_EPS = 1e-5  # RVO2's RVO_EPSILON: parallel lines/planes
_PARAM_MAX = 1e4

Vec = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True)
class ORCAParams:
    """Parameters of :class:`ORCA` (units in comments; the source of each default).

    Attributes:
        time_horizon: ``tau`` between UAVs (s): collisions later than this are ignored.
            RVO2-3D's example uses 10 s; 5 s here, so formation neighbours 20 m apart at
            equal speeds do not constrain each other (their truncated cone then lies
            beyond ``R / tau`` = 1.6 m/s of relative speed).
        obstacle_time_horizon: ``tau`` against obstacles (s): the APF's prediction horizon
            ``K_s`` (10 s), so the methods look equally far at the intruder.
        margin_scale: Multiplies the combined radii (the trade-off sweep's knob; default
            1.5, the knee of ORCA's front on the ``-v3`` validation bank).
        uav_responsibility: Share of a UAV-UAV half-space each UAV takes (ORCA: 1/2).
        obstacle_responsibility: Share against an obstacle (1: it does not avoid).
        response_time: ``T`` (s): ``v_pref = v + a_nom T`` and the command
            ``(v_new - v) / T``. 1 s, as MVP's.
        uav_radius: Combined radius between UAVs (m); None: ``uav.separation_distance``
            (ORCA has no margin of its own: the zone is the separation threshold).
        obstacle_radius: Combined radius from an obstacle's centre (m); None:
            ``uav.obstacle_separation``.
    """

    time_horizon: float = 5.0  # s
    obstacle_time_horizon: float = 10.0  # s
    # The knee of ORCA's front on the -v3 validation bank (docs/figures/tradeoff.md).
    margin_scale: float = 1.5  # -
    uav_responsibility: float = 0.5  # -
    obstacle_responsibility: float = 1.0  # -
    response_time: float = 1.0  # s
    uav_radius: float | None = None  # m
    obstacle_radius: float | None = None  # m

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                zero_ok = f.name in ("margin_scale", "uav_responsibility")
                check_positive(f"orca.{f.name}", value, allow_zero=zero_ok, hi=_PARAM_MAX)
        for name in ("uav_responsibility", "obstacle_responsibility"):
            value = getattr(self, name)
            check(value <= 1.0, f"orca.{name}", value, "must be <= 1")


def orca_planes(
    rel_pos: np.ndarray,
    rel_vel: np.ndarray,
    velocity: np.ndarray,
    radius: float,
    time_horizon: float,
    time_step: float,
    responsibility: float,
) -> tuple[np.ndarray, np.ndarray]:
    """ORCA half-spaces ``{v : (v - point) . normal >= 0}`` for each neighbour (batched).

    Args:
        rel_pos: ``p_j - p_i``, ``(..., K, 3)`` (m).
        rel_vel: ``v_i - v_j``, ``(..., K, 3)`` (m/s).
        velocity: ``v_i``, ``(..., 3)`` (m/s).
        radius: Combined radius ``R`` (m).
        time_horizon: ``tau`` (s).
        time_step: The step (s): inside ``R`` the pair is separated within one step.
        responsibility: Share ``r`` of the change the agent takes.

    Returns:
        ``(normals, points)``, each ``(..., K, 3)``.
    """
    dist_sq = np.einsum("...i,...i->...", rel_pos, rel_pos)
    r_sq = radius * radius
    inv_tau = 1.0 / time_horizon
    # Outside: the cut-off sphere (centre p / tau, radius R / tau) or the cone's side.
    w = rel_vel - inv_tau * rel_pos
    w_sq = np.einsum("...i,...i->...", w, w)
    dot = np.einsum("...i,...i->...", w, rel_pos)
    on_sphere = (dot < 0.0) & (dot * dot > r_sq * w_sq)
    w_len = np.sqrt(np.maximum(w_sq, 1e-24))
    n_sphere = w / w_len[..., None]
    u_sphere = (radius * inv_tau - w_len)[..., None] * n_sphere
    # Cone side: the leg the relative velocity is nearest to, in the plane of the axis and
    # ``v_rel`` (the cone is circular): leg ``l = cos a p^ + sin a e``, outward normal
    # ``n = cos a e - sin a p^`` (``sin a = R / |p|``, ``e`` the unit part of ``v_rel``
    # across the axis) and ``u = -(v_rel . n) n``. RVO2's closed form is the same point but
    # loses ``n`` to cancellation near the axis (exactly head-on it gave ``n = 0``, no
    # constraint); on the axis (within 1e-9 rad) there is no nearest leg and the right one
    # is taken (``e = down x p^``, right of the line of sight: the rules of the air; both
    # agents of a pair turn right, as ``e`` is odd in ``p``; straight above or below, east
    # or west by the sign of ``p_z``).
    dist = np.sqrt(np.maximum(dist_sq, 1e-24))
    axis = rel_pos / dist[..., None]
    across = rel_vel - np.einsum("...i,...i->...", rel_vel, axis)[..., None] * axis
    across_len = norm(across)
    right = np.cross(np.array([0.0, 0.0, 1.0]), axis)
    right_len = norm(right)
    east = np.stack([np.zeros_like(dist), np.where(rel_pos[..., 2] < 0.0, -1.0, 1.0),
                     np.zeros_like(dist)], axis=-1)  # fmt: skip
    right = np.where((right_len > 1e-9)[..., None], right / np.maximum(right_len, 1e-300)[
        ..., None], east)  # fmt: skip
    on_axis = across_len <= 1e-9 * norm(rel_vel)
    e = np.where(on_axis[..., None], right, across / np.maximum(across_len, 1e-300)[..., None])
    sin_a = np.minimum(radius / dist, 1.0)
    cos_a = np.sqrt(np.maximum(1.0 - sin_a * sin_a, 0.0))
    n_cone = cos_a[..., None] * e - sin_a[..., None] * axis
    u_cone = -np.einsum("...i,...i->...", rel_vel, n_cone)[..., None] * n_cone
    # Inside R: leave the sphere of one step (centre p / dt, radius R / dt).
    inv_dt = 1.0 / time_step
    w_in = rel_vel - inv_dt * rel_pos
    wi_len = np.maximum(norm(w_in), 1e-12)
    n_in = w_in / wi_len[..., None]
    u_in = (radius * inv_dt - wi_len)[..., None] * n_in
    outside = (dist_sq > r_sq)[..., None]
    sphere = on_sphere[..., None]
    normal = np.where(outside, np.where(sphere, n_sphere, n_cone), n_in)
    u = np.where(outside, np.where(sphere, u_sphere, u_cone), u_in)
    point = velocity[..., None, :] + responsibility * u
    return normal, point


# -- the linear programs (RVO2-3D's incremental algorithm, in plain floats) --------------
def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _add(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _mul(k: float, a: Vec) -> Vec:
    return (k * a[0], k * a[1], k * a[2])


def _cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _unit(a: Vec) -> Vec:
    n = math.sqrt(_dot(a, a))
    return _mul(1.0 / n, a) if n > 0.0 else a


Plane = tuple[Vec, Vec]  # (normal, point): feasible where (v - point) . normal >= 0


def _violated(plane: Plane, v: Vec, slack: float = 0.0) -> bool:
    return _dot(plane[0], _sub(plane[1], v)) > slack


def _lp1(
    planes: Sequence[Plane], k: int, line: tuple[Vec, Vec], radius: float, opt: Vec,
    direction: bool,
) -> Vec | None:  # fmt: skip
    """Best point on ``line`` (point, unit direction) within the sphere and planes < k."""
    point, d = line
    dp = _dot(point, d)
    disc = dp * dp + radius * radius - _dot(point, point)
    if disc < 0.0:
        return None  # the speed sphere misses the line
    sq = math.sqrt(disc)
    lo, hi = -dp - sq, -dp + sq
    for normal, p in planes[:k]:
        num = _dot(_sub(p, point), normal)
        den = _dot(d, normal)
        if den * den <= _EPS:  # parallel: all or nothing
            if num > 0.0:
                return None
            continue
        t = num / den
        if den >= 0.0:
            lo = max(lo, t)
        else:
            hi = min(hi, t)
        if lo > hi:
            return None
    if direction:
        t = hi if _dot(opt, d) > 0.0 else lo
    else:
        t = min(max(_dot(d, _sub(opt, point)), lo), hi)
    return _add(point, _mul(t, d))


def _lp2(planes: Sequence[Plane], k: int, radius: float, opt: Vec, direction: bool) -> Vec | None:
    """Best point on plane ``k`` within the sphere and planes < k."""
    normal, p = planes[k]
    plane_dist = _dot(p, normal)
    if plane_dist * plane_dist > radius * radius:
        return None  # the speed sphere misses the plane
    disc_r_sq = radius * radius - plane_dist * plane_dist
    centre = _mul(plane_dist, normal)
    if direction:
        proj = _sub(opt, _mul(_dot(opt, normal), normal))
        proj_sq = _dot(proj, proj)
        if proj_sq <= _EPS:
            result = centre
        else:
            result = _add(centre, _mul(math.sqrt(disc_r_sq / proj_sq), proj))
    else:
        result = _add(opt, _mul(_dot(_sub(p, opt), normal), normal))
        if _dot(result, result) > radius * radius:
            off = _sub(result, centre)
            result = _add(centre, _mul(math.sqrt(disc_r_sq / _dot(off, off)), off))
    for i in range(k):
        if _violated(planes[i], result):
            cr = _cross(planes[i][0], normal)
            if _dot(cr, cr) <= _EPS:
                return None  # parallel and plane i excludes plane k
            d = _unit(cr)
            line_normal = _cross(d, normal)
            s = _dot(_sub(planes[i][1], p), planes[i][0]) / _dot(line_normal, planes[i][0])
            result = _lp1(planes, i, (_add(p, _mul(s, line_normal)), d), radius, opt, direction)
            if result is None:
                return None
    return result


def _lp3(planes: Sequence[Plane], radius: float, opt: Vec, direction: bool) -> tuple[int, Vec]:
    """RVO2's ``linearProgram3``: (index of the first infeasible plane or len, result)."""
    if direction:
        result = _mul(radius, opt)
    elif _dot(opt, opt) > radius * radius:
        result = _mul(radius, _unit(opt))
    else:
        result = opt
    for i in range(len(planes)):
        if _violated(planes[i], result):
            new = _lp2(planes, i, radius, opt, direction)
            if new is None:
                return i, result
            result = new
    return len(planes), result


def _lp4(planes: Sequence[Plane], begin: int, radius: float, result: Vec) -> Vec:
    """RVO2's ``linearProgram4``: the velocity violating the planes least (infeasible case)."""
    distance = 0.0
    for i in range(begin, len(planes)):
        ni, pi = planes[i]
        if _dot(ni, _sub(pi, result)) > distance:
            projected: list[Plane] = []
            for j in range(i):
                nj, pj = planes[j]
                cr = _cross(nj, ni)
                if _dot(cr, cr) <= _EPS:
                    if _dot(ni, nj) > 0.0:
                        continue  # same direction: plane i is the binding one
                    point = _mul(0.5, _add(pi, pj))
                else:
                    line_normal = _cross(cr, ni)
                    s = _dot(_sub(pj, pi), nj) / _dot(line_normal, nj)
                    point = _add(pi, _mul(s, line_normal))
                projected.append((_unit(_sub(nj, ni)), point))
            fail, new = _lp3(projected, radius, ni, True)
            if fail >= len(projected):  # else rounding: keep the current result
                result = new
            distance = _dot(ni, _sub(pi, result))
    return result


# -- the exact program: every active set, solved in closed form --------------------------
#: A normal whose part orthogonal to the earlier ones of its set is shorter than this is
#: their combination (a duplicate or parallel plane, to within 1e-12 rad): dropped from the
#: set. The set without it is a candidate too, and within that angle its point violates the
#: dropped plane by under 1e-12 of the speeds involved, well inside the tolerance below.
_DEPENDENT = 1e-12
#: Feasibility tolerance of a candidate, relative to the largest speed of the program
#: (round-off level: the orthogonalised systems below are backward stable).
_FEAS_TOL = 1e-9


@functools.lru_cache(maxsize=32)
def _plane_sets(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Every set of at most three of ``k`` planes: indices ``(C, 3)`` (padded) and sizes."""
    sets = [c for m in range(4) for c in itertools.combinations(range(k), m)]
    idx = np.array([c + (0,) * (3 - len(c)) for c in sets], dtype=np.intp).reshape(-1, 3)
    return idx, np.array([len(c) for c in sets], dtype=np.intp)


def _dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a . b`` over the last axis (3), added left to right (no BLAS: the same everywhere)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _exact_program(
    normals: np.ndarray, offsets: np.ndarray, preferred: np.ndarray, max_speed: float
) -> np.ndarray | None:
    """The optimum of the program, or None where it has no feasible velocity.

    ``argmin |v - v_pref|`` s.t. ``n_k . v >= c_k`` and ``|v| <= V``: strictly convex, so
    its minimiser is unique and, on its active set ``S`` (at most three planes with
    independent normals, and perhaps the sphere), is the point of the ball's section by the
    planes' common affine subspace ``A_S`` nearest ``v_pref``. Every set of at most three
    planes is tried: its normals are orthonormalised in order (modified Gram-Schmidt,
    twice; a dependent normal, a duplicate or (nearly) parallel plane, is dropped), which
    gives ``A_S`` as ``E v = beta`` with ``E`` orthonormal, then the projection ``q`` of
    ``v_pref`` on ``A_S``, the centre ``c`` of the section and its radius, and the
    candidate: ``q`` if inside the section, else its radial projection onto the section's
    boundary. Every candidate that satisfies all constraints (to round-off) is a feasible
    velocity and the optimum is one of them: the nearest to ``v_pref`` is the optimum.
    Backward stable, so nearly parallel or duplicated binding planes (where RVO2-3D's
    incremental program declares the program infeasible) are solved like any other.
    """
    k = normals.shape[0]
    if k == 0:
        speed = norm(preferred)
        return preferred * min(1.0, max_speed / speed) if speed > 0.0 else preferred
    idx, size = _plane_sets(k)
    n_s = normals[idx]  # (C, 3, 3): the rows of each set
    c_s = offsets[idx]  # (C, 3)
    scale = 1.0 + max(max_speed, float(np.abs(offsets).max(initial=0.0)), norm(preferred))
    basis: list[np.ndarray] = []
    beta: list[np.ndarray] = []
    for j in range(3):
        e = n_s[:, j, :]
        rhs = c_s[:, j]
        for _ in range(2):  # twice is enough (Giraud et al. 2005)
            for ei, bi in zip(basis, beta, strict=True):
                r = _dot3(e, ei)
                e = e - r[:, None] * ei
                rhs = rhs - r * bi
        length = np.sqrt(_dot3(e, e))
        keep = (j < size) & (length > _DEPENDENT)
        inv = np.where(keep, 1.0 / np.where(keep, length, 1.0), 0.0)
        basis.append(e * inv[:, None])
        beta.append(rhs * inv)
    q = preferred[None, :] + sum(
        (bj - _dot3(ej, preferred[None, :]))[:, None] * ej
        for ej, bj in zip(basis, beta, strict=True)
    )
    centre = sum(bj[:, None] * ej for ej, bj in zip(basis, beta, strict=True))
    radius_sq = max_speed * max_speed - _dot3(centre, centre)
    off = q - centre
    off_sq = _dot3(off, off)
    outside = off_sq > np.maximum(radius_sq, 0.0)
    shrink = np.sqrt(np.maximum(radius_sq, 0.0) / np.where(outside, off_sq, 1.0))
    v = np.where(outside[:, None], centre + shrink[:, None] * off, q)  # (C, 3)
    tol = _FEAS_TOL * scale
    slack = np.einsum("ki,ci->ck", normals, v) - offsets[None, :]  # (C, K)
    ok = (slack.min(axis=-1, initial=np.inf) >= -tol) & (np.sqrt(_dot3(v, v)) <= max_speed + tol)
    if not ok.any():
        return None
    dist = _dot3(v - preferred[None, :], v - preferred[None, :])
    return v[np.argmin(np.where(ok, dist, np.inf))]


def solve_orca_lp(
    normals: np.ndarray, points: np.ndarray, preferred: np.ndarray, max_speed: float
) -> np.ndarray:
    """The velocity nearest ``preferred`` in every half-space and the speed sphere.

    ``argmin |v - v_pref|`` s.t. ``(v - point_k) . normal_k >= 0`` and ``|v| <= max_speed``:
    exact where the half-spaces and the sphere leave a velocity (every active set in closed
    form, :func:`_exact_program`; nearly parallel and duplicated planes included), and
    RVO2-3D's fallback (``linearProgram4``, the least largest violation) where they leave
    none.

    Args:
        normals: ``(K, 3)`` unit normals.
        points: ``(K, 3)`` points on the planes.
        preferred: ``(3,)`` the preferred velocity.
        max_speed: Radius of the speed sphere.

    Returns:
        ``(3,)`` the new velocity.
    """
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    pref = np.asarray(preferred, dtype=float).reshape(3)
    offsets = _dot3(normals, points)
    exact = _exact_program(normals, offsets, pref, float(max_speed))
    if exact is not None:
        return np.array(exact, dtype=float)
    planes = [
        (tuple(map(float, n)), tuple(map(float, p))) for n, p in zip(normals, points, strict=True)
    ]
    opt = tuple(map(float, pref))
    fail, result = _lp3(planes, float(max_speed), opt, False)  # type: ignore[arg-type]
    if fail < len(planes):
        result = _lp4(planes, fail, float(max_speed), result)  # type: ignore[arg-type]
    return np.array(result, dtype=float)


@register_policy("orca", label="ORCA", reference=True, default_margin=1.5)
class ORCA(TrackingController):
    """ORCA velocity selection on the shared plan tracking (batched numpy + small LPs).

    Args:
        config: The environment config (observation layout, bounds, separation radii).
        params: :class:`ORCAParams` (default: the defaults).
    """

    name = "orca"
    params_type = ORCAParams

    def __init__(self, config: EnvConfig, params: ORCAParams | None = None) -> None:
        super().__init__(config, params)
        p = self.params
        r_uav, r_obs = self.separations(p.uav_radius, p.obstacle_radius)
        self.uav_radius = p.margin_scale * r_uav  # m
        self.obstacle_radius = p.margin_scale * r_obs  # m

    def planes(self, o: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every agent's half-spaces: ``(normals, points, active)``, ``(..., K_u + K_o, ...)``."""
        p, dt = self.params, self.config.step_duration
        v = o["velocity"]
        n_u, q_u = orca_planes(
            o["uav_rel_pos"], -o["uav_rel_vel"], v, self.uav_radius, p.time_horizon, dt,
            p.uav_responsibility,
        )  # fmt: skip
        n_o, q_o = orca_planes(
            o["obstacle_rel_pos"], -o["obstacle_rel_vel"], v, self.obstacle_radius,
            p.obstacle_time_horizon, dt, p.obstacle_responsibility,
        )  # fmt: skip
        active = np.concatenate([o["uav_mask"], o["obstacle_mask"]], axis=-1)
        return np.concatenate([n_u, n_o], axis=-2), np.concatenate([q_u, q_o], axis=-2), active

    def new_velocity(self, o: dict[str, np.ndarray], preferred: np.ndarray) -> np.ndarray:
        """ORCA's velocity for each agent, ``(..., 3)`` (m/s)."""
        normals, points, active = self.planes(o)
        vmax = self.config.uav.max_speed
        speed = norm(preferred)
        start = preferred * np.minimum(1.0, vmax / np.maximum(speed, 1e-12))[..., None]
        slack = np.einsum("...ki,...ki->...k", normals, points - start[..., None, :])
        need = (active & (slack > 0.0)).any(axis=-1)
        out = start.reshape(-1, 3).copy()
        k = active.shape[-1]
        flat_n, flat_q = normals.reshape(-1, k, 3), points.reshape(-1, k, 3)
        flat_a, flat_p = active.reshape(-1, k), preferred.reshape(-1, 3)
        for i in np.flatnonzero(need.reshape(-1)):  # the few constrained agents
            keep = flat_a[i]
            out[i] = solve_orca_lp(flat_n[i][keep], flat_q[i][keep], flat_p[i], vmax)
        return out.reshape(start.shape)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(..., 3)`` for observations ``(..., obs_dim)``."""
        o = self.layout.decode(np.asarray(observations))
        t = self.params.response_time
        v = o["velocity"]
        v_new = self.new_velocity(o, v + plan_tracking(o, self.tracking) * t)
        return self.bounded((v_new - v) / t, v).astype(np.float32)
