"""The compiled kernels return the numpy forms' numbers bit for bit."""

from __future__ import annotations

import copy
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import HANG_GUARD_S

# Importing the modules registers their twins.
from uasep_env import (  # noqa: F401
    _numba,
    config,
    dynamics,
    estimation,
    formation,
    geometry,
    noise,
    observation,
    obstacles,
    outcome,
    physics_step,
    reachable,
    rewards,
)
from uasep_env.policies import learned  # noqa: F401 (registers the network's twin)
from uasep_env.reachable import distance

pytestmark = pytest.mark.skipif(
    not _numba.available(), reason="numba not installed or UASEP_NUMBA=0"
)


def _kernel(name: str):
    """The compiled kernel ``name`` with the constants its numpy module gives it."""
    return _numba.TWINS[name].compiled()


def _numpy_nearest(points, centers, axes, headings):
    q, cp, sp = distance._to_body(points, centers, headings)
    x, dist, n = distance._nearest_body(q, axes)
    cp, sp = np.broadcast_arrays(cp, sp, dist)[:2]
    offset = distance._to_world(np.broadcast_to(x, (*dist.shape, 3)), cp, sp)
    return offset, dist, distance._to_world(np.broadcast_to(n, (*dist.shape, 3)), cp, sp)


def _cases(rng: np.random.Generator, k: int) -> tuple[np.ndarray, ...]:
    """Random points and ellipsoids plus the degenerate ones the numpy tests cover."""
    axes = rng.uniform(0.0, 40.0, size=(k, 3))
    axes[: k // 8, rng.integers(0, 3)] = 0.0  # flat and needle-like ellipsoids
    axes[k // 8 : k // 4] = axes[k // 8 : k // 4, :1]  # spheres (equal axes)
    axes[k // 4 : k // 4 + 5] = 0.0  # points
    centers = rng.normal(0.0, 30.0, size=(k, 3))
    pts = centers + rng.normal(0.0, 1.0, size=(k, 3)) * rng.choice([0.1, 5.0, 50.0, 1e7], (k, 1))
    pts[k // 2 : k // 2 + 20] = centers[k // 2 : k // 2 + 20]  # at the centre
    on_axis = slice(k // 2 + 20, k // 2 + 60)
    pts[on_axis, 1:] = centers[on_axis, 1:]  # on an axis (heading 0 below)
    heading = rng.uniform(-np.pi, np.pi, size=k)
    heading[on_axis] = 0.0
    return pts, centers, axes, heading


def test_nearest_point_kernel_matches_numpy_bit_for_bit():

    pts, ctr, ax, hd = _cases(np.random.default_rng(0), 4000)
    want = _numpy_nearest(pts, ctr, ax, hd)
    got = _kernel("nearest_on_ellipsoids")(pts, ctr, ax, hd)
    for w, g in zip(want, got, strict=True):
        assert np.all(np.isfinite(g))
        _assert_bits(g, w)


@pytest.fixture
def parallel_loops(monkeypatch):
    """The parallel loops run for big calls, whatever this machine's core count decides."""
    from uasep_env._kernels import common

    monkeypatch.setattr(common, "THREADS", [2])


def test_parallel_and_serial_loops_agree(parallel_loops):
    from uasep_env._kernels import common

    pts, ctr, ax, hd = _cases(np.random.default_rng(1), 2 * common.PARALLEL_MIN)
    big = _kernel("nearest_on_ellipsoids")(pts, ctr, ax, hd)
    small = [_kernel("nearest_on_ellipsoids")(*(a[:100] for a in (pts, ctr, ax, hd)))]
    for b, s in zip(big, small[0], strict=True):
        _assert_bits(b[:100], s)


def _copy(x):
    """A deep copy of an argument: arrays and tuples of arrays copied, the rest shared."""
    if isinstance(x, np.ndarray):
        if x.flags.c_contiguous:
            return x.copy()
        y = np.zeros((*x.shape, 2), x.dtype)[..., 0]  # a strided view stays one
        y[...] = x
        return y
    if isinstance(x, tuple) and hasattr(x, "_fields"):
        return type(x)(*(_copy(a) for a in x))
    if isinstance(x, tuple):
        return tuple(_copy(a) for a in x)
    if isinstance(x, list):  # generators: each copied with its state
        return [copy.deepcopy(g) for g in x]
    if isinstance(x, obstacles.ObstacleState):
        state = copy.copy(x)
        for name, value in vars(x).items():
            setattr(state, name, _copy(value))
        return state
    return x


def _assert_bits(got, want, where: str = "") -> None:
    """Same dtype, shape and bits (``-0.0`` is not ``0.0``, every NaN payload counts)."""
    assert isinstance(got, np.ndarray), where
    assert (got.dtype, got.shape) == (want.dtype, want.shape), where
    if want.dtype.kind != "f":
        np.testing.assert_array_equal(got, want, err_msg=where)
        return
    u = np.dtype(f"u{want.dtype.itemsize}")
    same = np.ascontiguousarray(got).view(u) == np.ascontiguousarray(want).view(u)
    if not same.all():
        bad = np.argwhere(~same)
        first = tuple(int(k) for k in bad[0])
        raise AssertionError(
            f"{where}: {len(bad)} of {same.size} values differ in their bits; the first at "
            f"{first}: got {got[first]!r}, want {want[first]!r}"
        )


def _assert_same(got, want, where: str) -> None:
    if isinstance(want, tuple):
        assert isinstance(got, tuple) and len(got) == len(want), where
        for k, (g, w) in enumerate(zip(got, want, strict=True)):
            _assert_same(g, w, f"{where}[{k}]")
    elif isinstance(want, np.ndarray):
        _assert_bits(got, want, where)
    elif isinstance(want, list):  # generators: left in the same state
        assert len(got) == len(want), where
        for g, w in zip(got, want, strict=True):
            np.testing.assert_equal(g.bit_generator.state, w.bit_generator.state, err_msg=where)
    elif isinstance(want, obstacles.ObstacleState):  # updated in place: every attribute
        assert vars(got).keys() == vars(want).keys(), where
        for name, value in vars(want).items():
            _assert_bits(getattr(got, name), value, f"{where}.{name}")
    else:
        assert got == want, where


def _world_case(n_envs: int = 40):
    from uasep_env.envs.core import EnvCore

    core = EnvCore({"n_uavs": 4, "n_obstacles": 3, "scenario": "random"}, n_envs)
    core.reset(seed=3)
    rng = np.random.default_rng(4)
    for _ in range(8):
        core.step(rng.uniform(-1, 1, size=(n_envs, 4, 3)))
    core.world.obstacles.active[::4, 1] = False
    return core


# Each case builder returns a list of argument tuples: random states plus the ones that take
# every branch of the kernel (ties, zero and infinite distances, absent slots, clipping, ...).
# The comparison is in float64, before any cast to float32: a float64 sum added in another
# order differs in the last bits, which a float32 output would round away.


def _degenerate_ellipsoids():
    """Points on, in and beside flat, needle, point-like and extremely thin ellipsoids."""
    axes_list, offsets = [], []
    thin = 1e-170  # the axis ratio overflows the level set's value
    shapes = [
        (0.0, 0.0, 0.0),
        (10.0, 0.0, 0.0),
        (0.0, 10.0, 0.0),
        (0.0, 0.0, 10.0),
        (0.0, 8.0, 12.0),
        (8.0, 0.0, 12.0),
        (8.0, 12.0, 0.0),
        (thin, 30.0, 30.0),
        (30.0, thin, 30.0),
        (30.0, 30.0, thin),
        (6.0, 9.0, 14.0),
        (7.0, 7.0, 7.0),
    ]
    for a in shapes:
        a = np.array(a)
        on_axes = np.diag(a)  # on the surface at the end of each axis (or at the centre)
        for off in (np.zeros(3), *on_axes, *(0.5 * on_axes), *(on_axes + 3.0), 0.3 * a,
                    np.array([2.0, -3.0, 5.0]), 2.0 * a + 1.0):  # fmt: skip
            axes_list.append(a)
            offsets.append(off)
    k = len(axes_list)
    centers = np.random.default_rng(23).normal(0, 20, size=(k, 3))
    heading = np.zeros(k)
    heading[1::2] = np.pi / 2  # a right angle keeps the surface points on it (near enough)
    return centers + np.array(offsets), centers, np.array(axes_list), heading


def _case_nearest():
    return [_cases(np.random.default_rng(20), 500), _degenerate_ellipsoids()]


def _case_pairwise():
    rng = np.random.default_rng(21)
    e, n, m = 20, 4, 3
    pts, ctr, ax, hd = _cases(rng, e * n * m)  # the degenerate ellipsoids and points
    ax, hd = ax[: e * m].reshape(e, m, 3), hd[: e * m].reshape(e, m)
    ctr = ctr[: e * m].reshape(e, m, 3)
    points = pts.reshape(e, n * m, 3)[:, :n].copy()
    points[:4, 0] = ctr[:4, 0]  # at a centre
    points[4:8, 1, 1:] = ctr[4:8, 1, 1:]  # on an axis
    hd[4:8, 1] = 0.0
    return [(points, ctr, ax, hd)]


def _case_region():
    w = _world_case().world
    est = w.est_pos.copy()
    est[1::3, 0] = w.pred_center[1::3, 0]  # inside a region (its centre)
    est[2::5, 2] = w.pred_center[2::5, 2] + 0.5 * w.pred_axes[2::5, 2]
    return [(est, w.pred_center, w.pred_axes, w.pred_heading, w.pred_cos, w.pred_sin,
             w.obstacles.active)]  # fmt: skip


def _case_separations():
    w = _world_case().world
    pos, ob, active = w.uav_pos.copy(), w.obstacles.pos.copy(), w.obstacles.active.copy()
    pos[0, 1] = pos[0, 0]  # two UAVs at one point
    ob[1, 0] = pos[1, 2]  # an obstacle at a UAV
    active[2] = False  # no obstacle at all
    return [(pos, ob, active), (pos, ob[:, :0], active[:, :0])]  # and no obstacle slot


def _observation_states():
    """A world's observation inputs, edited so that every branch of the assembly runs."""
    core = _world_case()
    x = observation._gather_inputs(core.world, core.layout)
    x = type(x)(*(a.copy() for a in x))
    pos, vel, wp = x.pos, x.vel, x.wp_dir
    # Env 0: two UAVs at one point; env 1: integer positions, neighbours tied at 10 m.
    pos[0, 1] = pos[0, 0]
    pos[1] = [[0.0, 0.0, -50.0], [10.0, 0.0, -50.0], [-10.0, 0.0, -50.0], [0.0, 10.0, -50.0]]
    pos[2, 3] += 1e4  # beyond the sensing range, and offsets far beyond the clip (+ and -)
    vel[3, 0] = [1e3, -1e3, 0.0]  # velocities beyond the clip
    vel[4] = 0.0  # the formation at rest: its frame falls back to the way-point direction
    vel[5] = [0.0, 0.0, 3.0]  # climbing vertically: no heading
    vel[6], wp[6] = 0.0, 0.0  # at rest with no direction at all
    vel[7], wp[7] = 0.0, [0.0, 0.0, 1.0]  # at rest, vertical direction
    x.active[8] = False  # no obstacle present
    x.obstacle_pos[9, 0] += 1e4  # an obstacle beyond the sensing range
    for f in ("obstacle_pos", "obstacle_vel", "pred_center", "pred_axes", "cos_h", "sin_h",
              "heading"):  # fmt: skip
        getattr(x, f)[10, 1] = getattr(x, f)[10, 0]  # two obstacles alike: tied distances
    x.active[10, :2] = True
    pos[11, 0] = x.pred_center[11, 0]  # inside a region (at its centre)
    pos[12, 1] = x.obstacle_pos[12, 2] + [0.0, 0.0, 1e3]  # at the sensing range's edge
    pos[13, 3] = 1e200  # so far that the distances overflow to inf
    # An irregular formation in depth: every slot sums three non-zero terms.
    x.pattern[14:] += np.random.default_rng(6).normal(0.0, 5.0, size=x.pattern[14:].shape)
    vel[14:, :, 2] += 1.0  # climbing
    return core.layout, x


def _case_observations():
    import dataclasses

    layout, x = _observation_states()
    every = dataclasses.replace(layout, features=tuple(f.key for f in observation.FEATURES))
    n = x.pos.shape[1]
    wide = dataclasses.replace(layout, k_uavs=n, k_obstacles=x.pred_center.shape[1] + 2)
    short = dataclasses.replace(every, sensing_range=30.0)
    # Either half of the features (each has some in every block): the absent ones are skipped.
    halves = [dataclasses.replace(every, features=every.features[k::2]) for k in (0, 1)]
    for half in halves:
        blocks = {f.block for f in observation.FEATURES if f.key in half.features}
        assert blocks == {"self", "uav", "obstacle"}

    def obstacles(k):  # only the first k obstacle slots of the world
        cut = {f: getattr(x, f)[:, :k] for f in ("obstacle_pos", "obstacle_vel", "pred_center",
               "pred_axes", "cos_h", "sin_h", "heading", "active")}  # fmt: skip
        return x._replace(**cut)

    cases = []
    for lay, inputs in ((layout, x), (every, x), (wide, x), (short, x), (halves[0], x),
                        (halves[1], x), (every, obstacles(1)), (wide, obstacles(0))):  # fmt: skip
        e, n = inputs.pos.shape[:2]
        # float64: the numbers before the cast to float32 (NaN: every entry must be written)
        cases.append((inputs, lay, np.full((e, n, lay.world_dim), np.nan)))
    return cases


def _case_rewards():
    core = _world_case()
    w, cfg = core.world, core.config
    x = rewards._gather_inputs(w)
    x = type(x)(*(a.copy() for a in x))
    u = cfg.uav
    weights, constants = rewards._vectors(cfg.reward, cfg.uav, cfg.max_steps)
    x.min_uav_dist[0] = [0.5 * u.collision_distance, 0.5 * u.separation_distance,
                         2 * u.separation_distance, np.inf]  # fmt: skip
    x.min_obstacle_dist[1] = [0.5 * u.collision_distance, 0.5 * u.obstacle_separation,
                              2 * u.obstacle_separation, np.inf]  # fmt: skip
    x.region[2, 0] = -1e3  # deep inside a region: the capped penalty
    x.region[3] = np.inf  # no region at all
    x.uav_pos[4] = x.plan_pos[4]  # on the plan: zero deviation
    x.cmd[5], x.prev_cmd[5] = 0.0, 0.0  # no command, no change
    random = np.random.default_rng(5).uniform(-2, 2, size=weights.shape)
    no_region = x._replace(region=x.region[..., :0])
    return [(x, constants, weights), (x, constants, random), (no_region, constants, weights)]


def _case_outcome():
    """The reward cases with the episode-end tests and costs on their edges."""
    core = _world_case()
    cfg = core.config
    cases = []
    for k, (x, c, w) in enumerate(_case_rewards()):
        x = type(x)(*(a.copy() for a in x))
        u = cfg.uav
        x.uav_pos[6] = x.plan_pos[6] + [u.lost_distance, 0.0, 0.0]  # exactly at the bound
        x.uav_pos[7, 0] = x.plan_pos[7, 0] + [0.0, 0.0, 2 * u.lost_distance]  # lost
        x.min_uav_dist[8] = u.collision_distance  # at the collision bound: not collided
        weights = [
            config.CostWeights(),
            config.CostWeights(separation_uav=1.5, separation_obstacle=0.0, region=0.25),
        ][k % 2]
        cases.append((x, c, w, outcome.outcome_constants(u.lost_distance, weights)))
    return cases


def _case_plan():
    w = _world_case().world
    plan = w.plan
    t = np.arange(w.n_envs) * 7.3
    t[0], t[1], t[2] = -5.0, 0.0, 1e5  # before the start, at it, long after the end
    t[3] = plan.length[3] / plan.cruise_speed[3]  # at the end
    t[4] = plan.cum[4, 1] / plan.cruise_speed[4]  # at a way-point
    return [(plan, t, w._plan_offsets)]


def _case_fit_ellipse_params():
    """``(vt, phi, r)``: typical and degenerate rows of the ellipse fit."""
    rng = np.random.default_rng(23)
    k = 300
    vt = rng.uniform(0.0, 150.0, k)
    phi = rng.uniform(0.0, 3.0, k)
    r = rng.uniform(0.0, 40.0, k)
    vt[:10], phi[10:20], r[20:30] = 0.0, 0.0, 0.0  # discs, straight flight, no radius
    phi[30:40] = rng.uniform(3.0, 20.0, 10)  # turns past pi
    phi[40:45] = 0.5 * np.pi  # a node (pi / 2) exactly at the largest turn
    return vt, phi, r


def _fit_stage_args(attr: str) -> list[tuple]:
    """The arguments ``_ellipse_core`` passes to ``fit.<attr>`` (a twin), both sets' fits.

    Typical and degenerate rows (:func:`_case_fit_ellipse_params`); the swept flag last.
    """
    from uasep_env.reachable import fit

    vt, phi, r = _case_fit_ellipse_params()
    cases = []
    reference = getattr(fit, attr)
    try:  # capture the arguments (the twin's dispatch replaced)
        setattr(fit, attr, lambda *args: cases.append(args) or reference.reference(*args))
        for swept in (True, False):
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                fit._ellipse_core(vt, phi, r, swept)
    finally:
        setattr(fit, attr, reference)
    return [(*(a.copy() for a in args[:-1]), args[-1]) for args in cases]


def _case_fit_ellipse():
    """The fit's inputs as ``_ellipse_core`` makes them: typical, degenerate and NaN rows."""
    cases = _fit_stage_args("_fit_certified")
    nan = tuple(a[:16].copy() for a in cases[0][:-1])  # a NaN in each array in turn
    for j, a in enumerate(nan):
        a[j] = np.nan
    return [*cases, (*nan, True)]


def _case_ellipse_start():
    """The fit's start as ``_ellipse_core`` asks for it, and a NaN table coordinate."""
    cases = _fit_stage_args("_ellipse_start")
    nan = tuple(a.copy() for a in cases[0][:-1])
    nan[4][40:43] = np.nan  # log10 of the radius: the table's first column (np.where's guard)
    return [*cases, (*nan, True)]


def _case_node_arguments():
    """The nodes' arguments as ``_ellipse_core`` asks for them, and NaN spacings."""
    cases = _fit_stage_args("_node_arguments")
    nan = tuple(a[:6].copy() for a in cases[0])
    nan[0][0], nan[1][1, 3], nan[2][2], nan[3][3] = np.nan, np.nan, np.nan, np.nan
    return [*cases, nan]


def _case_ellipse_nodes():
    """The nodes as ``_ellipse_core`` makes them; fewer (an odd number of merge passes), NaN."""
    cases = _fit_stage_args("_ellipse_nodes")
    th, phi = cases[0][0], cases[0][1]
    nan = th[:6].copy()
    nan[:, 5::17] = np.nan  # np.sort puts NaN last
    return [*cases, (th[:8, :60].copy(), phi[:8].copy(), True), (nan, phi[:6].copy(), False)]


def _case_dense():
    rng = np.random.default_rng(22)
    x = rng.normal(0, 3, size=(37, 61)).astype(np.float32)
    x[0] = 0.0
    x[1, ::2] = np.float32(3e38)  # near float32's largest
    w = rng.normal(0, 0.2, size=(61, 128)).astype(np.float32).astype(np.float64)
    return [(x, w, rng.normal(0, 0.1, size=128).astype(np.float32).astype(np.float64))]


def _case_noise():
    """Noise blocks: numpy's every path (tail, wedges, retries), chunks, other generators.

    The first case's 18,816 Gaussians take the ziggurat's rare paths (the tail beyond the
    base strip about once in 3,000 draws, and a second try in it from seed 11); the second
    refills 70 environments (more than one chunk of the kernel's scratch); the third holds
    a Philox generator, which the kernel declines (numpy draws, the reference).
    """
    rngs = [np.random.default_rng(s) for s in (3, 11, 8, 13, 21, 34, 55)]
    std = np.random.default_rng(30).uniform(0.1, 3.0, size=49)
    first = (rngs, np.array([0, 2, 3, 6, 1, 4]), std, np.zeros((64, 7, 49)), np.zeros((64, 7, 2)))
    many = [np.random.default_rng(100 + s) for s in range(80)]
    envs = np.r_[np.arange(0, 80, 2), np.arange(1, 61, 2)]
    second = (many, envs, std[:3], np.full((2, 80, 3), 7.0), np.full((2, 80, 4), -1.0))
    mixed = [np.random.default_rng(7), np.random.Generator(np.random.Philox(7))]
    third = (mixed, np.arange(2), std[:5], np.zeros((3, 2, 5)), np.zeros((3, 2, 1)))
    return [first, second, third]


def _case_double_integrator():
    rng = np.random.default_rng(24)
    k, v_max, a_max, dt = 600, 12.0, 4.0, 0.1
    pos = rng.normal(0.0, 100.0, size=(30, k // 30, 3))
    vel = rng.normal(0.0, 7.0, size=pos.shape)
    cmd = rng.normal(0.0, 5.0, size=pos.shape)  # beyond the bound on many axes
    noise = rng.normal(0.0, 0.3, size=pos.shape)
    unit = vel[0] / np.linalg.norm(vel[0], axis=-1, keepdims=True)
    vel[0] = v_max * unit  # at the limit
    cmd[0], noise[0] = 0.0, 0.0  # and staying there
    cmd[1], noise[1] = -0.0, -0.0  # signed zeros through the clip and the noise
    vel[2] = 3.0 * v_max * unit  # far beyond the limit: scaled back
    cmd[3] = [a_max, -a_max, 0.0]  # exactly at the bounds
    strided = np.zeros((30, k // 30, 6))[..., ::2]  # not contiguous: written back
    strided[...] = pos
    strided_vel = np.zeros((30, k // 30, 6))[..., 1::2]
    strided_vel[...] = vel
    nan = cmd.copy()
    nan[:, 0] = np.nan  # a NaN command propagates as numpy's clip propagates it
    return [(pos, vel, cmd, noise, dt, v_max, a_max),
            (pos, vel, cmd, None, dt, v_max, a_max),  # no process noise
            (strided, strided_vel, cmd, noise, 0.05, 5.0, 2.0),
            (pos, vel, nan, noise, dt, v_max, a_max)]  # fmt: skip


def _obstacle_case(time_now: float = 20.0):
    """A world's obstacles edited onto the model's boundaries, and pilot uniforms."""
    w = _world_case().world
    ob = copy.deepcopy(w.obstacles)
    e, m = ob.heading.shape
    rng = np.random.default_rng(25)
    uniforms = rng.uniform(size=(e, m, obstacles.N_UNIFORMS))
    ob.speed *= rng.uniform(0.9, 1.1, size=ob.speed.shape)  # not round numbers
    ob.turn_rate[:] = rng.uniform(-1.0, 1.0, size=(e, m)) * ob.max_turn_rate  # turning
    ob.switch_prob[:] = 0.5
    ob.straight_prob[:] = 0.3
    time = np.full(e, time_now)
    ob.hold_until[0] = time_now  # the hold ends now
    ob.hold_until[1] = time_now + 1.0  # still held
    uniforms[0:2, :, 0] = 0.0  # would switch
    alt = -ob.pos[..., 2]
    ob.alt_band[2, :, 1] = alt[2] + 1e-3  # climbing out of the band's top
    ob.climb_rate[2] = ob.max_climb_rate[2]
    ob.alt_band[3, :, 0] = alt[3] - 1e-3  # descending out of its floor
    ob.climb_rate[3] = -ob.max_climb_rate[3]
    uniforms[2:4, :, 0] = 1.0  # keep those commands
    ob.ground[4] = alt[4] - 0.05  # just above the ground, descending: bounded
    ob.climb_rate[4] = -ob.max_climb_rate[4]
    ob.wind[5] = [1.0, -2.0, 3.0 * ob.max_climb_rate[5].max()]  # a down-wind beats vz_max
    ob.ground[5] = alt[5]  # on the ground
    ob.turn_rate[6] = 0.0  # straight: the arc's 0 / 0 guard
    ob.heading[7] = [np.pi - 1e-9, -np.pi, np.pi][:m]  # the wrap at +-pi
    ob.turn_rate[7] = ob.max_turn_rate[7]
    ob.active[8] = False  # absent slots stay where they are
    ob.pos[8, 0] = -0.0  # (even a -0.0 coordinate becomes 0.0, as numpy adds 0.0)
    uniforms[9:12, :, 1] = 0.0  # straight-and-level commands
    ob.alt_band[12, :, 1] = alt[12] - 10.0  # above its band, descending back into it
    ob.climb_rate[12] = -ob.max_climb_rate[12]
    uniforms[12, :, 0] = 1.0
    ob.pos[13:20, :, :2] = 0.0  # at the origin: the move's every bit shows in the position
    return ob, uniforms, time


def _case_obstacles():
    ob, uniforms, time = _obstacle_case()
    everyone = copy.deepcopy(ob)
    everyone.active[:] = True
    strided = copy.deepcopy(ob)
    strided.pos = np.zeros((*ob.pos.shape, 2))[..., 0]  # not contiguous: written back
    strided.pos[...] = ob.pos
    return [(ob, uniforms, 0.1, time), (ob, uniforms, 0.1, None), (everyone, uniforms, 0.5, time),
            (strided, uniforms, 0.1, time)]  # fmt: skip


def _case_kalman():
    rng = np.random.default_rng(26)
    kf = estimation.KalmanModel(0.1, 0.5, 2.0, 0.3)
    e, n = 20, 4
    est_pos, est_vel = rng.normal(0, 50, (e, n, 3)), rng.normal(0, 5, (e, n, 3))
    meas_pos = est_pos + rng.normal(0, 2, (e, n, 3))
    meas_vel = est_vel + rng.normal(0, 0.3, (e, n, 3))
    accel = rng.normal(0, 1, (e, n, 3))
    count = rng.integers(1, 2 * len(kf.gains), size=e)  # before and after convergence
    count[0] = len(kf.gains) - 1  # exactly at the last gain
    steady = np.full(e, 5 * len(kf.gains))
    return [(est_pos, est_vel, accel, meas_pos, meas_vel, count, kf.gains, kf.dt),
            (est_pos, est_vel, None, meas_pos, meas_vel, count, kf.gains, kf.dt),
            (est_pos, est_vel, accel, meas_pos, meas_vel, steady, kf.gains[-1:], kf.dt),
            (est_pos[:, ::2], est_vel[:, ::2], accel[:, ::2], meas_pos[:, ::2],
             meas_vel[:, ::2], count, kf.gains, kf.dt)]  # not contiguous: written back  # fmt: skip


class _ShiftReplay:
    """A stand-in for recorded tracks: moves obstacle slot 0 of the even worlds after the step."""

    def step(self, obs, time):
        obs.pos[::2, 0] += time[::2, None] * 0.5
        obs.heading[::2, 0] = -obs.heading[::2, 0]


def _case_physics():
    """A world's arrays after a few steps, the obstacles on the model's edges, fresh noise."""
    w = _world_case().world
    ob, uniforms, time = _obstacle_case()
    e, n, m = w.n_envs, w.n_uavs, w.n_obstacles
    rng = np.random.default_rng(27)
    arrays = physics_step.PhysicsArrays(
        time, rng.integers(0, 2 * len(w._uav_kf.gains), size=e),  # before and after convergence
        *(getattr(w, k).copy() for k in physics_step.PhysicsArrays._fields[2:10]),
        rng.uniform(0.0, 40.0, size=(e, n)), rng.uniform(0.0, 400.0, size=(e, n)),
    )  # fmt: skip
    arrays.accel_cmd[...] = rng.normal(0.0, 6.0, size=(e, n, 3))  # beyond the bound on some axes
    arrays.uav_vel[0] = 3.0 * w.config.uav.max_speed  # beyond the speed limit: scaled back
    arrays.min_uav_dist[1] = np.inf  # nothing yet this step
    normals = rng.normal(0.0, 0.7, size=(e, 9 * n + 6 * m))
    u = uniforms.reshape(e, -1)
    cfg = w.config
    params = physics_step.PhysicsParams(
        cfg.dt, cfg.uav.max_speed, cfg.uav.max_accel, True, w._uav_kf.gains, w._obstacle_kf.gains
    )
    steady = arrays._replace(kf_count=np.full(e, 5 * len(w._uav_kf.gains)))
    return [(arrays, ob, normals, u, params),
            (arrays, ob, normals, u, params._replace(kalman=False)),  # measurements as estimates
            (steady, ob, normals, u, params),  # every track converged: the last gain
            (arrays, ob, normals, u, params, _ShiftReplay())]  # replayed slots moved  # fmt: skip


#: The cases of each compiled twin; a new twin without cases fails the registry test.
def _case_apf():
    """Observations of batches in flight (collision courses, random traffic with several
    obstacles and neighbours), then rows edited into the APF's corners: a region on the UAV,
    a UAV standing still or too fast, absent neighbours and obstacles, far goals, and one
    row with a NaN velocity (case 2, NaN on purpose)."""
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies.apf import APF

    cases = []
    rng = np.random.default_rng(8)
    configs = (
        {"scenario": "collision_head_on", "n_uavs": 3, "n_obstacles": 1},
        {"scenario": "random", "n_uavs": 4, "n_obstacles": 3,
         "observation": {"k_uavs": 3, "k_obstacles": 3}},
    )  # fmt: skip
    for kw in configs:
        core = EnvCore(kw, 24)
        obs = core.reset(seed=11)
        pol = APF(core.config)
        rows = []
        for t in range(640):  # past the collision courses' meeting times
            act = pol(obs) if t % 3 else rng.uniform(-1, 1, (24, core.n_uavs, 3))
            res = core.step(act)
            obs = res.obs
            done = res.terminated | res.truncated
            if done.any():
                obs[done] = core.reset_some(done)
            if t % 40 == 39:
                rows.append(obs.copy())
        cases.append((np.concatenate(rows), pol.layout, pol.gains, pol.max_speed,
                      pol.max_accel, pol.dt))  # fmt: skip
    obs, layout, gains, *rest = cases[1]
    obs = obs[:40].copy()
    where = layout.decode_columns()

    def put(row, key, value, slot=0):
        start, size, scale, stride, _ = where[key]
        c = start + slot * stride
        obs[row, ..., c : c + size] = np.asarray(value, dtype=float) / scale

    put(0, "obstacle_center", [0.5, -0.2, 0.1])  # the UAV inside the region
    put(0, "obstacle_mask", [1.0])
    put(0, "uav_rel_pos", [1.5, -1.0, 0.3])  # and a neighbour close by: both forces act
    put(0, "uav_rel_vel", [-2.0, 1.0, 0.5])
    put(0, "uav_mask", [1.0])
    put(1, "velocity", [0.0, 0.0, 0.0])  # standing still
    put(2, "velocity", [30.0, 5.0, -2.0])  # faster than V_max: the speed cap acts
    put(3, "uav_mask", [0.0], slot=0)
    put(3, "obstacle_mask", [0.0], slot=1)
    put(4, "goal_offset", [900.0, -400.0, 10.0])  # far: the goal term saturates
    put(5, "uav_rel_pos", [1.0, 0.5, 0.0], slot=1)  # a neighbour closing in, very near
    put(5, "uav_rel_vel", [-3.0, -1.0, 0.0], slot=1)
    put(5, "uav_mask", [1.0], slot=1)
    put(6, "uav_rel_pos", [0.0, 0.0, 0.0], slot=2)  # an absent neighbour, as encoded
    put(6, "uav_rel_vel", [0.0, 0.0, 0.0], slot=2)
    put(6, "uav_mask", [0.0], slot=2)
    put(7, "obstacle_center", [-8.0, 0.0, 0.0])  # a region just behind, flown away from
    put(7, "obstacle_axes", [4.0, 3.0, 2.0])
    put(7, "obstacle_heading_cs", [1.0, 0.0])
    put(7, "obstacle_mask", [1.0])
    put(7, "velocity", [6.0, 0.0, 0.0])
    nan = obs[:8].copy()
    start = where["velocity"][0]
    nan[0, ..., start] = np.nan  # inside a region: the entry prediction meets the NaN
    nan[4, ..., where["goal_offset"][0]] = np.nan  # the goal term's cap meets it
    return [cases[0], (obs, layout, gains, *rest), (nan, layout, gains, *rest)]


def _case_scenario():
    """Episodes' draws of the random family, edited to take every path of the geometry.

    Typical batches (aimed obstacles level and climbing, no obstacle), a narrow airspace
    (the starts' and climbs' clamps), starts crowded on purpose (the scatter shrunk, or the
    pattern itself where even it is too tight), an obstacle whose pilot reacts at once, a
    NaN, and the two paths the kernel declines (a plan flown on past the timeline, a
    zero-length segment).
    """
    from uasep_env.config import make_config
    from uasep_env.scenarios import batched
    from uasep_env.scenarios.registry import get_family

    def inputs(seeds, **config):
        cfg = make_config(scenario="random", **config)
        family = get_family("random")
        draws = [family.draws(np.random.default_rng(s), cfg) for s in seeds]
        patterns = [d.pattern for d in draws]
        return list(batched.geometry_inputs(patterns, *batched._stacked(draws, cfg), cfg))

    typical = inputs(range(60), n_uavs=4, n_obstacles=3)
    typical[1][:5, :, 10] = 500.0  # reaction leads longer than the meeting times
    narrow = inputs(range(40), n_obstacles=3, airspace={"obstacle_margin": 85.0,
                                                         "ceiling_altitude": 112.0})  # fmt: skip
    crowded = inputs(range(12), n_uavs=3, n_obstacles=0)
    lay, n_plan = crowded[0], batched._N_PLAN
    lay[:6, n_plan + 3 : n_plan + 6] = 0.0  # UAV 1 on its slot, UAV 0 scattered onto it
    lay[:6, n_plan : n_plan + 3] = crowded[2][:6, 1] - crowded[2][:6, 0]
    tight = [*crowded[:5], 1e6, *crowded[6:]]  # no shrink separates them: the pattern
    nan = inputs(range(4), n_obstacles=2)
    nan[1][0, :, 9] = 0.0  # level, at a NaN altitude offset
    nan[1][0, :, 7] = np.nan
    longer = [*typical[:4], 50.0, *typical[5:]]
    flat = inputs(range(3), n_obstacles=1)
    flat[0][1, 1 + 2 * batched._TURNS : n_plan] = 0.5  # every turn at one place
    return [tuple(c) for c in (typical, narrow, crowded, tight, nan, longer, flat)]


def _case_draws():
    """Episodes' draws: the random family's mix, single members, no obstacle, numpy's rare
    rejection in its bounded integers, a one-entry mix (nothing drawn), a Philox generator
    (declined)."""
    from uasep_env.config import make_config
    from uasep_env.scenarios import batched
    from uasep_env.scenarios.families import ENCOUNTERS
    from uasep_env.scenarios.registry import Mix, get_family

    tables, _ = get_family("random").draw_tables()
    names = tables.names

    def rngs(seeds):
        return [np.random.default_rng(s) for s in seeds]

    def config(**kw):
        return make_config(scenario="random", **kw)

    # The first integers() reads the kept half: 0 is rejected (drawn again), the least
    # value above the rejection threshold is kept.
    crafted = rngs(range(2))
    for g, kept in zip(crafted, (0, 858993460), strict=True):
        state = g.bit_generator.state
        g.bit_generator.state = {**state, "has_uint32": 1, "uinteger": kept}
    solo_mix = Mix(weights={"head_on": 1})

    def solo(rng, cfg):
        return batched.draw_encounters("solo", cfg, rng, None, solo_mix, ENCOUNTERS)

    solo_tables = batched.draw_tables({"solo": None}, None, solo_mix, ENCOUNTERS, solo, (solo,))
    philox = [np.random.default_rng(1), np.random.Generator(np.random.Philox(1))]
    return [
        (rngs(range(40)), config(n_uavs=3, n_obstacles=1), tables, -1),
        (rngs(range(40, 70)), config(n_uavs=5, n_obstacles=3), tables, -1),
        (rngs(range(70, 90)), config(n_obstacles=2), tables, names.index("climbing")),
        (rngs(range(90, 100)), config(n_obstacles=0), tables, names.index("multi_obstacle")),
        (crafted, config(n_obstacles=2), tables, -1),
        (rngs(range(100, 110)), config(n_obstacles=2), solo_tables, -1),
        (philox, config(), tables, -1),
    ]


TWIN_CASES = {
    "apf_actions": _case_apf,
    "nearest_on_ellipsoids": _case_nearest,
    "pairwise_distances": _case_pairwise,
    "region_distances": _case_region,
    "separations": _case_separations,
    "assemble_observations": _case_observations,
    "reward_terms": _case_rewards,
    "plan_now": _case_plan,
    "dense": _case_dense,
    "double_integrator": _case_double_integrator,
    "obstacle_step": _case_obstacles,
    "kalman_correct": _case_kalman,
    "fit_ellipse": _case_fit_ellipse,
    "ellipse_start": _case_ellipse_start,
    "ellipse_nodes": _case_ellipse_nodes,
    "node_arguments": _case_node_arguments,
    "physics_step": _case_physics,
    "step_outcome": _case_outcome,
    "refill_noise": _case_noise,
    "scenario_geometry": _case_scenario,
    "encounter_draws": _case_draws,
}


#: The outputs of the kernels that write into their arguments instead of returning them.
IN_PLACE = {
    "assemble_observations": lambda args: args[2:],
    "kalman_correct": lambda args: args[:2],
    "refill_noise": lambda args: args[3:],
    "obstacle_step": lambda args: (args[0].pos, args[0].heading, args[0].climb_rate),
    "physics_step": lambda args: (
        *(a for a in args[0] if a.dtype == np.float64),
        args[1].pos,
        args[1].heading,
    ),
}


#: Cases whose outputs hold NaN on purpose (NaN inputs propagate as numpy propagates them).
NAN_ON_PURPOSE = {
    ("double_integrator", 3),
    ("fit_ellipse", 2),
    ("apf_actions", 2),
    ("scenario_geometry", 4),
    ("ellipse_nodes", 3),
    ("node_arguments", 2),
    *(("encounter_draws", k) for k in range(7)),  # level obstacles' climbs are NaN
}


def test_every_compiled_twin_has_a_case():
    assert set(_numba.TWINS) == set(TWIN_CASES)


@pytest.mark.parametrize("loops", ["serial", "parallel"])
@pytest.mark.parametrize("name", sorted(TWIN_CASES))
def test_each_kernel_matches_its_numpy_reference_bit_for_bit(name, loops, monkeypatch):
    """Return values and arrays filled in place, in float64, for every registered pair.

    With the serial loops, and with the parallel ones wherever a kernel has them (numba's
    parallel loops are compiled apart: one once wrote wrong numbers where its serial twin
    did not).
    """
    from uasep_env._kernels import common

    if loops == "parallel":
        monkeypatch.setattr(common, "THREADS", [2])
        monkeypatch.setattr(common, "PARALLEL_MIN", 0)
    twin = _numba.TWINS[name]
    for k, args in enumerate(TWIN_CASES[name]()):
        want_args, got_args = _copy(args), _copy(args)
        with np.errstate(over="ignore"):  # the extreme cases overflow on purpose
            want = twin.reference(*want_args)
            got = twin.compiled()(*got_args)
        _assert_same(got, want, f"{name} case {k}")
        _assert_same(got_args, want_args, f"{name} case {k} arguments")
        outputs = IN_PLACE[name](want_args) if name in IN_PLACE else want
        for a in outputs if isinstance(outputs, tuple) else (outputs,):
            if a.dtype.kind in "bi":  # a flag (the fit's certificate), an index (a member)
                continue
            assert a.dtype == np.float64, name  # compared before any cast to float32
            if (name, k) not in NAN_ON_PURPOSE:
                assert not np.isnan(a).any(), name  # every entry written


@pytest.mark.skipif(
    sys.version_info[:2] != (3, 11), reason="reads CPython 3.11's bytecode for the branches"
)
def test_the_cases_take_every_branch_of_every_kernel():
    """Each outcome of each condition in ``uasep_env/_kernels`` runs in some twin case.

    ``tests/kernel_branches.py`` traces the cases through the kernels' Python source
    (``NUMBA_DISABLE_JIT=1``). The random states alone leave branches untaken (the check
    sees them); the edited states take every one, so the bit-for-bit comparison covers
    every path a kernel can take.
    """
    import json
    import subprocess

    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "PYTHONPATH": str(Path(__file__).parents[1])}
    out = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("kernel_branches.py"))],
        env=env,
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    untaken = json.loads(out.stdout.strip().splitlines()[-1])
    assert untaken["first_cases"]  # the check is not blind
    assert untaken["all_cases"] == [], untaken["all_cases"]


def test_public_functions_use_the_kernel_with_broadcasting(monkeypatch):
    rng = np.random.default_rng(2)
    pts = rng.normal(0, 20, size=(5, 4, 1, 3))
    ctr = rng.normal(0, 5, size=(1, 4, 2, 3))
    ax = rng.uniform(1, 30, size=(2, 3))
    hd = rng.uniform(-3, 3, size=(4, 2))
    fast = reachable.distance_to_ellipsoid(pts, ctr, ax, hd, return_normal=True)
    near_fast = reachable.nearest_point_on_ellipsoid(pts, ctr, ax, hd)
    monkeypatch.setitem(_numba._state, "numba", None)
    assert not _numba.available()
    slow = reachable.distance_to_ellipsoid(pts, ctr, ax, hd, return_normal=True)
    near_slow = reachable.nearest_point_on_ellipsoid(pts, ctr, ax, hd)
    assert fast[0].shape == (5, 4, 2) and fast[1].shape == (5, 4, 2, 3)
    for f, s in zip((*fast, *near_fast), (*slow, *near_slow), strict=True):
        _assert_bits(f, s)


def test_noise_kernel_draws_itself_and_declines_what_it_cannot_read(monkeypatch):
    """The kernel draws PCG64's numbers itself here (so the twin cases compare two codes),
    and where it could not read the generators' memory it declines and numpy draws."""
    from uasep_env._kernels import noise as kernel

    if sys.platform == "win32":
        pytest.skip("numpy's MSVC builds store PCG64's words high first: the kernel declines")
    args = _case_noise()[0]
    assert kernel._native_pcg64()  # numpy's native 128-bit layout (GCC, Clang builds)
    assert kernel.refill_noise(*_copy(args)) is None  # drawn by the kernel
    monkeypatch.setattr(kernel, "_DRAWS_FROM", ())
    got = _copy(args)
    assert kernel.refill_noise(*got) is NotImplemented
    assert not got[3].any()  # nothing drawn
    want = _copy(args)
    noise.refill_noise.reference(*want)
    noise.refill_noise(*got)  # the dispatch: numpy's draws
    _assert_same(got, want, "declined")


def test_reset_kernels_build_random_episodes_themselves(monkeypatch):
    """A partial reset's draws and geometry run compiled on the random family's episodes
    (the twin cases compare two codes), and the draws decline where they could not read
    the generators' kept half-word: then Python draws the same episodes."""
    from uasep_env._kernels import draws as kernel_draws

    if sys.platform == "win32":
        pytest.skip("numpy's MSVC builds store PCG64's words high first: the kernel declines")
    compiled = _numba.kernels()
    draws_case, geometry_case = _case_draws()[0], _case_scenario()[0]
    twin = _numba.TWINS["encounter_draws"]
    assert kernel_draws._BUFFER_OK
    got = compiled.encounter_draws(*_copy(draws_case), **twin.constants)
    assert got is not NotImplemented
    built = compiled.scenario_geometry(
        *geometry_case, **_numba.TWINS["scenario_geometry"].constants
    )
    assert built is not NotImplemented
    monkeypatch.setattr(kernel_draws, "_BUFFER_OK", False)
    declined = _copy(draws_case)
    assert compiled.encounter_draws(*declined, **twin.constants) is NotImplemented
    _assert_same(twin.dispatch(*declined), got, "declined: Python's draws")


def test_fit_kernels_take_the_sines_themselves(monkeypatch):
    """numpy's float64 sines and cosines are the C library's here, so the fit's kernels
    that take them run (the twin cases compare two codes); where they were not, the three
    kernels decline and numpy's give the same fit."""
    from uasep_env._kernels import common
    from uasep_env.reachable import fit

    assert common.sin_cos_agree()
    monkeypatch.setattr(common.numba.config, "USING_SVML", True)
    assert not common._sin_cos_agree()  # numba's sines may be vectorised: not trusted
    monkeypatch.undo()
    compiled = _numba.kernels()
    vt, phi, r = _case_fit_ellipse_params()
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        want = fit._ellipse_core(vt, phi, r, True)
    names = ("ellipse_start", "node_arguments", "ellipse_nodes")

    def answer(name: str) -> object:
        return getattr(compiled, name)(*TWIN_CASES[name]()[0], **_numba.TWINS[name].constants)

    assert all(answer(name) is not NotImplemented for name in names)
    monkeypatch.setattr(common, "_SIN_COS", [False])
    assert all(answer(name) is NotImplemented for name in names)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        _assert_same(fit._ellipse_core(vt, phi, r, True), want, "declined: numpy's sines")


def test_draw_tables_need_the_mix_to_list_the_members():
    from uasep_env.scenarios import batched
    from uasep_env.scenarios.families import ENCOUNTERS, TRAFFIC_MIX
    from uasep_env.scenarios.registry import Mix

    with pytest.raises(ValueError, match="does not list the members"):
        batched.draw_tables(
            {"crossing": ENCOUNTERS["crossing"]}, Mix(weights={"head_on": 1}), TRAFFIC_MIX,
            ENCOUNTERS, print, (print,),
        )  # fmt: skip


def test_noise_kernel_declines_where_numba_moved_its_tables():
    """numba's copy of numpy's ziggurat tables is a private module: gone, numpy draws."""
    import subprocess

    code = (
        "import sys; sys.modules['numba.np.random._constants'] = None\n"
        "import numpy as np\n"
        "from uasep_env._kernels import noise as k\n"
        "args = ([np.random.default_rng(1)], np.arange(1), np.ones(2), np.zeros((2, 1, 2)),"
        " np.zeros((2, 1, 1)))\n"
        "print(k._DRAWS_FROM, k.refill_noise(*args) is NotImplemented)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env,
        timeout=HANG_GUARD_S,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["()", "True"]


def test_disabled_by_environment_variable(monkeypatch):
    monkeypatch.setenv("UASEP_NUMBA", "0")
    monkeypatch.delitem(_numba._state, "numba", raising=False)
    assert not _numba.available()
    with pytest.raises(RuntimeError, match="dense: numba is not in use"):
        _numba.TWINS["dense"].compiled()  # would compare the reference with itself
    monkeypatch.delitem(_numba._state, "numba")
    monkeypatch.setenv("UASEP_NUMBA", "1")
    assert _numba.available()


def test_episodes_are_bit_identical_with_and_without_numba(monkeypatch):
    """The whole transition (world, observations, rewards, APF) does not depend on numba."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies import APF

    def rollout() -> list[np.ndarray]:
        cfg = make_config(n_uavs=3, n_obstacles=2, scenario="random")
        core = EnvCore(cfg, n_envs=6)
        obs = core.reset(seed=11)
        apf = APF(cfg)
        out = []
        for _ in range(60):
            res = core.step(apf(obs))
            out += [res.obs, res.rewards, res.safety["min_region_distance"]]
            obs = res.obs
        return out

    fast = rollout()
    monkeypatch.setitem(_numba._state, "numba", None)
    slow = rollout()
    for f, s in zip(fast, slow, strict=True):
        _assert_bits(f, s)


def test_pairwise_distances_kernel_matches_the_broadcast_numpy_form(parallel_loops):
    from uasep_env._kernels import common

    rng = np.random.default_rng(4)
    for e, n, m in ((1, 3, 1), (7, 4, 3), (600, 3, 2)):  # the last runs the parallel loop
        pts = rng.normal(0, 40, size=(e, n, 3))
        ctr = rng.normal(0, 20, size=(e, m, 3))
        ax = rng.uniform(0, 30, size=(e, m, 3))
        ax[0, 0, 1] = 0.0  # a flat one
        hd = rng.uniform(-np.pi, np.pi, size=(e, m))
        want = _numpy_nearest(pts[:, :, None], ctr[:, None], ax[:, None], hd[:, None])[1]
        got = _kernel("pairwise_distances")(pts, ctr, ax, hd)
        assert got.shape == (e, n, m)
        _assert_bits(got, want)
    assert e * n * m >= common.PARALLEL_MIN


@pytest.mark.parametrize(
    "config",
    [
        {"n_uavs": 3, "n_obstacles": 1, "scenario": "random"},
        {"n_uavs": 6, "n_obstacles": 3, "scenario": "random"},
        # Short sensing range (absent neighbours), more obstacle slots than obstacles.
        {
            "n_uavs": 5,
            "n_obstacles": 2,
            "observation": {"k_uavs": 2, "k_obstacles": 4, "sensing_range": 60.0},
        },
        {"n_uavs": 4, "n_obstacles": 0},
    ],
)
def test_observation_kernel_matches_numpy_assembly_bit_for_bit(config, parallel_loops):
    from uasep_env.envs.core import EnvCore
    from uasep_env.interface import observation

    core = EnvCore(config, n_envs=700)  # 2,100+ agents: the parallel loop
    core.reset(seed=5)
    rng = np.random.default_rng(6)
    absent = 0
    for _ in range(15):
        core.step(rng.uniform(-1, 1, size=(700, core.n_uavs, 3)))
        x = observation._gather_inputs(core.world, core.layout)
        # float64: the numbers before the cast; float32: what the environments return.
        for dtype in (np.float64, np.float32):
            want = np.full(core._obs.shape, np.nan, dtype=dtype)
            got = want.copy()
            observation._assemble.reference(x, core.layout, want)
            _kernel("assemble_observations")(x, core.layout, got)
            assert not np.isnan(want).any()  # NaN-filled: every entry was written
            _assert_bits(got, want, str(dtype))
            small = want[:2].copy()
            _kernel("assemble_observations")(type(x)(*(a[:2] for a in x)), core.layout, small)
            _assert_bits(small, want[:2], f"{dtype} serial")  # the serial loop
        absent += int(np.sum(core.layout.decode(want)["uav_mask"] == 0))
    if "observation" in config:
        assert absent > 0  # the short range did hide some neighbours


def _assemble_both(x, layout, dtype=np.float64):
    """The numpy assembly and the kernel's, into NaN-filled arrays: ``(want, got)``.

    float64 by default: the numbers before the cast to float32.
    """
    e, n = x.pos.shape[:2]
    want = np.full((e, n, layout.world_dim), np.nan, dtype=dtype)
    got = want.copy()
    observation._assemble.reference(x, layout, want)
    _kernel("assemble_observations")(x, layout, got)
    return want, got


def test_float32_observations_are_the_float64_numbers_rounded():
    """The float64 ``out`` the tests compare holds the numbers the environments round: the
    float32 observations are them cast, in numpy and in the kernel (the clip bound, 12, is
    a float32 number, so clipping before or after the cast agrees)."""
    for args in _case_observations():
        x, layout, _ = args
        assert np.float32(layout.clip) == layout.clip
        with np.errstate(over="ignore"):
            want64, got64 = _assemble_both(x, layout)
            want32, got32 = _assemble_both(x, layout, np.float32)
        _assert_bits(want32, want64.astype(np.float32), "numpy")
        _assert_bits(got32, got64.astype(np.float32), "kernel")


def _columns_of(layout, key):
    """The vector columns of feature ``key`` in ``layout`` (every neighbour slot)."""
    f = next(f for f in observation.FEATURES if f.key == key)
    s = layout.slices[key]
    if f.block == "self":
        return list(range(s.start, s.stop))
    start = layout.self_dim + (layout.k_uavs * layout.width("uav") if f.block == "obstacle" else 0)
    k = layout.k_uavs if f.block == "uav" else layout.k_obstacles
    w = layout.width(f.block)
    return [start + slot * w + c for slot in range(k) for c in range(s.start, s.stop)]


@pytest.mark.parametrize("key", [f.key for f in observation.FEATURES])
def test_every_feature_of_the_table_is_bit_identical_with_and_without_it(key):
    """Each feature, on (optional ones enabled) and off: kernel and numpy agree, and the rest
    of the vector is the same numbers at the shifted columns (the layout is data)."""
    import dataclasses

    core = _world_case()
    default = core.layout
    on = dataclasses.replace(default, features=(*default.features, key))
    off = dataclasses.replace(default, features=tuple(k for k in on.features if k != key))
    assert key in on.features and key not in off.features
    assert off.dim < on.dim
    x = observation._gather_inputs(core.world, on)
    want_on, got_on = _assemble_both(x, on)
    want_off, got_off = _assemble_both(x, off)
    for want, got in ((want_on, got_on), (want_off, got_off)):
        assert not np.isnan(want).any()  # every entry written
        _assert_bits(got, want)
    cols = _columns_of(on, key)
    assert len(cols) == on.dim - off.dim
    assert np.any(want_on[..., cols] != 0.0)  # computed, not left at zero
    rest = np.delete(want_on, cols, axis=-1)
    _assert_bits(rest, want_off)
    if on.features != default.features:  # optional: its vector decodes with it
        assert key in on.decode(want_on)


def test_optional_features_are_named_in_the_config():
    from uasep_env import make_config
    from uasep_env.interface.observation_layout import OPTIONAL_FEATURES, ObservationLayout

    with pytest.raises(ValueError, match=r"observation\.optional_features"):
        ObservationLayout.from_config(make_config(observation={"optional_features": ["nope"]}))
    with pytest.raises(ValueError, match=r"observation\.optional_features"):
        make_config(observation={"optional_features": "uav_dist"})
    with pytest.raises(ValueError, match="unknown observation feature"):
        ObservationLayout(
            k_uavs=1,
            k_obstacles=1,
            pos_scale=1.0,
            vel_scale=1.0,
            acc_scale=1.0,
            clip=1.0,
            sensing_range=1.0,
            features=("nope",),
        )
    for key in OPTIONAL_FEATURES:
        cfg = make_config(observation={"optional_features": [key]})
        assert key in ObservationLayout.from_config(cfg).features
    default = ObservationLayout.from_config(make_config())
    assert not set(OPTIONAL_FEATURES) & set(default.features)


def test_norm_adds_in_einsum_order():
    """The kernels' distance is numpy's ``sqrt(einsum)`` to the bit (its summation order)."""
    from uasep_env._kernels import common

    d = np.random.default_rng(8).normal(0, 100, size=(5000, 3))
    want = np.sqrt(np.einsum("...i,...i->...", d, d))
    got = np.array([common._dist3(*row) for row in d])
    _assert_bits(got, want)


@pytest.mark.parametrize(("n_envs", "n_obstacles"), [(5, 3), (800, 2), (3, 0)])
def test_separations_kernel_matches_numpy(monkeypatch, n_envs, n_obstacles):
    from uasep_env import World

    world = World({"n_uavs": 4, "n_obstacles": n_obstacles, "scenario": "random"}, n_envs)
    world.reset(seed=9)
    world.obstacles.active[::2] = False  # inactive obstacles do not count
    fast = world.separations()
    monkeypatch.setitem(_numba._state, "numba", None)
    slow = world.separations()
    for f, s in zip(fast, slow, strict=True):
        assert f.shape == (n_envs, 4)
        _assert_bits(f, s)
    if n_obstacles:
        assert np.isinf(fast[1][::2]).all() and np.isfinite(fast[1][1::2]).all()


def test_formation_frame_kernel_matches_numpy_including_fallbacks():
    """The compiled frame (eq. 6) is rotation_from_velocity's, slow and vertical cases too."""
    from uasep_env._kernels.observations import _frame
    from uasep_env.sim.formation import MIN_FRAME_SPEED, rotation_from_velocity

    rng = np.random.default_rng(12)
    vel = rng.normal(0, 3, size=(3000, 3)) * rng.choice([1e-3, 0.2, 1.0, 10.0], (3000, 1))
    fallback = rng.normal(0, 1, size=(3000, 3))
    vel[:50, :2] = 0.0  # vertical
    vel[50:60] = 0.0  # still: the fallback decides
    fallback[50:55] = [0.0, 0.0, 1.0]  # a vertical fallback has no heading
    fallback[55:58] = 0.0  # no fallback direction at all: level, north
    fallback[58:60, :2] = 1e-10  # almost vertical
    want = rotation_from_velocity(vel, fallback)
    assert (np.linalg.norm(vel, axis=-1) < MIN_FRAME_SPEED).sum() > 100
    for v, f, w in zip(vel, fallback, want, strict=True):
        ct, st, cp, sp = _frame(*v, *f, MIN_FRAME_SPEED)
        got = [[-st, cp * ct, -ct * sp], [ct, cp * st, -st * sp], [0.0, -sp, -cp]]
        _assert_bits(np.array(got), w)


@pytest.mark.parametrize(("n_envs", "shared"), [(3, 0.0), (800, 0.4)])  # serial, parallel
def test_reward_kernel_matches_numpy_terms_bit_for_bit(monkeypatch, n_envs, shared, parallel_loops):
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.interface import rewards

    cfg = make_config(n_uavs=4, n_obstacles=2, scenario="random", reward={"shared": shared})
    core = EnvCore(cfg, n_envs)
    core.reset(seed=2)
    rng = np.random.default_rng(3)
    w = core.world
    for step in range(12):
        core.step(rng.uniform(-1, 1, size=(n_envs, 4, 3)))
        w.obstacles.active[::3] = step % 2 == 0  # inactive obstacles: infinite distances
        w.min_uav_dist[::5, 0] = 0.5 * cfg.uav.collision_distance  # a collision
        w.uav_pos[1::4, 1] = w.pred_center[1::4, 0]  # inside a reachable region
        fast = rewards.compute_rewards(w, cfg.reward)
        monkeypatch.setitem(_numba._state, "numba", None)
        slow = rewards.compute_rewards(w, cfg.reward)
        monkeypatch.undo()
        _assert_bits(fast[0], slow[0])
        assert list(fast[1]) == list(slow[1]) == list(rewards.REWARD_TERMS)
        for name in rewards.REWARD_TERMS:
            _assert_bits(fast[1][name], slow[1][name], name)
    assert (fast[1]["collision"] < 0).any() and (fast[1]["separation_region"] < 0).any()


def test_kernels_name_their_plain_tuples_with_the_references_fields():
    """The kernels take plain tuples and name them again: the same fields, in order."""
    from uasep_env._kernels import observations as kernel_obs
    from uasep_env._kernels import rewards as kernel_rewards
    from uasep_env.interface import observation_layout

    assert kernel_obs._Inputs._fields == observation._Inputs._fields
    assert kernel_obs._Columns._fields == observation_layout.Columns._fields
    assert kernel_rewards._Inputs._fields == rewards._Inputs._fields
    assert kernel_rewards._Constants._fields == rewards._Constants._fields
    assert kernel_rewards._TermIndex._fields == rewards._TERM_INDEX._fields
    assert kernel_rewards._OutcomeConstants._fields == outcome.OutcomeConstants._fields


def test_reward_terms_agree_between_table_numpy_kernel_and_weights():
    """A term cannot be half-added: the table, the numpy terms, the kernel's writes, the
    weights and the module's documentation name the same terms."""
    import dataclasses
    import inspect
    import re

    from uasep_env._kernels import rewards as kernel
    from uasep_env.config import RewardWeights

    names = rewards.REWARD_TERMS
    assert names == tuple(t.name for t in rewards.TERMS) == rewards._TERM_INDEX._fields
    assert tuple(rewards._TERM_INDEX) == tuple(range(len(names)))
    x, constants, weights = _case_rewards()[0]
    assert tuple(rewards._term_values(x, constants)) == names
    written = re.findall(r"terms\[ix\.(\w+), e, i\]", inspect.getsource(kernel._reward_agent))
    assert sorted(written) == sorted(names)  # each row once, by name
    assert not re.search(r"terms\[\d", inspect.getsource(kernel))  # no literal rows
    not_terms = {"shared", "deviation_scale"}
    weight_names = {f.name for f in dataclasses.fields(RewardWeights)} - not_terms
    assert weight_names == set(names)
    for name in names:
        assert f"``{name}``" in rewards.__doc__
    # At run time too: every row of a NaN-filled terms array is written.
    e, n = x.min_uav_dist.shape
    own, terms = np.full((e, n), np.nan), np.full((len(names), e, n), np.nan)
    x = tuple(np.ascontiguousarray(a) for a in x)
    kernel._rewards_serial(x, tuple(constants), tuple(rewards._TERM_INDEX), weights, own, terms)
    assert not np.isnan(terms).any() and not np.isnan(own).any()


def test_plan_kernel_matches_numpy_along_and_past_the_plan(monkeypatch):
    from uasep_env import World

    world = World({"n_uavs": 4, "n_obstacles": 1, "scenario": "random"}, 50)
    world.reset(seed=1)
    seen = set()
    for t in (0.0, 0.2, 7.3, 40.0, 95.5, 300.0, 1e5):
        world.time[:] = t + np.arange(50) * 3.1  # every env somewhere else on its plan
        world._refresh_plan()
        fast = [a.copy() for a in world._plan_arrays()]
        seen.update(world.plan.locate(world.time)[1].tolist())
        monkeypatch.setitem(_numba._state, "numba", None)
        world._refresh_plan()
        slow = world._plan_arrays()
        monkeypatch.undo()
        for f, s in zip(fast, slow, strict=True):
            _assert_bits(f, s)
    assert len(seen) > 2  # several segments, and the end of the plan (t = 1e5)


def _big_rollout(_: int = 0) -> np.ndarray:
    from uasep_env.envs.core import EnvCore

    core = EnvCore({"n_uavs": 3, "n_obstacles": 1, "scenario": "random"}, n_envs=700)
    core.reset(seed=0)
    for _ in range(3):
        res = core.step(np.zeros((700, 3, 3)))
    return res.obs


def test_a_forked_child_runs_the_kernels_after_the_parent_ran_them_in_parallel(parallel_loops):
    """numba's GNU OpenMP layer would kill the child; forked children use the serial loops."""
    import multiprocessing

    from uasep_env._kernels import common

    parent = _big_rollout()  # 2,100 agents: the parallel loops
    assert common._parallel(2100)
    with multiprocessing.get_context("fork").Pool(1) as pool:
        child = pool.apply_async(_big_rollout).get(timeout=HANG_GUARD_S)
    _assert_bits(child, parent)


def test_world_region_distances_from_kept_cosines_match_numpy(monkeypatch):
    """The compiled region distances use the world's kept cos/sin; numpy recomputes them."""
    from uasep_env import World

    world = World({"n_uavs": 3, "n_obstacles": 3, "scenario": "random"}, 40)
    world.reset(seed=4)
    rng = np.random.default_rng(5)
    for step in range(20):
        active = rng.random(40) < 0.8  # frozen envs are snapshotted and restored
        world.step(rng.uniform(-3, 3, size=(40, 3, 3)), active=active)
        if step == 7:
            world.reset(mask=rng.random(40) < 0.3)  # a partial reset places regions anew
        world.obstacles.active[::4, 1] = False
        fast = world.region_distances()
        est = world.region_distances(world.est_pos[5:9], rows=np.arange(5, 9))
        _assert_bits(est, world.region_distances(world.est_pos)[5:9])  # the rows' own regions
        monkeypatch.setitem(_numba._state, "numba", None)
        _assert_bits(fast, world.region_distances())
        _assert_bits(est, world.region_distances(world.est_pos[5:9], rows=np.arange(5, 9)))
        monkeypatch.undo()
        assert np.isinf(fast[::4, :, 1]).all() and np.isfinite(fast[1::4]).all()


def test_install_time_warm_up_command_runs_without_numba():
    """``python -m uasep_env.precompile`` (run by the Makefile after installing) never fails."""
    import subprocess
    import sys

    env = {**os.environ, "UASEP_NUMBA": "0"}
    out = subprocess.run(
        [sys.executable, "-m", "uasep_env.precompile"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert "numba kernels: not in use" in out.stdout


def test_threads_are_the_process_share_of_its_cores():
    """N processes started side by side never ask for more threads than the cores."""
    from uasep_env.runtime.cores import (
        PARALLEL_MIN_THREADS,
        PARALLEL_MIN_THREADS_OTHER,
        decide_threads,
    )

    # The cases below are written for these.
    assert PARALLEL_MIN_THREADS == {"omp": 2} and PARALLEL_MIN_THREADS_OTHER == 4
    assert decide_threads({}, cores=16) == 16
    assert decide_threads({"UASEP_WORKERS": "4"}, cores=16) == 4
    assert decide_threads({"UASEP_WORKERS": "8"}, cores=16) == 2
    assert decide_threads({"UASEP_WORKERS": "16"}, cores=16) == 1
    assert decide_threads({}, cores=2) == 2  # OpenMP's two sleeping threads pay
    assert decide_threads({"UASEP_WORKERS": "2"}, cores=2) == 1
    assert decide_threads({"UASEP_WORKERS": "3"}, cores=2) == 1
    # numba's own workqueue (no OpenMP runtime): two threads do not pay, four do.
    assert decide_threads({}, cores=2, layer="workqueue") == 1
    assert decide_threads({"UASEP_WORKERS": "8"}, cores=16, layer="tbb") == 1
    assert decide_threads({}, cores=4, layer="workqueue") == 4
    assert decide_threads({"UASEP_THREADS": "2"}, cores=2, layer="workqueue") == 2
    assert decide_threads({"UASEP_THREADS": "2", "UASEP_WORKERS": "8"}, cores=16) == 2
    for name, value in (("UASEP_THREADS", "0"), ("UASEP_WORKERS", "two")):
        with pytest.raises(ValueError, match=f"{name}='{value}'"):
            decide_threads({name: value}, cores=4)


def test_the_kernels_take_the_process_share_of_the_cores():
    import numba

    from uasep_env.runtime.cores import kernel_threads, process_share

    common = _numba.kernels().common
    want = 1
    if min(process_share(), numba.config.NUMBA_NUM_THREADS) > 1:
        want = min(kernel_threads(numba.threading_layer()), numba.config.NUMBA_NUM_THREADS)
    assert common.THREADS[0] == want


@pytest.mark.parametrize("users", [None, "ACTIVE"])
def test_openmp_threads_start_asleep_unless_the_user_says(monkeypatch, users):
    """``OMP_WAIT_POLICY=PASSIVE`` while the pool starts (the runtime reads it then), and
    gone after it, so that torch's runtime, loaded later, keeps its own; a user's value is
    theirs. Spinning threads halved two processes' throughput on two cores."""
    seen = []

    class FakeNumba:
        def set_num_threads(self, n):
            seen.append((n, os.environ.get("OMP_WAIT_POLICY")))

        def threading_layer(self):
            return "omp"

    if users is None:
        monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    else:
        monkeypatch.setenv("OMP_WAIT_POLICY", users)
    assert _numba.start_threads(FakeNumba(), 2) == "omp"
    assert seen == [(2, users or "PASSIVE")]
    assert os.environ.get("OMP_WAIT_POLICY") == users


def test_serial_loops_with_one_thread(monkeypatch):
    from uasep_env._kernels import common

    monkeypatch.setattr(common, "THREADS", [1])
    assert not common._parallel(10 * common.PARALLEL_MIN)
    monkeypatch.setattr(common, "THREADS", [2])
    assert common._parallel(common.PARALLEL_MIN) and not common._parallel(common.PARALLEL_MIN - 1)


def test_noise_threads_take_the_process_share(monkeypatch):
    """The noise pool never starts more threads than the process's share of the cores."""
    from uasep_env.runtime import cores
    from uasep_env.sim import noise

    calls = []
    monkeypatch.setattr(noise, "process_share", lambda: 1)
    noise._run_chunked(calls.append, np.arange(4 * noise.REFILL_CHUNK))
    assert len(calls) == 1  # one share: no pool, one call
    monkeypatch.setattr(noise, "process_share", lambda: 2)
    monkeypatch.setattr(noise, "_pool", [])
    noise._run_chunked(calls.append, np.arange(4 * noise.REFILL_CHUNK))
    assert len(calls) == 3 and noise._pool[0]._max_workers == 2
    noise._pool[0].shutdown()
    assert cores.core_share({"UASEP_WORKERS": "2"}, cores=2) == 1


def test_every_kernel_compiles_without_reference_counting():
    """Each compiled loop allocates nothing and runs without numba's reference counts.

    With them, every array a loop passes to a helper or slices pays atomic increments and
    decrements: the observations at 4096 environments took 4.8x as long (docs/speed.md).
    A kernel that needs to allocate gets its arrays from its Python wrapper instead.
    """
    import inspect

    import numba

    from uasep_env import _kernels

    loops = {}
    for module in sorted(_kernels.__all__):
        owner = sys.modules[getattr(_kernels, module).__module__]
        for name, value in inspect.getmembers(owner):
            if isinstance(value, numba.core.registry.CPUDispatcher):
                loops[f"{owner.__name__}.{name}"] = value
    assert len(loops) >= 30, sorted(loops)  # every module's loops were found
    counted = sorted(name for name, fn in loops.items() if fn.targetoptions.get("_nrt", True))
    assert counted == []


@pytest.mark.parametrize("swept", [True, False])
def test_fit_kernel_builds_the_nodes_of_numpy_bit_for_bit(swept):
    """The fit kernel's per-row nodes (squares, spacings, the set's support) against
    ``_Nodes``, array by array: a node's support feeds the fit only where it binds, so the
    fit's results alone would not show a wrong branch at a node (e.g. exactly at the
    largest turn, where the reachable and the corner formulas differ in the last bit)."""
    from uasep_env._kernels.ellipse_fit import _nodes_row
    from uasep_env.reachable import fit

    cases = []
    reference = fit._fit_certified
    try:
        fit._fit_certified = lambda *args: cases.append(args) or reference.reference(*args)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            fit._ellipse_core(*_case_fit_ellipse_params(), swept)
    finally:
        fit._fit_certified = reference
    th, cos, sin, vt, phi, ip, omc, sc, r = cases[0][:9]
    want = fit._Nodes(th, vt, phi, r, swept, cos, sin, (ip, omc, sc))
    k = th.shape[1]
    at_phi = 0
    for i in range(th.shape[0]):
        c2, s2, d2, h = np.empty(k), np.empty(k), np.empty(k - 1), np.empty(k)
        _nodes_row(th[i], sin[i], cos[i], vt[i], phi[i], ip[i], omc[i], sc[i], r[i], swept,
                   c2, s2, d2, h)  # fmt: skip
        for got, ref in ((c2, want.c2), (s2, want.s2), (d2, want.d2), (h, want.h)):
            np.testing.assert_array_equal(got, ref[i])
        at_phi += int((th[i] == phi[i]).any())
    assert at_phi >= 5  # rows with a node exactly at the largest turn were checked


@pytest.mark.parametrize("numba_on", [True, False])
def test_apf_checks_its_observations_with_and_without_the_kernel(monkeypatch, numba_on):
    """The same errors either way: a wrong width, a NaN or infinite semi-axis (refused by
    every policy's input check, naming the entry)."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies import APF

    if not numba_on:
        monkeypatch.setitem(_numba._state, "numba", None)
    cfg = make_config(scenario="random")
    obs = EnvCore(cfg, n_envs=3).reset(seed=1)
    apf = APF(cfg)
    with pytest.raises(ValueError, match=f"observation width must be {obs.shape[-1]}, got 7"):
        apf(obs[..., :7])
    start = apf.layout.decode_columns()["obstacle_axes"][0]
    for bad in (np.nan, np.inf):
        edited = obs.copy()
        edited[1, 2, start + 1] = bad
        with pytest.raises(ValueError, match=r"entry 'obstacle0\.axes\[1\]' .* not finite"):
            apf(edited)


def test_an_apf_subclass_with_its_own_piece_runs_that_piece():
    """The compiled decision is APF's pieces as they are: a subclass that replaces one
    (here: no obstacle repulsion) gets the numpy form with its own piece."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies import APF
    from uasep_env.policies.apf import _plain

    class NoObstacles(APF):
        def obstacle_repulsion(self, o):
            return np.zeros_like(o["velocity"])

    cfg = make_config(scenario="collision_head_on")
    core = EnvCore(cfg, n_envs=8)
    obs = core.reset(seed=2)
    apf, blind = APF(cfg), NoObstacles(cfg)
    assert _plain(APF) and not _plain(NoObstacles)
    seen = False
    for _ in range(700):
        o = blind.layout.decode(obs)
        want = blind.bound(blind.attraction(o) + blind.inner_repulsion(o), o["velocity"])
        np.testing.assert_array_equal(blind(obs), want.astype(np.float32))
        seen |= not np.array_equal(apf(obs), blind(obs))  # the APF does avoid
        res = core.step(apf(obs))
        obs = res.obs
        done = res.terminated | res.truncated
        if done.any():
            obs[done] = core.reset_some(done)
    assert seen
