"""Tests of the matplotlib renderer (headless: the Agg backend is forced)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import gymnasium
from conftest import run_in_repo, run_python

import uasep_env
from uasep_env.rendering import Renderer, ellipsoid_points, save_frame
from uasep_env.sim.world import World


@pytest.fixture(autouse=True)
def _agg_backend():
    import matplotlib

    matplotlib.use("Agg")  # never open windows in tests, even with a display


def _world(seed: int = 0, **config) -> World:
    w = World({"scenario": "paper", **config}, n_envs=1)
    w.reset(seed=seed)
    return w


def _zero(w: World) -> np.ndarray:
    return np.zeros((w.n_envs, w.n_uavs, 3))


def _check_frame(frame) -> None:
    assert isinstance(frame, np.ndarray)
    assert frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 100 and frame.shape[1] >= 100
    colours = np.unique(frame.reshape(-1, 3)[::7], axis=0)
    assert len(colours) > 20, "frame looks blank"


def test_import_does_not_import_matplotlib():
    res = run_python(
        """
        import sys
        import uasep_env.rendering
        import uasep_env
        env = uasep_env.parallel_env()
        env.reset(seed=0)
        bad = sorted(m for m in sys.modules if m.split(".")[0] in ("matplotlib", "mpl_toolkits"))
        assert not bad, bad
        print("ok")
        """
    )
    assert res.returncode == 0, res.stderr
    assert "ok" in res.stdout


def test_rgb_array_frame():
    w = _world()
    r = Renderer(mode="rgb_array")
    try:
        frame = r.render(w)
        _check_frame(frame)
        assert frame.shape == (640, 1120, 3)  # default size: multiples of 16 for video
        # Red obstacle and coloured UAV pixels are present, not only greys.
        assert (frame.astype(int).max(axis=2) - frame.astype(int).min(axis=2) > 80).sum() > 50
    finally:
        r.close()


def test_frames_change_as_world_steps():
    w = _world()
    r = Renderer()
    try:
        first = r.render(w)
        for _ in range(10):
            w.step(_zero(w))
        second = r.render(w)
        assert first.shape == second.shape
        assert (first != second).any(axis=2).sum() > 100
    finally:
        r.close()


def test_figure_reused_and_trails_cleared_on_reset():
    w = _world(seed=3)
    r = Renderer()
    fresh = Renderer()
    try:
        r.render(w)
        fig = r.fig
        for _ in range(8):
            w.step(_zero(w))
            r.render(w)
        assert r.fig is fig  # one figure for the whole run
        w.reset(seed=3)  # time goes back to 0: the trails must restart
        again = r.render(w)
        np.testing.assert_array_equal(again, fresh.render(w))
    finally:
        r.close()
        fresh.close()


def test_close_is_idempotent_and_renderer_reusable():
    w = _world()
    r = Renderer()
    r.render(w)
    r.close()
    r.close()
    assert r.fig is None
    _check_frame(r.render(w))  # a closed renderer draws again with a new figure
    r.close()


def test_invalid_arguments():
    with pytest.raises(ValueError, match="render mode"):
        Renderer(mode="ansi")
    with pytest.raises(ValueError):
        Renderer(figsize=(0, 3))
    w = _world()
    r = Renderer()
    with pytest.raises(IndexError):
        r.render(w, env=1)
    r.close()


def test_batched_world_renders_selected_env():
    w = World({"scenario": "random"}, n_envs=3)
    w.reset(seed=5)
    r = Renderer()
    try:
        frames = [r.render(w, env=i) for i in range(3)]
        for f in frames:
            _check_frame(f)
        assert (frames[0] != frames[2]).any()
    finally:
        r.close()


@pytest.mark.parametrize(
    "config",
    [
        {"n_obstacles": 0},
        {"scenario": "large_formation", "n_uavs": 10, "formation": "wedge", "n_obstacles": 3},
        {"scenario": "multi_obstacle", "n_obstacles": 4},
    ],
)
def test_other_configurations(config):
    w = _world(seed=1, **config)
    r = Renderer()
    try:
        for _ in range(3):
            w.step(_zero(w))
            _check_frame(r.render(w))
    finally:
        r.close()


def test_inactive_obstacles_and_scattered_formation():
    w = _world(n_obstacles=2)
    w.obstacles.active[0, 1] = False
    r = Renderer(top_view=False)
    try:
        # Zero actions: the paper's UAVs drift apart; the view grows instead of losing them.
        for _ in range(300):
            w.step(_zero(w))
        _check_frame(r.render(w))
    finally:
        r.close()


def test_view_box_stable_between_frames():
    w = _world()
    r = Renderer()
    try:
        widths = []
        for _ in range(12):
            w.step(_zero(w))
            r.render(w)
            ax = r.fig.axes[0]
            lo, hi = ax.get_xlim()
            widths.append(hi - lo)
            centre = np.asarray(w.uav_pos[0]).mean(axis=0)
            assert math.isclose((lo + hi) / 2, centre[1], abs_tol=1e-6)  # east centred
        assert np.ptp(widths) == 0.0
        assert widths[0] >= 300.0
    finally:
        r.close()


def test_ellipsoid_points_geometry():
    centre = np.array([100.0, 50.0, -80.0])  # NED
    axes = np.array([30.0, 10.0, 5.0])
    unit = np.eye(3)
    # Heading east: longitudinal -> east, lateral (right) -> south, vertical -> down.
    pts = ellipsoid_points(unit, centre, axes, math.pi / 2)  # (east, north, altitude)
    np.testing.assert_allclose(pts[0], [50.0 + 30.0, 100.0, 80.0], atol=1e-9)
    np.testing.assert_allclose(pts[1], [50.0, 100.0 - 10.0, 80.0], atol=1e-9)
    np.testing.assert_allclose(pts[2], [50.0, 100.0, 80.0 - 5.0], atol=1e-9)
    # Heading north: longitudinal -> north, lateral -> east.
    pts = ellipsoid_points(unit, centre, axes, 0.0)
    np.testing.assert_allclose(pts[0], [50.0, 130.0, 80.0], atol=1e-9)
    np.testing.assert_allclose(pts[1], [60.0, 100.0, 80.0], atol=1e-9)


def test_save_frame(tmp_path):
    w = _world()
    path = save_frame(w, tmp_path / "sub" / "frame.png")
    assert path.exists()
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = Renderer()
    for _ in range(5):
        w.step(_zero(w))
        r.render(w)
    save_frame(w, tmp_path / "with_trails.png", renderer=r)
    assert r.fig is not None  # a renderer passed in is not closed
    r.close()


def test_readme_frame_script(tmp_path):
    """``baselines/render_frame.py`` (the one frame-making script) flies the APF and saves."""
    out = tmp_path / "frame.png"
    res = run_in_repo("baselines/render_frame.py", "--time", "35", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "t = 35" in res.stdout
    import matplotlib.image

    frame = (matplotlib.image.imread(out)[..., :3] * 255).astype(np.uint8)
    _check_frame(frame)


def test_human_mode_headless_does_not_crash():
    res = run_python(
        """
        import warnings
        import numpy as np
        from uasep_env.rendering import Renderer
        from uasep_env.sim.world import World
        w = World({"scenario": "paper"}); w.reset(seed=0)
        r = Renderer(mode="human")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(3):
                assert r.render(w) is None
                w.step(np.zeros((1, 3, 3)))
        r.close()
        msgs = [str(c.message) for c in caught if "interactive" in str(c.message)]
        assert len(msgs) == 1, [str(c.message) for c in caught]
        print("ok")
        """
    )
    assert res.returncode == 0, res.stderr
    assert "ok" in res.stdout


def test_human_mode_in_process():
    w = _world()
    r = Renderer(mode="human")
    with pytest.warns(RuntimeWarning, match="interactive"):
        assert r.render(w) is None
    assert r.render(w) is None  # warns only once
    r.close()


def test_parallel_env_rgb_array():
    env = uasep_env.parallel_env(render_mode="rgb_array")
    env.reset(seed=0)
    frames = [env.render()]
    for _ in range(3):
        env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})
        frames.append(env.render())
    for f in frames:
        _check_frame(f)
    assert (frames[0] != frames[-1]).any()
    env.close()


def test_parallel_env_human_headless():
    env = uasep_env.parallel_env(render_mode="human")
    with pytest.warns(RuntimeWarning, match="interactive"):
        env.reset(seed=0)  # renders in human mode
    env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})
    assert env.render() is None
    env.close()


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pettingzoo.test's own imports
def test_pettingzoo_render_test():
    from pettingzoo.test import render_test
    from pettingzoo.utils.conversions import parallel_to_aec

    def env_fn(render_mode=None):
        return parallel_to_aec(uasep_env.parallel_env(render_mode=render_mode))

    with pytest.warns(RuntimeWarning, match="interactive"):
        render_test(env_fn)


def test_pettingzoo_render_test_parallel_equivalent():
    """render_test's checks, through the parallel API, for every declared render mode."""
    modes = uasep_env.parallel_env().metadata["render_modes"]
    assert set(modes) == {"human", "rgb_array"}
    for mode in modes:
        env = uasep_env.parallel_env(render_mode=mode)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # human mode, headless
            env.reset(seed=0)
            results = []
            for i in range(5):
                if i:
                    env.step({a: env.action_space(a).sample() for a in env.agents})
                results.append(env.render())
        for res in results:
            if mode == "rgb_array":
                _check_frame(res)
            else:
                assert res is None
        env.close()


def test_gymnasium_env_frames_for_video():
    """The frames a video recorder would get: constant shape, even sizes, uint8."""
    env = gymnasium.make("uasep/PaperEncounter-v3", render_mode="rgb_array", episode_duration=4.0)
    env.reset(seed=0)
    frames = [env.render()]
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        frames.append(env.render())
        done = term or trunc
    env.close()
    assert len(frames) == 21  # 4 s of 0.2 s steps, plus the reset frame
    shapes = {f.shape for f in frames}
    assert len(shapes) == 1
    h, w, _ = shapes.pop()
    assert h % 2 == 0 and w % 2 == 0
    for f in frames[:: len(frames) // 3]:
        _check_frame(f)


def test_gymnasium_record_video(tmp_path):
    pytest.importorskip("moviepy", reason="gymnasium's RecordVideo needs moviepy")
    from gymnasium.wrappers import RecordVideo

    env = gymnasium.make("uasep/PaperEncounter-v3", render_mode="rgb_array", episode_duration=4.0)
    videos = tmp_path / "videos"
    env = RecordVideo(env, video_folder=str(videos), episode_trigger=lambda ep: True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        done = term or trunc
    env.close()
    mp4s = list(videos.glob("*.mp4"))
    assert mp4s and mp4s[0].stat().st_size > 1000


def test_vector_env_render():
    env = gymnasium.make_vec(
        "uasep/PaperEncounter-v3",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        render_mode="rgb_array",
    )
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    frames = env.render()
    # Issue 23 item 7: Gymnasium's vector convention, one frame per sub-env (was env 0's).
    assert isinstance(frames, tuple) and len(frames) == 2
    for frame in frames:
        _check_frame(frame)
    assert not np.array_equal(frames[0], frames[1])
    # Sub-env i is the single env seeded seed + i: the same frame, pixel for pixel, below
    # the title (which names the env index).
    single = gymnasium.make("uasep/PaperEncounter-v3", render_mode="rgb_array")
    single.reset(seed=1)
    single.step(np.zeros(single.action_space.shape, dtype=np.float32))
    np.testing.assert_array_equal(frames[1][40:], single.render()[40:])
    single.close()
    env.close()


def test_vector_env_human_rendering_wrapper(monkeypatch):
    """gymnasium.wrappers.vector.HumanRendering tiles the sub-envs' frames in a window."""
    pytest.importorskip("pygame")
    pytest.importorskip("cv2")
    from gymnasium.wrappers.vector import HumanRendering

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")  # no display needed
    env = HumanRendering(
        gymnasium.make_vec(
            "uasep/PaperEncounter-v3",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            render_mode="rgb_array",
            episode_duration=2.0,
        )
    )
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert env.window is not None and env.screen_size is not None
    env.close()


# ---------------------------------------------------------------------------- what is drawn
def _pixel(r: Renderer, frame: np.ndarray, ax, east: float, north: float) -> np.ndarray:
    """The frame's RGB at the projection of ``(east, north)`` on 2D axes ``ax``."""
    x, y = ax.transData.transform((east, north))
    return frame[frame.shape[0] - 1 - int(np.rint(y)), int(np.rint(x))].astype(int)


def _near(colour: np.ndarray, hex_colour: str, tol: int = 40) -> bool:
    want = np.array([int(hex_colour[k : k + 2], 16) for k in (1, 3, 5)])
    return bool(np.abs(colour - want).max() <= tol)


def test_top_view_draws_each_uav_at_its_position_in_its_colour():
    from uasep_env.viz.style import UAV_COLOURS

    w = _world(seed=2)
    r = Renderer()
    try:
        frame = r.render(w)
        top = r._art["ax2"]
        for i, (north, east, _) in enumerate(w.uav_pos[0]):
            assert _near(_pixel(r, frame, top, east, north), UAV_COLOURS[i]), i
    finally:
        r.close()


def test_obstacle_region_is_drawn_at_the_projection_of_its_predicted_ellipsoid():
    w = _world(seed=0)
    while np.hypot(*(w.pred_center[0, 0, :2] - w.uav_pos[0].mean(axis=0)[:2])) > 100.0:
        w.step(_zero(w))  # until the paper's obstacle comes into view
        assert w.time[0] < 200.0
    r = Renderer()
    try:
        frame = r.render(w)
        top = r._art["ax2"]
        north, east, down = w.pred_center[0, 0]
        axes, heading = w.pred_axes[0, 0], float(w.pred_heading[0, 0])
        # The top view's outline is the ellipsoid's horizontal section, around its centre.
        outline = np.unique(r._art["obs"][0]["region2"].get_xy().round(9), axis=0)  # open ring
        np.testing.assert_allclose(outline.mean(axis=0), [east, north], atol=1e-6 * axes.max())
        # Its centre is tinted by the translucent red fill; a point two semi-axes out, not.
        inside = _pixel(r, frame, top, east, north)
        assert inside[0] > inside[1] + 8 and inside[0] > inside[2] + 8, inside
        lateral = 2.5 * axes[1] * np.array([-math.sin(heading), math.cos(heading)])
        outside = _pixel(r, frame, top, east + lateral[1], north + lateral[0])
        assert abs(outside[0] - outside[1]) < 8, outside
        # The 3D wireframe lies on the ellipsoid: body-frame points of norm 1.
        e, n, alt = r._art["obs"][0]["wire3"].get_data_3d()
        ok = np.isfinite(e)
        dn, de, dd = n[ok] - north, e[ok] - east, -alt[ok] - down
        lon = dn * math.cos(heading) + de * math.sin(heading)
        lat = -dn * math.sin(heading) + de * math.cos(heading)
        radius = np.sqrt((lon / axes[0]) ** 2 + (lat / axes[1]) ** 2 + (dd / axes[2]) ** 2)
        np.testing.assert_allclose(radius, 1.0, atol=1e-9)
    finally:
        r.close()


def test_trails_hold_the_last_trail_length_seconds_ending_at_the_uav():
    w = _world()
    dt = w.config.dt * w.config.decision_interval
    r = Renderer(trail_length=5 * dt)
    try:
        seen = []
        for _ in range(12):
            r.render(w)
            seen.append(np.array(w.uav_pos[0]))
            w.step(_zero(w))
        for i, u in enumerate(r._art["uav"]):
            east, north = u["trail2"].get_data()
            assert len(east) == 6  # now and the five frames of the last 5 dt
            want = np.stack(seen[-6:])[:, i]
            np.testing.assert_array_equal(east, want[:, 1])
            np.testing.assert_array_equal(north, want[:, 0])
    finally:
        r.close()
