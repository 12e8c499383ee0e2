"""Tests of the paper's figure set (headless, on synthetic episodes: no simulator needed)."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from conftest import make_record, run_python

from uasep_env.plotting import (
    closest_approach,
    ellipsoid_surface,
    most_deviated_uav,
    plot_paper_figures,
)
from uasep_env.rollout import Episode


def _episode(seed: int = 0, bump: float = 6.0, n_uavs: int = 3, duration: float = 60.0):
    """A formation flying north at 5 m/s; an obstacle crosses east->west near uav_2."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    t = np.arange(0.0, duration + 1e-9, dt)
    n_t = t.size
    slots = np.array([[0.0, -20.0, 0.0], [0.0, 20.0, 0.0], [0.0, 0.0, 0.0]])[:n_uavs]
    if n_uavs > 3:
        slots = np.array([[0.0, 10.0 * k, 0.0] for k in range(n_uavs)])
    centre = np.stack([5.0 * t, np.zeros_like(t), np.full_like(t, -100.0)], axis=1)
    planned = centre[:, None, :] + slots[None]
    pos = planned.copy()
    # the middle UAV climbs away around t = 30 s (z is down: negative is up)
    pos[:, -1, 2] -= bump * np.exp(-0.5 * ((t - 30.0) / 4.0) ** 2)
    pos += 0.05 * rng.standard_normal(pos.shape)
    vel = np.gradient(pos, dt, axis=0)
    acc = np.gradient(vel, dt, axis=0)
    obs = np.stack([np.full_like(t, 150.0), 150.0 - 5.0 * t, np.full_like(t, -100.0)], axis=1)
    obs = obs[:, None, :]
    active = (t >= 5.0)[:, None]
    d = np.linalg.norm(pos[:, :, None, :] - obs[:, None, :, :], axis=-1)
    record = make_record(
        pos,
        dt,
        planned=planned,
        vel=vel,
        acc=acc,
        obstacle_pos=obs,
        active=active,
        region=d - 25.0,
        collision_distance=3.0,
        uav_separation=8.0,
        obstacle_separation=10.0,
        deviation_threshold=2.0,
        settle_time=10.0,
    )
    heading = np.full((n_t, 1), -math.pi / 2)  # flying west
    center = obs + 10.0 * np.array([0.0, -1.0, 0.0])
    return Episode(
        seed=seed,
        family="synthetic",
        record=record,
        episode_return=0.0,
        steps=n_t - 1,
        terminated=False,
        obstacle_axes=np.array([[30.0, 20.0, 8.0]]),
        pred_center=center,
        pred_heading=heading,
        waypoints=centre[::20, :],
    )


def test_plot_paper_figures_writes_every_png(tmp_path):
    eps = {"apf": _episode(0, bump=6.0), "traditional-apf": _episode(0, bump=9.0)}
    paths = plot_paper_figures(eps, tmp_path / "figs", accel_limit=2.0)
    names = {p.name for p in paths}
    for label in eps:
        for stem in (
            "trajectory_3d",
            "obstacle_distance",
            "uav_distance",
            "deviation",
            "velocity_acceleration",
        ):
            assert f"{stem}_{label}.png" in names
    assert "acceleration_z_comparison.png" in names
    assert len(paths) == 5 * len(eps) + 1
    for p in paths:
        assert p.parent == tmp_path / "figs"
        data = p.read_bytes()
        assert len(data) > 10_000
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
    if "matplotlib.pyplot" in sys.modules:  # no pyplot figure was left open
        import matplotlib.pyplot as plt

        assert plt.get_fignums() == []


def test_plot_sanitises_model_path_labels_and_many_uavs(tmp_path):
    ep = _episode(1, n_uavs=6)
    paths = plot_paper_figures({"runs/model v1.zip": ep}, tmp_path, dpi=50)
    assert all(p.exists() and p.stat().st_size > 0 for p in paths)
    assert all(" " not in p.name and "/" not in p.name for p in paths)


def test_plot_requires_an_episode(tmp_path):
    with pytest.raises(ValueError, match="episodes_by_policy"):
        plot_paper_figures({}, tmp_path)


def test_closest_approach_and_most_deviated():
    ep = _episode(0)
    (m, k, dist), *_ = closest_approach(ep)
    r = ep.record
    d = np.linalg.norm(r.uav_pos[:, :, :] - r.obstacle_pos[:, :1, :], axis=-1)
    d[~r.obstacle_active[:, 0]] = np.inf
    assert m == 0
    assert dist == pytest.approx(d.min())
    assert k == np.unravel_index(np.argmin(d), d.shape)[0]
    assert most_deviated_uav(ep) == 2
    assert most_deviated_uav([ep, _episode(0, bump=0.0)]) == 2


@pytest.mark.parametrize("heading", [0.0, math.pi / 2, 1.0])
def test_ellipsoid_surface_geometry(heading):
    centre = np.array([100.0, -50.0, -80.0])
    axes = np.array([30.0, 10.0, 5.0])
    east, north, alt = ellipsoid_surface(centre, axes, heading)
    dn, de, dz = north - centre[0], east - centre[1], -alt - centre[2]
    lon = dn * math.cos(heading) + de * math.sin(heading)
    lat = -dn * math.sin(heading) + de * math.cos(heading)
    q = (lon / axes[0]) ** 2 + (lat / axes[1]) ** 2 + (dz / axes[2]) ** 2
    np.testing.assert_allclose(q, 1.0, atol=1e-9)
    # the longest extent lies along the heading (north for 0, east for pi/2)
    ext_n, ext_e = np.ptp(north), np.ptp(east)
    if heading == 0.0:
        assert ext_n == pytest.approx(2 * axes[0]) and ext_e == pytest.approx(2 * axes[1])
    if heading == math.pi / 2:
        assert ext_e == pytest.approx(2 * axes[0]) and ext_n == pytest.approx(2 * axes[1])
    assert np.ptp(alt) == pytest.approx(2 * axes[2])


def test_import_does_not_import_matplotlib():
    code = "import sys, uasep_env.plotting; print('matplotlib' in sys.modules)"
    out = run_python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_figure_7_draws_the_region_at_closest_approach_and_the_uavs_tracks():
    """The plan view's outline surrounds the predicted centre; each UAV's track is its path."""
    from uasep_env.plotting import plot_trajectory_3d

    ep = _episode()
    fig = plot_trajectory_3d(ep, "apf")
    top = fig.axes[1]
    (m, k, _), *_ = closest_approach(ep)
    lines = {line.get_label(): line for line in top.get_lines()}
    region = next(v for lab, v in lines.items() if lab.startswith("reachable region at t"))
    east, north = region.get_data()
    centre = ep.pred_center[k, m]
    np.testing.assert_allclose([east[:-1].mean(), north[:-1].mean()], centre[[1, 0]], atol=1e-9)
    r = ep.record
    for i, name in enumerate(r.names):
        east, north = lines[name].get_data()
        np.testing.assert_array_equal(east, r.uav_pos[:, i, 1])
        np.testing.assert_array_equal(north, r.uav_pos[:, i, 0])


def test_figure_9_plots_the_uav_distances():
    from uasep_env.plotting import plot_uav_distances
    from uasep_env.sim.geometry import uav_distances

    ep = _episode()
    fig = plot_uav_distances(ep, "apf")
    d = uav_distances(ep.record.uav_pos)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    names = ep.record.names
    for i, j in ((0, 1), (0, 2), (1, 2)):
        np.testing.assert_allclose(lines[f"{names[i]} – {names[j]}"].get_ydata(), d[:, i, j])
