"""Live frames: matplotlib rendering of one environment of a :class:`~uasep_env.sim.world.World`.

:class:`Renderer` draws a 3D view of the formation and the obstacles next to a top view
(north up), following the formation:

* the UAVs (one colour each, labelled ``uav_i``) with trails of their recent true positions,
  their planned tracks (dotted), their current planned positions (hollow circles) and the
  planned trajectory of the formation centre (the way-point polyline, dashed grey);
* the obstacles (red crosses) with trails, and their predicted reachable ellipsoids
  (translucent meshes; the top view shows their horizontal outline);
* a title with the simulated time and the smallest UAV-UAV and UAV-obstacle distances over
  the last step (red when separation is lost).

Plots use east as the horizontal axis and north as the vertical one (maps look like maps)
and altitude ``-z`` (the simulator's frame is NED). The view is a box of fixed size centred
on the formation centre: it moves smoothly with the formation and only grows (in 50 m
steps) when a UAV strays outside it, so frames do not jitter.

matplotlib is imported lazily, when a renderer draws its first frame: importing this module
does not import it. ``"rgb_array"`` frames are drawn on a non-interactive Agg canvas (no
pyplot, no window; safe in threads and subprocesses). ``"human"`` opens a pyplot window;
with a non-interactive backend (headless machines) it warns once and shows nothing.

:func:`save_frame` is the one way to write a frame to a PNG file; the README's frame (the
paper scenario under the APF) is written with it by ``python baselines/render_frame.py``.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.sim.formation import rotation_from_velocity
from uasep_env.viz.frame_artists import build_artists
from uasep_env.viz.shapes import SPHERE_LINES, SPHERE_QUADS, ellipsoid_points, enu, unit_ring
from uasep_env.viz.style import OBSTACLE_COLOUR

if TYPE_CHECKING:
    from uasep_env.sim.world import World

__all__ = ["RENDER_MODES", "Renderer", "save_frame"]

#: Modes accepted by :class:`Renderer`.
RENDER_MODES = ("rgb_array", "human")

_NON_INTERACTIVE = frozenset({"agg", "cairo", "pdf", "pgf", "ps", "svg", "template"})
_GROW_STEP_M = 50.0  # the view grows in steps of this size
_EPS_T = 1e-9
_RING = unit_ring(65)  # the ellipsoid's horizontal outline (its equator), body frame


def _is_interactive_backend(backend: str) -> bool:
    return backend.lower() not in _NON_INTERACTIVE


@dataclass
class _History:
    """Recent true positions of one environment (for the trails)."""

    key: tuple[int, int]
    times: deque = field(default_factory=deque)
    uavs: deque = field(default_factory=deque)
    obstacles: deque = field(default_factory=deque)
    half_width: float = 0.0
    half_height: float = 0.0


class Renderer:
    """Draws one environment of a :class:`~uasep_env.sim.world.World` with matplotlib.

    Args:
        mode: ``"rgb_array"`` (:meth:`render` returns an ``(H, W, 3)`` uint8 array) or
            ``"human"`` (a pyplot window; :meth:`render` returns ``None``).
        trail_length: Seconds of history drawn behind the UAVs and obstacles. The history
            holds the positions seen by :meth:`render`, so trails are as fine as the frames.
        figsize: Figure size (inches); with ``dpi`` it fixes the frame size. The default
            gives 1120 x 640 pixels (multiples of 16, as video encoders like).
        dpi: Dots per inch.
        min_half_width: Smallest horizontal half-width of the view (m); the view is at
            least three times the formation's extent.
        top_view: Draw the top view next to the 3D view.
        elev: Elevation of the 3D camera (degrees).
        azim: Azimuth of the 3D camera (degrees).

    Raises:
        ValueError: If ``mode`` is not one of :data:`RENDER_MODES` or a size is not positive.
    """

    def __init__(
        self,
        mode: str = "rgb_array",
        trail_length: float = 40.0,
        figsize: tuple[float, float] = (11.2, 6.4),
        dpi: int = 100,
        min_half_width: float = 150.0,
        top_view: bool = True,
        elev: float = 22.0,
        azim: float = -66.0,
    ) -> None:
        if mode not in RENDER_MODES:
            raise ValueError(f"render mode must be one of {RENDER_MODES}, got {mode!r}")
        if not trail_length >= 0 or not min_half_width > 0 or not dpi > 0:
            raise ValueError("trail_length must be >= 0, min_half_width and dpi > 0")
        if len(figsize) != 2 or not all(s > 0 for s in figsize):
            raise ValueError(f"figsize must be two positive numbers, got {figsize!r}")
        self.mode = mode
        self.trail_length = float(trail_length)
        self.figsize = (float(figsize[0]), float(figsize[1]))
        self.dpi = int(dpi)
        self.min_half_width = float(min_half_width)
        self.top_view = bool(top_view)
        self.elev = float(elev)
        self.azim = float(azim)
        self.fig: Any = None
        self._canvas: Any = None
        self._art: dict[str, Any] = {}
        self._shape: tuple[int, int] = (-1, -1)
        self._history: _History | None = None
        self._plan_cache: tuple[bytes, np.ndarray, list[np.ndarray]] | None = None
        self._shown = False
        self._warned = False
        self._interactive = False

    # ------------------------------------------------------------------ figure
    def _new_figure(self) -> None:
        if self.mode == "human":
            import matplotlib
            import matplotlib.pyplot as plt

            self._interactive = _is_interactive_backend(matplotlib.get_backend())
            self.fig = plt.figure(figsize=self.figsize, dpi=self.dpi)
            manager = getattr(self.fig.canvas, "manager", None)
            if manager is not None:
                manager.set_window_title("uasep_env")
            self._shown = False
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=self.figsize, dpi=self.dpi)
            FigureCanvasAgg(self.fig)
        self._canvas = self.fig.canvas
        self._art = {}
        self._shape = (-1, -1)

    def _build(self, n_uavs: int, n_obstacles: int, horizon: float) -> None:
        """Create every artist once; frames only update their data."""
        self._art = build_artists(
            self.fig, n_uavs, n_obstacles, horizon, top_view=self.top_view, elev=self.elev,
            azim=self.azim,
        )  # fmt: skip
        self._shape = (n_uavs, n_obstacles)

    # ------------------------------------------------------------------ history
    def _update_history(self, world: World, env: int) -> _History:
        key = (id(world), env)
        t = float(world.time[env])
        h = self._history
        if h is None or h.key != key or (h.times and t < h.times[-1] - _EPS_T):
            h = self._history = _History(key)
        uav = np.array(world.uav_pos[env], dtype=float)
        obs = np.array(world.obstacles.pos[env], dtype=float)
        obs[~world.obstacles.active[env]] = np.nan
        if h.times and abs(t - h.times[-1]) <= _EPS_T:  # the same frame again: replace
            h.uavs[-1], h.obstacles[-1] = uav, obs
        else:
            h.times.append(t)
            h.uavs.append(uav)
            h.obstacles.append(obs)
        while h.times and h.times[0] < t - self.trail_length - _EPS_T:
            h.times.popleft()
            h.uavs.popleft()
            h.obstacles.popleft()
        return h

    def _planned_tracks(self, world: World, env: int) -> tuple[np.ndarray, list[np.ndarray]]:
        """The centre's way-point polyline and each UAV's planned track, NaN-separated."""
        wp = np.asarray(world.plan.waypoints[env], dtype=float)
        slots = np.asarray(world.slots[env], dtype=float)
        key = wp.tobytes() + slots.tobytes()
        if self._plan_cache is not None and self._plan_cache[0] == key:
            return self._plan_cache[1], self._plan_cache[2]
        seg = np.diff(wp, axis=0)
        seg_len = np.linalg.norm(seg, axis=-1)
        keep = seg_len > 1e-9
        pieces: list[list[np.ndarray]] = [[] for _ in range(len(slots))]
        nan = np.full((1, 3), np.nan)
        for k in np.flatnonzero(keep):
            rot = rotation_from_velocity(seg[k] / seg_len[k])
            offsets = slots @ rot.T  # (N, 3) NED
            for i in range(len(slots)):
                pieces[i].append(np.stack([wp[k] + offsets[i], wp[k + 1] + offsets[i]]))
                pieces[i].append(nan)
        tracks = [np.concatenate(p[:-1]) if p else np.zeros((0, 3)) for p in pieces]
        centre = wp[np.concatenate([[True], keep])]
        self._plan_cache = (key, centre, tracks)
        return centre, tracks

    def _view_box(self, world: World, env: int, hist: _History) -> tuple[np.ndarray, float, float]:
        """Centre ``(east, north, alt)`` and horizontal / vertical half-widths of the view."""
        pos = np.asarray(world.uav_pos[env], dtype=float)
        center_ned = pos.mean(axis=0)
        centre = np.array([center_ned[1], center_ned[0], -center_ned[2]])
        if hist.half_width <= 0.0:
            extent = float(np.linalg.norm(world.slots[env], axis=-1).max(initial=0.0))
            hist.half_width = max(self.min_half_width, 3.0 * extent)
            hist.half_height = max(30.0, hist.half_width / 4.0)
        spread = float(np.abs(pos[:, :2] - center_ned[:2]).max(initial=0.0))
        if spread > 0.9 * hist.half_width:
            hist.half_width = _GROW_STEP_M * math.ceil(spread / 0.9 / _GROW_STEP_M)
            hist.half_height = max(hist.half_height, hist.half_width / 4.0)
        vspread = float(np.abs(pos[:, 2] - center_ned[2]).max(initial=0.0))
        if vspread > 0.9 * hist.half_height:
            hist.half_height = _GROW_STEP_M * math.ceil(vspread / 0.9 / _GROW_STEP_M)
        return centre, hist.half_width, hist.half_height

    # ------------------------------------------------------------------ frames
    def render(self, world: World, env: int = 0) -> np.ndarray | None:
        """Draw environment ``env`` of ``world``.

        Args:
            world: The world (after :meth:`~uasep_env.sim.world.World.reset`).
            env: Index of the environment to draw.

        Returns:
            ``(H, W, 3)`` uint8 RGB in ``"rgb_array"`` mode, ``None`` in ``"human"`` mode.

        Raises:
            IndexError: If ``env`` is out of range.
        """
        if not 0 <= env < world.n_envs:
            raise IndexError(f"env {env} out of range for a world of {world.n_envs}")
        if self.fig is None or (self.mode == "human" and not self._figure_alive()):
            self._new_figure()
        cfg = world.config
        if self._shape != (world.n_uavs, world.n_obstacles):
            self._build(world.n_uavs, world.n_obstacles, cfg.prediction.horizon)
        hist = self._update_history(world, env)
        self._draw_frame(world, env, hist)
        if self.mode == "human":
            self._show()
            return None
        self._canvas.draw()
        rgba = np.asarray(self._canvas.buffer_rgba())
        return np.ascontiguousarray(rgba[..., :3])

    def _draw_frame(self, world: World, env: int, hist: _History) -> None:
        art = self._art
        ax3, ax2 = art["ax3"], art["ax2"]
        centre, hw, hh = self._view_box(world, env, hist)
        x0, x1 = centre[0] - hw, centre[0] + hw
        y0, y1 = centre[1] - hw, centre[1] + hw
        z0, z1 = centre[2] - hh, centre[2] + hh
        ax3.set_xlim(x0, x1)
        ax3.set_ylim(y0, y1)
        ax3.set_zlim(z0, z1)
        ax3.set_box_aspect((1.0, 1.0, 0.5), zoom=1.15)
        if ax2 is not None:
            ax2.set_xlim(x0, x1)
            ax2.set_ylim(y0, y1)

        # Plan.
        plan_centre, tracks = self._planned_tracks(world, env)
        art["plan3"].set_data_3d(*enu(plan_centre))
        if ax2 is not None:
            art["plan2"].set_data(plan_centre[:, 1], plan_centre[:, 0])
        planned, _ = world.planned()
        planned = planned[env]

        # UAVs.
        uav_hist = np.stack(hist.uavs)  # (T, N, 3)
        pos = np.asarray(world.uav_pos[env], dtype=float)
        for i, u in enumerate(art["uav"]):
            e, n, a = enu(uav_hist[:, i])
            u["trail3"].set_data_3d(e, n, a)
            u["track3"].set_data_3d(*enu(tracks[i]))
            pe, pn, pa = enu(pos[i])
            u["dot3"].set_data_3d(*_pt(pe, pn, pa))
            u["drop3"].set_data_3d(*_seg(pe, pn, pa, z0))
            qe, qn, qa = enu(planned[i])
            u["planned3"].set_data_3d(*_pt(qe, qn, qa))
            if ax2 is not None:
                u["trail2"].set_data(e, n)
                u["track2"].set_data(tracks[i][:, 1], tracks[i][:, 0])
                u["planned2"].set_data([qe], [qn])
                u["dot2"].set_data([pe], [pn])
                if u["label2"] is not None:
                    u["label2"].xy = (pe, pn)

        # Obstacles and their reachable ellipsoids.
        if art["obs"]:
            obs_hist = np.stack(hist.obstacles)  # (T, M, 3)
            ob = world.obstacles
            for j, o in enumerate(art["obs"]):
                active = bool(ob.active[env, j])
                for artist in o.values():
                    artist.set_visible(active)
                if not active:
                    continue
                c = np.asarray(world.pred_center[env, j], dtype=float)
                axes = np.asarray(world.pred_axes[env, j], dtype=float)
                head = float(world.pred_heading[env, j])
                wire = ellipsoid_points(SPHERE_LINES, c, axes, head)
                o["wire3"].set_data_3d(wire[:, 0], wire[:, 1], wire[:, 2])
                o["surf3"].set_verts(ellipsoid_points(SPHERE_QUADS, c, axes, head))
                e, n, a = enu(obs_hist[:, j])
                o["trail3"].set_data_3d(e, n, a)
                pe, pn, pa = enu(np.asarray(ob.pos[env, j], dtype=float))
                o["dot3"].set_data_3d(*_pt(pe, pn, pa))
                o["drop3"].set_data_3d(*_seg(pe, pn, pa, z0))
                if ax2 is not None:
                    outline = ellipsoid_points(_RING, c, axes, head)
                    o["region2"].set_xy(outline[:, :2])
                    o["trail2"].set_data(e, n)
                    o["dot2"].set_data([pe], [pn])

        # Title.
        t = float(world.time[env])
        d_uav = float(np.min(world.min_uav_dist[env], initial=np.inf))
        d_obstacle = float(np.min(world.min_obstacle_dist[env], initial=np.inf))
        family = world.families[env] if env < len(world.families) else ""
        scen = f"{family} scenario  ·  " if family else ""
        art["title"].set_text(f"{scen}env {env}  ·  t = {t:6.1f} s")
        sep_uav = world.config.uav.separation_distance
        sep_obs = world.config.uav.obstacle_separation
        lost = d_uav < sep_uav or d_obstacle < sep_obs
        art["status"].set_text(
            f"min UAV–UAV {_fmt_dist(d_uav)}    min UAV–obstacle {_fmt_dist(d_obstacle)}"
            + ("    LOSS OF SEPARATION" if lost else "")
        )
        art["status"].set_color(OBSTACLE_COLOUR if lost else "0.15")

    # ------------------------------------------------------------------ human mode
    def _figure_alive(self) -> bool:
        import matplotlib.pyplot as plt

        return self.fig is not None and plt.fignum_exists(self.fig.number)

    def _show(self) -> None:
        if not self._interactive:
            if not self._warned:
                import matplotlib

                warnings.warn(
                    "render_mode='human' needs an interactive matplotlib backend; the backend "
                    f"is {matplotlib.get_backend()!r} (no display?), so nothing is shown. "
                    "Use render_mode='rgb_array' to get frames.",
                    RuntimeWarning,
                    stacklevel=3,
                )
                self._warned = True
            self._canvas.draw()
            return
        import matplotlib.pyplot as plt

        if not self._shown:
            plt.show(block=False)
            self._shown = True
        self._canvas.draw_idle()
        plt.pause(0.001)

    # ------------------------------------------------------------------ output
    def savefig(self, path: str | Path) -> Path:
        """Write the last drawn frame to ``path`` (format from the suffix, e.g. PNG).

        Raises:
            RuntimeError: If nothing was rendered yet.
        """
        if self.fig is None or not self._art:
            raise RuntimeError("nothing rendered yet: call render(world) first")
        from uasep_env.runtime.atomic import atomic_output  # all or nothing, like every output

        path = Path(path)
        with atomic_output(path) as fh:
            fig_format = path.suffix[1:] or "png"
            self.fig.savefig(fh, format=fig_format, dpi=self.dpi, facecolor="white")
        return path

    def close(self) -> None:
        """Release the figure (and close the window in ``"human"`` mode). Idempotent."""
        if self.fig is not None:
            if self.mode == "human":
                import matplotlib.pyplot as plt

                plt.close(self.fig)
            else:
                self.fig.clear()
        self.fig = None
        self._canvas = None
        self._art = {}
        self._shape = (-1, -1)
        self._history = None
        self._plan_cache = None


def _pt(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.array([x]), np.array([y]), np.array([z])


def _seg(x: float, y: float, z_top: float, z_bottom: float) -> tuple[np.ndarray, ...]:
    return np.array([x, x]), np.array([y, y]), np.array([z_top, z_bottom])


def _fmt_dist(d: float) -> str:
    return f"{d:.1f} m" if math.isfinite(d) else "–"


def save_frame(
    world: World, path: str | Path, env: int = 0, renderer: Renderer | None = None
) -> Path:
    """Render environment ``env`` of ``world`` and write it as an image (PNG by suffix).

    Args:
        world: The world to draw.
        path: Output file; parent folders are created.
        env: Environment index.
        renderer: An ``"rgb_array"`` renderer to draw with (keeps its trails; not closed).
            ``None`` draws with a fresh one (no trails), closed afterwards.

    Returns:
        The path written.
    """
    own = renderer is None
    r = Renderer(mode="rgb_array") if renderer is None else renderer
    try:
        r.render(world, env=env)
        return r.savefig(path)
    finally:
        if own:
            r.close()
