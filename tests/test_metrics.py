"""Tests of uasep_env.metrics on synthetic episodes with analytically known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import given, make_record, settings, st

from uasep_env.metrics import (
    EpisodeMetrics,
    EpisodeRecord,
    aggregate,
    conflict_timelines,
    episode_metrics,
    flatten_metrics,
    format_table,
    normal_quantile,
    path_lengths,
    rising_edge_counts,
    summary_table,
    t_interval,
    t_quantile,
    wilson_interval,
)

Z975 = 1.959963984540054


def deviation_record(dev_z, dt, *, region=None, settle_time=0.0, threshold=1.0, t0=0.0):
    """One UAV flying along x at 10 m/s, deviating by dev_z (m) upwards (-z in NED)."""
    dev_z = np.asarray(dev_z, dtype=float)
    n_t = dev_z.size
    t = t0 + dt * np.arange(n_t)
    planned = np.zeros((n_t, 1, 3))
    planned[:, 0, 0] = 10.0 * t
    pos = planned.copy()
    pos[:, 0, 2] -= dev_z
    kw = {}
    if region is not None:
        kw = {
            "obstacle_pos": np.full((n_t, 1, 3), 1e4),
            "region": np.asarray(region, dtype=float).reshape(n_t, 1, 1),
        }
    return make_record(
        pos,
        dt,
        planned=planned,
        t0=t0,
        settle_time=settle_time,
        deviation_threshold=threshold,
        **kw,
    )


# ----------------------------------------------------------------------------------------------
# Separation, loss of separation, collisions
# ----------------------------------------------------------------------------------------------


def head_on(dt=0.5, duration=50.0, lateral=6.0, speed=2.0, **kw):
    """Two UAVs approaching head-on: distance sqrt((100 - 2 speed t)^2 + lateral^2)."""
    t = np.arange(0.0, duration + dt / 2, dt)
    pos = np.zeros((t.size, 2, 3))
    pos[:, 0, 0] = -50.0 + speed * t
    pos[:, 1, 0] = 50.0 - speed * t
    pos[:, 0, 1] = -lateral / 2
    pos[:, 1, 1] = lateral / 2
    return make_record(pos, dt, **kw)


def test_head_on_min_separation_and_time():
    m = episode_metrics(head_on())
    # Closest approach at t = 100 / (2 * 2) = 25 s, at the lateral offset 6 m.
    for i, u in enumerate(m.uavs):
        assert u.min_uav_separation == pytest.approx(6.0, abs=1e-12)
        assert u.min_uav_separation_time == pytest.approx(25.0)
        assert u.min_uav_separation_partner_index == 1 - i
    ep = m.episode
    assert ep.min_uav_separation == pytest.approx(6.0)
    assert (ep.min_uav_separation_uav_a_index, ep.min_uav_separation_uav_b_index) == (0, 1)
    assert ep.min_uav_separation_time == pytest.approx(25.0)


def test_head_on_loss_of_separation_time_and_count():
    m = episode_metrics(head_on())
    # d < 10  <=>  |100 - 4t| < 8  <=>  23 < t < 27: samples 23.5 ... 26.5 (7 samples).
    for u in m.uavs:
        assert u.uav_los_events == 1
        assert u.uav_los_time == pytest.approx(7 * 0.5)
        assert u.uav_collision_events == 0
        assert not u.collision
    ep = m.episode
    assert ep.uav_los_events == 1  # one pair, counted once
    assert ep.uav_los_time == pytest.approx(3.5)
    assert ep.uav_loss_of_separation and ep.loss_of_separation
    assert not ep.collision
    assert ep.collision_events == 0


def test_head_on_collision():
    # d < 7  <=>  |100 - 4t| < sqrt(13) = 3.606  <=>  t in (24.10, 25.90): one event.
    m = episode_metrics(head_on(collision_distance=7.0))
    assert m.episode.collision
    assert m.episode.uav_collision
    assert not m.episode.obstacle_collision
    assert m.episode.uav_collision_events == 1
    assert all(u.collision and u.uav_collision_events == 1 for u in m.uavs)


def test_min_separation_partner_among_three():
    n_t = 5
    pos = np.zeros((n_t, 3, 3))
    pos[:, 0, 0] = 0.0
    pos[:, 1, 0] = 40.0
    pos[:, 2, 0] = 20.0 + np.array([0, 0, 8, 0, 0])  # closest to UAV 1 at sample 2 (12 m)
    m = episode_metrics(make_record(pos, 1.0, uav_names=("UAV1", "UAV2", "UAV3")))
    u3 = m.uav("UAV3")
    assert u3.min_uav_separation == pytest.approx(12.0)
    assert u3.min_uav_separation_partner_index == 1
    assert u3.min_uav_separation_time == pytest.approx(2.0)
    assert m.uav("UAV1").min_uav_separation == pytest.approx(20.0)
    assert m.uav("UAV1").min_uav_separation_partner_index == 2
    assert (m.episode.min_uav_separation_uav_a_index, m.episode.min_uav_separation_uav_b_index) == (
        1,
        2,
    )


def runs_of_true(seq):
    return sum(1 for k, v in enumerate(seq) if v and (k == 0 or not seq[k - 1]))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=60))
def test_rising_edges_match_run_count(pattern):
    mask = np.array(pattern)
    assert int(rising_edge_counts(mask)) == runs_of_true(pattern)
    # The same pattern driven through a pair of UAVs: 8 m apart (LoS) or 50 m apart.
    n_t = len(pattern)
    pos = np.zeros((n_t, 2, 3))
    pos[:, 1, 0] = np.where(mask, 8.0, 50.0)
    m = episode_metrics(make_record(pos, 0.25))
    assert m.episode.uav_los_events == runs_of_true(pattern)
    assert m.episode.uav_los_time == pytest.approx(0.25 * sum(pattern))
    assert m.uavs[0].uav_los_events == m.uavs[1].uav_los_events == runs_of_true(pattern)
    assert m.episode.uav_collision_events == 0


def test_rising_edges_multi_dim():
    mask = np.array([[1, 0], [1, 1], [0, 1], [1, 0], [1, 1]], dtype=bool)
    np.testing.assert_array_equal(rising_edge_counts(mask), [2, 2])
    assert rising_edge_counts(np.zeros((0, 3), dtype=bool)).tolist() == [0, 0, 0]


def test_obstacle_los_collision_and_inactive_ignored():
    dt = 1.0
    n_t = 10
    pos = np.zeros((n_t, 1, 3))
    obs = np.zeros((n_t, 1, 3))
    #            0   1   2   3   4   5   6   7   8   9
    dist = [50, 15, 15, 3, 15, 50, 0.5, 15, 50, 50]
    obs[:, 0, 0] = dist
    active = np.ones((n_t, 1), dtype=bool)
    active[6] = False  # the 0.5 m sample is an inactive obstacle: ignored
    region = np.array(dist, dtype=float)[:, None, None] - 12.0
    rec = make_record(pos, dt, obstacle_pos=obs, active=active, region=region)
    m = episode_metrics(rec)
    u = m.uavs[0]
    assert u.min_obstacle_distance == pytest.approx(3.0)
    assert u.min_obstacle_distance_time == pytest.approx(3.0)
    assert u.min_obstacle_distance_obstacle_index == 0
    assert u.min_region_distance == pytest.approx(-9.0)
    assert u.min_region_distance_time == pytest.approx(3.0)
    # LoS (< 20 m): samples 1-4 and 7 (6 inactive breaks the run) -> 2 events, 5 s.
    assert u.obstacle_los_events == 2
    assert u.obstacle_los_time == pytest.approx(5.0)
    # Collision (< 5 m): sample 3 only.
    assert u.obstacle_collision_events == 1
    assert u.collision
    ep = m.episode
    assert ep.obstacle_collision and ep.collision and not ep.uav_collision
    assert ep.obstacle_los_events == 2
    assert ep.min_obstacle_distance_uav_index == 0
    assert ep.min_obstacle_distance_obstacle_index == 0


def test_inactive_obstacle_may_hold_nan():
    n_t = 4
    pos = np.zeros((n_t, 1, 3))
    obs = np.full((n_t, 1, 3), np.nan)
    obs[2, 0] = [30.0, 0.0, 0.0]
    active = np.zeros((n_t, 1), dtype=bool)
    active[2] = True
    region = np.full((n_t, 1, 1), np.nan)
    region[2] = 10.0
    m = episode_metrics(make_record(pos, 1.0, obstacle_pos=obs, active=active, region=region))
    assert m.uavs[0].min_obstacle_distance == pytest.approx(30.0)
    assert m.uavs[0].min_region_distance == pytest.approx(10.0)


def test_no_obstacles_single_uav_is_nan_and_json_safe():
    pos = np.zeros((5, 1, 3))
    pos[:, 0, 0] = np.arange(5.0)
    m = episode_metrics(make_record(pos, 1.0))
    u = m.uavs[0]
    assert math.isnan(u.min_uav_separation)
    assert u.min_uav_separation_partner_index == -1
    assert math.isnan(u.min_obstacle_distance)
    assert u.min_obstacle_distance_obstacle_index == -1
    assert math.isnan(m.episode.min_region_distance)
    assert not m.episode.collision
    d = json.loads(m.to_json())
    assert d["uavs"][0]["min_uav_separation"] is None
    json.dumps(m.to_dict())  # plain types throughout


# ----------------------------------------------------------------------------------------------
# Trajectory deviation and conflict-resolution timeline
# ----------------------------------------------------------------------------------------------


def sin2_bump(t, t0=100.0, width=30.0, amp=5.0):
    inside = (t >= t0) & (t <= t0 + width)
    return np.where(inside, amp * np.sin(np.pi * (t - t0) / width) ** 2, 0.0)


def test_deviation_bump_stats_and_timeline():
    dt = 0.5
    t = np.arange(0.0, 150.0 + dt / 2, dt)
    dev = sin2_bump(t)
    # Closest approach to the region at 112 s (inside the region between 108 s and 116 s).
    region = np.abs(t - 112.0) - 4.0
    rec = deviation_record(dev, dt, region=region, settle_time=10.0)
    m = episode_metrics(rec)
    u = m.uavs[0]

    # Crossing of 1 m: sin^2(pi s / 30) = 1/5 at s = 30/pi asin(sqrt(0.2)) = 4.4272 s.
    s_cross = 30.0 / np.pi * np.arcsin(np.sqrt(0.2))
    leave_exact, back_exact = 100.0 + s_cross, 130.0 - s_cross
    tl = u.timeline
    assert tl.left and not tl.never_returned and not tl.started_off_track
    assert tl.t_leave == pytest.approx(np.ceil(leave_exact / dt) * dt)  # 104.5
    assert tl.t_back == pytest.approx(np.ceil(back_exact / dt) * dt)  # 126.0
    assert tl.t_resolved == pytest.approx(112.0)
    assert tl.resolved_region_distance == pytest.approx(-4.0)
    assert tl.t_region_exit == pytest.approx(116.5)  # first sample with region > 0
    assert tl.time_to_resolve == pytest.approx(112.0 - 104.5)
    assert tl.recovery_time == pytest.approx(126.0 - 112.0)
    assert tl.conflict_duration == pytest.approx(126.0 - 104.5)
    assert tl.n_departures == 1

    # Statistics over the 281 samples from 10 s to 150 s: the sampled sum of sin^4 over one
    # period of 60 samples is exactly 60 * 3/8.
    n_settled = int(np.sum(t >= 10.0))
    rms = np.sqrt(25.0 * 60 * 3 / 8 / n_settled)
    dv = u.deviation
    assert dv.max_norm == pytest.approx(5.0)
    assert dv.max_norm_time == pytest.approx(115.0)
    assert dv.rms_norm == pytest.approx(rms, rel=1e-12)
    assert dv.max_abs == pytest.approx((0.0, 0.0, 5.0))
    assert dv.rms == pytest.approx((0.0, 0.0, rms), rel=1e-12)
    assert dv.time_off_track == pytest.approx(np.sum(dev > 1.0) * dt)
    assert m.episode.max_deviation == pytest.approx(5.0)
    assert m.episode.n_uavs_left == 1
    assert m.episode.max_conflict_duration == pytest.approx(21.5)


def test_paper_timeline_103_122_130():
    """The paper's UAV3: leaves at 103 s, resolved at 122 s, back at 130 s: 27 s in total."""
    dt = 0.5
    t = np.arange(0.0, 160.0 + dt / 2, dt)
    dev = np.where((t >= 103.0) & (t < 130.0), 3.0, 0.0)
    region = np.where(t < 122.0, 122.0 - t, 0.5 * (t - 122.0)) + 2.0
    m = episode_metrics(deviation_record(dev, dt, region=region, settle_time=20.0))
    tl = m.uavs[0].timeline
    assert (tl.t_leave, tl.t_resolved, tl.t_back) == pytest.approx((103.0, 122.0, 130.0))
    assert tl.conflict_duration == pytest.approx(27.0)
    assert tl.time_to_resolve == pytest.approx(19.0)
    assert tl.recovery_time == pytest.approx(8.0)


def test_timeline_never_left():
    dt = 0.5
    t = np.arange(0.0, 20.0, dt)
    tl = conflict_timelines(deviation_record(0.9 * np.ones_like(t), dt))[0]
    assert not tl.left and not tl.never_returned
    for v in (tl.t_leave, tl.t_resolved, tl.t_back, tl.conflict_duration, tl.time_to_resolve):
        assert math.isnan(v)


def test_timeline_never_came_back():
    dt = 0.5
    t = np.arange(0.0, 60.0, dt)
    dev = np.where(t >= 30.0, 4.0, 0.0)
    tl = conflict_timelines(deviation_record(dev, dt))[0]
    assert tl.left and tl.never_returned
    assert tl.t_leave == pytest.approx(30.0)
    assert math.isnan(tl.t_back) and math.isnan(tl.conflict_duration)
    assert math.isnan(tl.t_resolved)  # no obstacle at all


def test_timeline_return_needs_full_hold_window_inside_record():
    dt = 0.5
    t = np.arange(0.0, 40.0 + dt / 2, dt)  # last sample 40 s
    dev = np.where((t >= 10.0) & (t < 38.5), 4.0, 0.0)  # back at 38.5: 1.5 s < hold
    assert conflict_timelines(deviation_record(dev, dt), hold_time=2.0)[0].never_returned
    tl = conflict_timelines(deviation_record(dev, dt), hold_time=1.5)[0]
    assert tl.t_back == pytest.approx(38.5)
    tl0 = conflict_timelines(deviation_record(dev, dt), hold_time=0.0)[0]
    assert tl0.t_back == pytest.approx(38.5)


def test_timeline_short_dip_stays_inside_excursion():
    dt = 0.5
    t = np.arange(0.0, 80.0, dt)
    dev = np.where((t >= 10.0) & (t < 40.0), 4.0, 0.0)
    dev[(t >= 20.0) & (t < 21.0)] = 0.5  # 1 s dip, shorter than the 2 s hold
    region = np.abs(t - 30.0) + 1.0  # closest approach after the dip
    tl = conflict_timelines(deviation_record(dev, dt, region=region))[0]
    assert tl.t_leave == pytest.approx(10.0)
    assert tl.t_resolved == pytest.approx(30.0)
    assert tl.t_back == pytest.approx(40.0)
    assert tl.n_departures == 2


def test_timeline_settle_time_and_started_off_track():
    dt = 1.0
    t = np.arange(0.0, 60.0, dt)
    dev = np.where(t < 5.0, 30.0, 0.0)  # forming up
    dev[(t >= 20) & (t < 25)] = 2.0
    tl = conflict_timelines(deviation_record(dev, dt, settle_time=8.0))[0]
    assert tl.t_leave == pytest.approx(20.0) and not tl.started_off_track
    assert tl.t_back == pytest.approx(25.0)
    m = episode_metrics(deviation_record(dev, dt, settle_time=8.0))
    assert m.uavs[0].deviation.max_norm == pytest.approx(2.0)  # the 30 m before 8 s ignored
    tl = conflict_timelines(deviation_record(dev, dt, settle_time=3.0))[0]
    assert tl.started_off_track and tl.t_leave == pytest.approx(3.0)
    assert tl.t_back == pytest.approx(5.0)


def test_hold_time_validation():
    rec = deviation_record(np.zeros(10), 1.0)
    with pytest.raises(ValueError, match=r"^hold_time"):
        conflict_timelines(rec, hold_time=-1.0)


# ----------------------------------------------------------------------------------------------
# Velocity / acceleration fluctuation, path length
# ----------------------------------------------------------------------------------------------


def test_sinusoidal_velocity_fluctuation():
    dt, period, amp = 0.1, 10.0, 3.0
    omega = 2 * np.pi / period
    n_t = 400  # exactly 4 periods (the sample at 40 s is not included)
    t = dt * np.arange(n_t)
    pos = np.zeros((n_t, 1, 3))
    vel = np.zeros((n_t, 1, 3))
    acc = np.zeros((n_t, 1, 3))
    vel[:, 0, 0] = 12.0
    vel[:, 0, 2] = amp * np.sin(omega * t)
    acc[:, 0, 2] = amp * omega * np.cos(omega * t)
    f = episode_metrics(make_record(pos, dt, vel=vel, acc=acc)).uavs[0].fluctuation
    assert f.vel_std == pytest.approx((0.0, 0.0, amp / np.sqrt(2)), rel=1e-12, abs=1e-12)
    assert f.acc_std == pytest.approx((0.0, 0.0, amp * omega / np.sqrt(2)), rel=1e-12, abs=1e-12)
    # max |v(t+dt) - v(t)| = 2 amp sin(omega dt / 2) max|cos(omega (t + dt/2))|, reached at a
    # sample here: amp sin(omega dt) / dt. Same for a with amp * omega.
    assert f.vel_max_rate[2] == pytest.approx(amp * np.sin(omega * dt) / dt, rel=1e-12)
    assert f.acc_max_rate[2] == pytest.approx(amp * omega * np.sin(omega * dt) / dt, rel=1e-12)
    assert f.vel_max_rate[0] == 0.0
    assert f.acc_max_abs[2] == pytest.approx(amp * omega)
    assert f.speed_max == pytest.approx(np.sqrt(144 + amp**2), rel=1e-4)


def test_zigzag_path_length_ratio():
    dt = 1.0
    n_t = 41
    t = np.arange(n_t, dtype=float)
    planned = np.zeros((n_t, 1, 3))
    planned[:, 0, 0] = 4.0 * t
    pos = planned.copy()
    pos[:, 0, 1] = np.where(np.arange(n_t) % 2 == 0, 0.0, 3.0)  # 3 m zig-zag every sample
    flown, planned_len, ratio = path_lengths(make_record(pos, dt, planned=planned))
    assert planned_len[0] == pytest.approx(160.0)
    assert flown[0] == pytest.approx(40 * 5.0)  # each leg sqrt(4^2 + 3^2) = 5 m
    assert ratio[0] == pytest.approx(1.25)
    m = episode_metrics(make_record(pos, dt, planned=planned, settle_time=10.0))
    assert m.uavs[0].path_length_ratio == pytest.approx(1.25)
    assert m.uavs[0].planned_path_length == pytest.approx(120.0)


def test_static_plan_gives_nan_ratio():
    pos = np.zeros((5, 1, 3))
    pos[:, 0, 0] = np.arange(5.0)
    m = episode_metrics(make_record(pos, 1.0, planned=np.zeros((5, 1, 3))))
    assert math.isnan(m.uavs[0].path_length_ratio)


@settings(max_examples=25, deadline=None)
@given(
    offset=st.tuples(*[st.floats(-1e3, 1e3, allow_nan=False)] * 3),
    seed=st.integers(0, 2**16),
)
def test_translation_invariance(offset, seed):
    rng = np.random.default_rng(seed)
    n_t, n, m = 30, 3, 2
    pos = np.cumsum(rng.normal(size=(n_t, n, 3)), axis=0) + rng.normal(scale=20, size=(1, n, 3))
    planned = pos + rng.normal(scale=1.0, size=pos.shape)
    obs = rng.normal(scale=20, size=(n_t, m, 3))
    vel = rng.normal(size=pos.shape)
    region = rng.normal(scale=10, size=(n_t, n, m))
    kw = {"planned": planned, "vel": vel, "obstacle_pos": obs, "region": region}
    a = episode_metrics(make_record(pos, 0.5, **kw)).to_dict()
    off = np.asarray(offset)
    kw2 = {**kw, "planned": planned + off, "obstacle_pos": obs + off}
    b = episode_metrics(make_record(pos + off, 0.5, **kw2)).to_dict()
    fa, fb = flatten_metrics(a), flatten_metrics(b)
    assert fa.keys() == fb.keys()
    for k in fa:
        assert fa[k] == pytest.approx(fb[k], rel=1e-6, abs=1e-6, nan_ok=True), k


# ----------------------------------------------------------------------------------------------
# Quantiles and confidence intervals
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("n", "expected"),
    [(2, 12.7062047362), (5, 2.7764451052), (30, 2.0452296421)],
)
def test_t_quantile_table(n, expected):
    assert t_quantile(0.975, n - 1) == pytest.approx(expected, abs=1e-3)
    assert t_quantile(0.975, n - 1) == pytest.approx(expected, abs=1e-8)
    assert t_quantile(0.025, n - 1) == pytest.approx(-expected, abs=1e-8)


@pytest.mark.parametrize(
    ("p", "df", "expected"),
    [
        (0.95, 1, 6.3137515147),
        (0.975, 2, 4.3026527297),
        (0.95, 10, 1.8124611228),
        (0.995, 10, 3.1692726726),
        (0.975, 100, 1.9839715185),
        (0.9, 3, 1.6377443537),
    ],
)
def test_t_quantile_more_values(p, df, expected):
    assert t_quantile(p, df) == pytest.approx(expected, abs=1e-8)


def test_t_quantile_tends_to_normal_and_validates():
    assert t_quantile(0.975, 1e7) == pytest.approx(Z975, abs=1e-6)
    assert normal_quantile(0.975) == pytest.approx(Z975, abs=1e-12)
    assert normal_quantile(0.5) == 0.0
    with pytest.raises(ValueError, match=r"^df"):
        t_quantile(0.9, 0)
    with pytest.raises(ValueError, match=r"^p"):
        t_quantile(1.0, 3)


@settings(max_examples=40, deadline=None)
@given(p=st.floats(0.51, 0.999), df=st.floats(0.5, 200))
def test_t_quantile_monotone_in_df(p, df):
    q = t_quantile(p, df)
    assert q > 0
    assert t_quantile(p, df * 1.5) <= q + 1e-9
    assert q >= normal_quantile(p) - 1e-9


#: The hand-written quantiles and Wilson interval (continued fraction and bisection) that
#: scipy.stats replaced: the intervals of the results files moved by < 3e-12 relative.
OLD_T = [
    (0.975, 1, 12.706204736174696),
    (0.975, 4, 2.776445105197787),
    (0.975, 19, 2.0930240544083105),
    (0.975, 199, 1.9719565442517464),
    (0.975, 499, 1.9647293909877632),
    (0.995, 4, 4.604094871349972),
    (0.95, 9, 1.8331129326562277),
    (0.9, 29, 1.311433647301559),
]
OLD_Z = [(0.975, 1.959963984540046), (0.995, 2.5758293035488933), (0.95, 1.6448536269514662)]
OLD_WILSON = [
    (0, 20, (0.0, 0.16112515805281827)),
    (1, 20, (0.008881448800795458, 0.236131193446741)),
    (3, 10, (0.10779126740630149, 0.6032218525388535)),
    (8, 500, (0.008129253033388335, 0.031251108533394176)),
    (19, 500, (0.02446011805583043, 0.058584772530643786)),
    (200, 200, (0.9811546736227338, 1.0)),
]


def test_scipy_statistics_match_the_hand_written_ones():
    for p, df, old in OLD_T:
        assert t_quantile(p, df) == pytest.approx(old, rel=1e-9, abs=0)
    for p, old in OLD_Z:
        assert normal_quantile(p) == pytest.approx(old, rel=1e-9, abs=0)
    for k, n, old in OLD_WILSON:
        low, high = wilson_interval(k, n)
        assert (low, high) == pytest.approx(old, rel=1e-9, abs=0)
        assert (k > 0 or low == 0.0) and (k < n or high == 1.0)  # exact ends


def test_t_interval_values():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, np.nan])
    lo, hi = t_interval(x)
    half = 2.7764451052 * np.std(x[:5], ddof=1) / np.sqrt(5)
    assert (lo, hi) == pytest.approx((3.0 - half, 3.0 + half), abs=1e-8)
    assert all(math.isnan(v) for v in t_interval([1.0]))


def test_t_interval_coverage_monte_carlo():
    rng = np.random.default_rng(1234)
    n, reps = 5, 4000
    x = rng.normal(loc=7.0, scale=2.0, size=(reps, n))
    half = t_quantile(0.975, n - 1) * x.std(axis=1, ddof=1) / np.sqrt(n)
    cover = np.mean(np.abs(x.mean(axis=1) - 7.0) <= half)
    assert 0.935 <= cover <= 0.965
    # Spot check: the vectorised half-width agrees with t_interval.
    lo, hi = t_interval(x[0])
    assert hi - lo == pytest.approx(2 * half[0])


@pytest.mark.parametrize("n", [1, 5, 20, 300])
def test_wilson_at_extremes(n):
    z2 = Z975**2
    assert wilson_interval(0, n) == pytest.approx((0.0, z2 / (n + z2)), abs=1e-12)
    assert wilson_interval(n, n) == pytest.approx((n / (n + z2), 1.0), abs=1e-12)


def test_wilson_known_value_and_validation():
    # k = 3 of n = 10 at 95 %: [0.10779, 0.60322].
    assert wilson_interval(3, 10) == pytest.approx((0.1077913, 0.6032219), abs=1e-6)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(ValueError, match=r"^successes"):
        wilson_interval(5, 3)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 500), frac=st.floats(0, 1))
def test_wilson_contains_estimate(n, frac):
    k = round(frac * n)
    lo, hi = wilson_interval(k, n)
    assert 0.0 <= lo <= k / n <= hi <= 1.0


def test_wilson_coverage_monte_carlo():
    rng = np.random.default_rng(99)
    n, p = 40, 0.2
    ks = rng.binomial(n, p, size=2000)
    cover = np.mean([lo <= p <= hi for lo, hi in (wilson_interval(int(k), n) for k in ks)])
    assert 0.92 <= cover <= 0.98


# ----------------------------------------------------------------------------------------------
# Aggregation and tables
# ----------------------------------------------------------------------------------------------


def episodes():
    out = []
    for lateral, coll in [(6.0, 5.0), (4.0, 5.0), (12.0, 5.0), (3.0, 5.0)]:
        out.append(episode_metrics(head_on(lateral=lateral, collision_distance=coll)))
    return out


def test_aggregate_means_and_rates():
    ms = episodes()
    agg = aggregate(ms)
    s = agg["episode.min_uav_separation"]
    vals = np.array([6.0, 4.0, 12.0, 3.0])
    assert s["kind"] == "mean" and s["n"] == 4 and s["n_valid"] == 4
    assert s["mean"] == pytest.approx(vals.mean())
    assert s["std"] == pytest.approx(vals.std(ddof=1))
    assert (s["min"], s["max"]) == (3.0, 12.0)
    half = t_quantile(0.975, 3) * vals.std(ddof=1) / 2.0
    assert (s["ci_low"], s["ci_high"]) == pytest.approx((vals.mean() - half, vals.mean() + half))
    c = agg["episode.collision"]  # collisions at 4 m and 3 m lateral (< 5 m)
    assert c["kind"] == "rate" and c["successes"] == 2 and c["rate"] == pytest.approx(0.5)
    assert (c["ci_low"], c["ci_high"]) == pytest.approx(wilson_interval(2, 4))
    los = agg["episode.loss_of_separation"]  # 12 m lateral never below 10 m
    assert los["successes"] == 3
    assert "uav.uav_0.deviation.max_abs.z" in agg
    assert not any(k.endswith("_index") for k in agg)
    json.dumps(agg)


def test_aggregate_ignores_nan_and_accepts_dicts():
    ms = episodes()
    single = np.zeros((3, 1, 3))
    single[:, 0, 0] = [0.0, 1.0, 2.0]
    ms.append(episode_metrics(make_record(single, 1.0, uav_names=("uav_0",))))
    agg = aggregate([m.to_dict() for m in ms])
    s = agg["episode.min_uav_separation"]
    assert s["n"] == 5 and s["n_valid"] == 4
    assert s["mean"] == pytest.approx(6.25)
    assert agg["uav.uav_1.min_uav_separation"]["n_valid"] == 4
    assert aggregate(ms)["episode.min_uav_separation"]["mean"] == pytest.approx(6.25)
    empty = aggregate([])
    assert empty == {}


def test_aggregate_single_episode_has_nan_ci():
    agg = aggregate(episodes()[:1])
    s = agg["episode.min_uav_separation"]
    assert s["n_valid"] == 1 and math.isnan(s["std"]) and math.isnan(s["ci_low"])


def test_summary_and_format_tables():
    ms = episodes()
    rows = summary_table(ms[0])
    assert rows[0][0] == "uav" and len(rows) == 3
    text = format_table(rows)
    assert "min_uav_separation" in text.splitlines()[0]
    assert set(text.splitlines()[1]) <= {"-", " "}

    ep_rows = summary_table(ms, keys=["min_uav_separation", "collision"])
    assert ep_rows[0] == ("episode", "min_uav_separation", "collision")
    assert ep_rows[2][1] == pytest.approx(4.0) and ep_rows[2][2] is True

    agg_rows = summary_table(aggregate(ms), keys=["episode.collision", "max_deviation"])
    assert [r[0] for r in agg_rows[1:]] == ["episode.collision", "episode.max_deviation"]
    out = format_table(agg_rows[1:], headers=agg_rows[0], floatfmt=".3f")
    lines = out.splitlines()
    assert len(lines) == 4
    assert len({len(line) for line in lines[:2]}) == 1
    assert "0.500" in lines[2]


def test_format_table_alignment_and_errors():
    out = format_table([("a", 1.5, True), ("bbb", 10.25, False)], headers=("name", "v", "ok"))
    lines = out.splitlines()
    assert lines[0].startswith("name")
    assert lines[2].endswith("yes") and lines[3].endswith("no")
    assert lines[2].index("1.5") + 3 == lines[3].index("10.25") + 5  # right-aligned numbers
    with pytest.raises(ValueError, match=r"^rows"):
        format_table([("a",)], headers=("x", "y"))
    assert format_table([]) == ""


def test_metrics_are_frozen_and_serialisable():
    m = episodes()[0]
    assert isinstance(m, EpisodeMetrics)
    with pytest.raises(AttributeError):
        m.episode.collision = True  # type: ignore[misc]
    d = m.to_dict()
    assert d["uavs"][0]["deviation"]["max_abs"] == {"x": 0.0, "y": 0.0, "z": 0.0}
    assert d["config"]["uav_separation"] == 10.0
    json.loads(m.to_json())


# ----------------------------------------------------------------------------------------------
# Input validation
# ----------------------------------------------------------------------------------------------


def good_kwargs(n_t=6, n=2, m=1):
    t = np.arange(n_t) * 0.5
    return {
        "time": t,
        "dt": 0.5,
        "uav_pos": np.zeros((n_t, n, 3)),
        "uav_vel": np.zeros((n_t, n, 3)),
        "uav_acc": np.zeros((n_t, n, 3)),
        "planned_pos": np.zeros((n_t, n, 3)),
        "obstacle_pos": np.zeros((n_t, m, 3)),
        "obstacle_active": np.ones((n_t, m), dtype=bool),
        "region_distance": np.ones((n_t, n, m)),
        "collision_distance": 5.0,
        "uav_separation": 10.0,
        "obstacle_separation": 20.0,
    }


def test_good_record_converts_inputs():
    kw = good_kwargs()
    kw["time"] = list(kw["time"])
    kw["obstacle_active"] = kw["obstacle_active"].astype(int)
    rec = EpisodeRecord(**kw)
    assert rec.time.dtype == np.float64
    assert rec.obstacle_active.dtype == bool
    assert rec.uav_names == ("uav_0", "uav_1")
    assert (rec.n_steps, rec.n_uavs, rec.n_obstacles) == (6, 2, 1)


BAD = [
    ("time", lambda kw: kw.update(time=kw["time"][::-1])),
    ("time", lambda kw: kw.update(time=kw["time"] ** 1.1)),
    ("time", lambda kw: kw.update(time=kw["time"][:, None])),
    ("time", lambda kw: kw.update(dt=0.25)),
    ("dt", lambda kw: kw.update(dt=-0.5)),
    ("dt", lambda kw: kw.update(dt=float("nan"))),
    ("uav_pos", lambda kw: kw.update(uav_pos=np.zeros((6, 2, 2)))),
    ("uav_pos", lambda kw: kw.update(uav_pos=np.zeros((5, 2, 3)))),
    ("uav_vel", lambda kw: kw.update(uav_vel=np.zeros((6, 3, 3)))),
    ("uav_acc", lambda kw: kw.update(uav_acc=np.full((6, 2, 3), np.inf))),
    ("planned_pos", lambda kw: kw.update(planned_pos=np.full((6, 2, 3), np.nan))),
    ("obstacle_pos", lambda kw: kw.update(obstacle_pos=np.zeros((6, 1, 2)))),
    ("obstacle_pos", lambda kw: kw.update(obstacle_pos=np.full((6, 1, 3), np.nan))),
    ("obstacle_active", lambda kw: kw.update(obstacle_active=np.ones((6, 2), dtype=bool))),
    ("obstacle_active", lambda kw: kw.update(obstacle_active=np.full((6, 1), 0.5))),
    ("region_distance", lambda kw: kw.update(region_distance=np.ones((6, 1, 1)))),
    ("region_distance", lambda kw: kw.update(region_distance=np.full((6, 2, 1), np.nan))),
    ("collision_distance", lambda kw: kw.update(collision_distance=0.0)),
    ("uav_separation", lambda kw: kw.update(uav_separation=5.0)),
    ("obstacle_separation", lambda kw: kw.update(obstacle_separation=4.0)),
    ("deviation_threshold", lambda kw: kw.update(deviation_threshold=0.0)),
    ("settle_time", lambda kw: kw.update(settle_time=100.0)),
    ("settle_time", lambda kw: kw.update(settle_time="soon")),
    ("uav_names", lambda kw: kw.update(uav_names=("a",))),
    ("uav_names", lambda kw: kw.update(uav_names=("a", "a"))),
    ("uav_names", lambda kw: kw.update(uav_names="ab")),
    ("step_cost", lambda kw: kw.update(step_cost=np.zeros((6, 2)))),  # one row per step: 5
    ("step_cost", lambda kw: kw.update(step_cost=np.full((5, 2), -1.0))),
    ("step_cost", lambda kw: kw.update(step_cost=np.full((5, 2), np.nan))),
]


@pytest.mark.parametrize(("field", "mutate"), BAD)
def test_bad_input_names_field(field, mutate):
    kw = good_kwargs()
    mutate(kw)
    with pytest.raises(ValueError, match=f"^{field}"):
        EpisodeRecord(**kw)


def test_no_worse_rate_is_the_overlap_rule():
    from uasep_env.metrics.statistics import no_worse_rate, wilson_interval

    apf = dict(zip(("ci_low", "ci_high"), wilson_interval(0, 50), strict=True))  # [0, 7.1 %]
    six = dict(zip(("ci_low", "ci_high"), wilson_interval(3, 50), strict=True))  # 2.1 % low
    twenty_two = dict(zip(("ci_low", "ci_high"), wilson_interval(11, 50), strict=True))
    assert no_worse_rate(six, apf) and no_worse_rate(apf, six)  # overlapping: no worse
    assert not no_worse_rate(twenty_two, apf)  # 12.8 % > 7.1 %: worse
    assert no_worse_rate(apf, twenty_two)  # lower: no worse
    with pytest.raises(ValueError, match="ci_low and ci_high"):
        no_worse_rate({"rate": 0.1}, apf)
    with pytest.raises(ValueError, match="NaN"):
        no_worse_rate({"ci_low": math.nan}, apf)


def test_episode_cost_is_each_uavs_summed_step_cost_and_the_team_mean():
    """Per UAV the sum over steps; the episode: the mean over UAVs and the worst UAV."""
    pos = np.zeros((4, 3, 3))
    pos[:, :, 0] = [0.0, 50.0, 100.0]
    step_cost = np.array([[1.0, 0.0, 2.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.5]])  # 3 steps
    m = episode_metrics(make_record(pos, 1.0, step_cost=step_cost))
    assert [u.cost for u in m.uavs] == [2.0, 0.0, 2.5]
    assert m.episode.cost == pytest.approx(4.5 / 3)
    assert m.episode.max_uav_cost == 2.5
    flat = flatten_metrics(m)
    assert flat["episode.cost"] == pytest.approx(1.5) and flat["uav.uav_2.cost"] == 2.5
    agg = aggregate([m, episode_metrics(make_record(pos, 1.0, step_cost=0 * step_cost))])
    assert agg["episode.cost"]["mean"] == pytest.approx(0.75)
    assert agg["episode.cost"]["kind"] == "mean" and agg["episode.cost"]["n_valid"] == 2
    # a record without the cost channel: NaN, never 0 (and not counted as a value)
    bare = episode_metrics(make_record(pos, 1.0))
    assert math.isnan(bare.uavs[0].cost) and math.isnan(bare.episode.cost)
    assert json.loads(bare.to_json())["episode"]["cost"] is None
    assert aggregate([m, bare])["episode.cost"]["n_valid"] == 1


def _wilson(k: int, n: int) -> dict[str, float]:
    from uasep_env.metrics.statistics import wilson_interval

    low, high = wilson_interval(k, n)
    return {"rate": k / n, "ci_low": low, "ci_high": high, "n_valid": n}


@pytest.mark.parametrize(
    ("policy", "apf", "verdict"),
    [
        ((4, 5), (0, 5), "not shown"),  # 80 % [37.6, 96.4] vs 0 % [0, 43.4]: overlap, worse
        ((0, 5), (0, 5), "not shown"),  # equal, but 5 episodes cannot rule out 43 %
        ((0, 50), (0, 50), "met"),  # 0 of 50 each: the bound 7.1 % is within 10 points
        ((1, 500), (3, 500), "met"),  # lower, and tightly bounded
        ((1, 50), (0, 50), "not shown"),  # 2 % vs 0 %: the point estimate is worse
        ((3, 500), (1, 500), "not shown"),  # tightly bounded, but worse
        ((40, 50), (0, 50), "not met"),  # 80 % [67, 89] wholly above [0, 7.1]
        ((11, 50), (0, 50), "not met"),
    ],
)
def test_rate_verdict_never_says_met_on_wide_intervals(policy, apf, verdict):
    from uasep_env.metrics.statistics import rate_verdict

    assert rate_verdict(_wilson(*policy), _wilson(*apf)) == verdict


def test_rate_verdict_reads_means_and_rejects_bad_input():
    from uasep_env.metrics.statistics import rate_verdict

    seeds = {"mean": 0.0, "ci_low": 0.0, "ci_high": 0.01}  # a bootstrap interval: no "rate"
    assert rate_verdict(seeds, seeds) == "met"
    assert rate_verdict(_wilson(0, 50), _wilson(0, 50), margin=0.05) == "not shown"
    with pytest.raises(ValueError, match="margin"):
        rate_verdict(seeds, seeds, margin=-0.1)
    with pytest.raises(ValueError, match="NaN"):
        rate_verdict(seeds | {"mean": math.nan}, seeds)
    with pytest.raises(ValueError, match="ci_low and ci_high"):
        rate_verdict({"rate": 0.1}, seeds)


def test_stated_and_weakest_verdicts():
    from uasep_env.metrics.statistics import stated_rate_verdict, weakest_verdict

    assert stated_rate_verdict(_wilson(1, 5), _wilson(0, 5)) == "not shown (5 vs 5 episodes)"
    assert stated_rate_verdict(_wilson(0, 50), _wilson(0, 40)) == "met (50 vs 40 episodes)"
    assert stated_rate_verdict({"rate": 0.0, "ci_low": 0.0, "ci_high": 0.0}, _wilson(0, 5)) == (
        "met (? vs 5 episodes)"
    )
    assert weakest_verdict(["met", "not shown", "met"]) == "not shown"
    assert weakest_verdict(["not shown", "not met"]) == "not met"
    assert weakest_verdict(["met"]) == "met"
    with pytest.raises(ValueError, match="verdicts"):
        weakest_verdict([])
    with pytest.raises(ValueError, match="verdicts"):
        weakest_verdict(["met", "n/a"])
