"""The batched world: the one transition function of the project.

:class:`World` holds ``n_envs`` independent worlds as arrays shaped ``(n_envs, n_uavs, ...)``
and ``(n_envs, n_obstacles, ...)`` and moves them all with :meth:`World.step`. Every
environment class in :mod:`uasep_env.envs` (PettingZoo, Gymnasium, vector, SB3) is a view of
a ``World``; none moves anything itself.

One environment step (``decision_interval`` physics steps of ``dt``) does, per physics step:

1. UAVs: the commanded accelerations, bounded per axis, plus process noise, through the
   double integrator with the speed limit (:mod:`uasep_env.sim.dynamics`, eqs. 1-4);
2. obstacles: the 3D Dubins model with random pilot commands (:mod:`uasep_env.sim.obstacles`),
   or recorded tracks replayed (``obstacle.model="replay"``, :mod:`uasep_env.sim.replay`);
3. sensing and estimation: noisy measurements of every UAV and obstacle, Kalman filtered
   (:mod:`uasep_env.sim.estimation`);
4. safety: the minimum UAV-UAV and UAV-obstacle distances over the physics steps, so that a
   collision inside a long decision interval is not missed;

and then predicts each obstacle's reachable ellipsoid over the horizon from its estimate
(:mod:`uasep_env.reachable`, eqs. 8-18; or, with ``prediction.fit="calibrated"``, the
conformal region of its aircraft class, :mod:`uasep_env.reachable.calibrated`). Steps 1-4
are one function, :func:`uasep_env.sim.physics_step.physics_step` (three compiled kernels when
numba is in use).

The planned state now (centre, direction, each UAV's planned position and velocity) is
computed on first read, once per step (:class:`uasep_env.sim.planned_now.PlannedNow`).

A reset (of all environments, or of those whose episodes ended) draws each environment's
scenario from its own generator and builds the geometry once over the reset rows
(:mod:`uasep_env.scenarios.batched`), so that a few episode ends in a step of a large batch
cost a few rows.

Randomness: each environment owns a :class:`numpy.random.Generator`, seeded at reset
(``seed + i`` for environment ``i`` when one seed is given for the batch, the Gymnasium
vector convention). Noise is drawn from it in blocks of ``noise_block`` physics steps, per
environment (:class:`uasep_env.sim.noise.NoiseStreams`), so environment ``i`` of a batch
follows exactly the same episode as a single environment seeded with ``seed + i``, bit for
bit.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from uasep_env import reachable
from uasep_env._deprecation import RENAMED_WORLD_ATTRIBUTES, RenamedAttributes
from uasep_env.config import EnvConfig, make_config
from uasep_env.config.checks import check_positive_int, check_seed, is_int
from uasep_env.reachable import calibrated
from uasep_env.scenarios import N_WAYPOINTS, place_obstacles
from uasep_env.scenarios.batched import sample_batch
from uasep_env.scenarios.real_traffic import check_replay_tracks, replay_samples
from uasep_env.scenarios.spec import ScenarioBatch
from uasep_env.sim.dynamics import measure
from uasep_env.sim.estimation import KalmanModel
from uasep_env.sim.formation import PlannedTrajectory, segment_offsets
from uasep_env.sim.geometry import nearest_separations, obstacle_distances, uav_distances
from uasep_env.sim.noise import NoiseStreams
from uasep_env.sim.obstacles import N_UNIFORMS, ObstacleState, obstacle_velocity
from uasep_env.sim.physics_step import PhysicsArrays, PhysicsParams, physics_step
from uasep_env.sim.planned_now import PlannedNow
from uasep_env.sim.replay import ReplayTracks
from uasep_env.sim.snapshot import (
    MAX_MAGNITUDE,
    check_arrays,
    check_range,
    copy_arrays,
    generator_states,
    generators_from,
    ndarray_attributes,
)

__all__ = ["World"]


#: The state arrays a region distance reads (:meth:`World.frozen_inputs` names), in the
#: order :func:`uasep_env.reachable.region_distances` takes them.
_REGION_INPUTS = ("uav_pos", "pred_center", "pred_axes", "pred_heading", "pred_cos",
                  "pred_sin", "obstacles.active")  # fmt: skip
_region_views = operator.itemgetter(*_REGION_INPUTS)


class World(PlannedNow, RenamedAttributes):
    """``n_envs`` batched worlds of UAVs and obstacles.

    Args:
        config: The validated configuration (or a dict for :func:`make_config`).
        n_envs: Number of independent worlds.
        noise_block: Physics steps of noise drawn at once per environment.

    Attributes:
        config: The configuration.
        n_envs: Batch size ``E``.
        n_uavs: ``N``.
        n_obstacles: ``M``.
        time: ``(E,)`` simulated time since reset (s).
        steps: ``(E,)`` environment steps since reset.
        uav_pos: ``(E, N, 3)`` true UAV positions (m, NED).
        uav_vel: ``(E, N, 3)`` true UAV velocities (m/s).
        uav_acc: ``(E, N, 3)`` accelerations applied over the last physics step (m/s^2).
        accel_cmd: ``(E, N, 3)`` last commanded accelerations (m/s^2).
        prev_accel_cmd: ``(E, N, 3)`` the command before that (m/s^2).
        est_pos: ``(E, N, 3)`` estimated UAV positions (m).
        est_vel: ``(E, N, 3)`` estimated UAV velocities (m/s).
        obstacles: The obstacles' true state (:class:`ObstacleState`).
        obstacle_est_pos: ``(E, M, 3)`` estimated obstacle positions (m).
        obstacle_est_vel: ``(E, M, 3)`` estimated obstacle ground velocities (m/s).
        pred_center: ``(E, M, 3)`` centres of the predicted reachable ellipsoids (m).
        pred_axes: ``(E, M, 3)`` their semi-axes (longitudinal, lateral, vertical) (m).
        pred_heading: ``(E, M)`` their headings (rad).
        pred_cos: ``(E, M)`` the headings' cosines (numpy's ``cos``).
        pred_sin: ``(E, M)`` the headings' sines.
        slots: ``(E, N, 3)`` formation pattern (m, formation frame).
        plan: The planned trajectories (:class:`PlannedTrajectory`).
        plan_center: ``(E, 3)`` planned formation centre now (m); read-only, new arrays
            after every step and reset (computed on first read), like the three below.
        plan_dir: ``(E, 3)`` unit direction of the planned path now.
        plan_pos: ``(E, N, 3)`` each UAV's planned position now (m).
        plan_vel: ``(E, N, 3)`` each UAV's planned velocity now (m/s).
        min_uav_dist: ``(E, N)`` smallest distance to another UAV over the last env step (m).
        min_obstacle_dist: ``(E, N)`` smallest distance to an active obstacle over it (m).
        families: Scenario family of each environment's episode.
    """

    def __init__(
        self, config: EnvConfig | dict | None = None, n_envs: int = 1, noise_block: int = 64
    ) -> None:
        cfg = config if isinstance(config, EnvConfig) else make_config(config)
        self.config = cfg
        self.n_envs = e = check_positive_int("n_envs", n_envs)
        self.n_uavs = n = cfg.n_uavs
        self.n_obstacles = m = cfg.n_obstacles
        self.noise_block = int(noise_block)
        nz = cfg.noise
        self._uav_kf = KalmanModel(cfg.dt, nz.accel_std, nz.position_std, nz.velocity_std)
        # Each standard normal's standard deviation, by column: accelerations, then each
        # UAV's and each obstacle's measured position and velocity.
        normal_std = np.concatenate(
            [
                np.full(n * 3, nz.accel_std),
                np.tile(np.repeat([nz.position_std, nz.velocity_std], 3), n),
                np.tile(np.repeat([nz.obstacle_position_std, nz.obstacle_velocity_std], 3), m),
            ]
        )
        self._noise = NoiseStreams(e, self.noise_block, normal_std, m * N_UNIFORMS)

        self.time = np.zeros(e)
        self.steps = np.zeros(e, dtype=np.int64)
        self._kf_count = np.zeros(e, dtype=np.int64)
        self.uav_pos = np.zeros((e, n, 3))
        self.uav_vel = np.zeros((e, n, 3))
        self.uav_acc = np.zeros((e, n, 3))
        self.accel_cmd = np.zeros((e, n, 3))
        self.prev_accel_cmd = np.zeros((e, n, 3))
        self.est_pos = np.zeros((e, n, 3))
        self.est_vel = np.zeros((e, n, 3))
        self.obstacles = ObstacleState(e, m)
        # Recorded tracks, one sample per physics step of an episode (replay model only).
        self.replay: ReplayTracks | None = None
        if cfg.obstacle.model == "replay":
            check_replay_tracks(cfg)  # enough distinct tracks: say so now, not at reset
            self.replay = ReplayTracks(e, m, replay_samples(cfg), cfg.dt)
        self.obstacle_est_pos = np.zeros((e, m, 3))
        self.obstacle_est_vel = np.zeros((e, m, 3))
        self.pred_offset = np.zeros((e, m))
        self._pred_inflation = np.zeros((e, m))
        if cfg.prediction.fit == "calibrated":
            calibrated.load_table()  # a missing or corrupt table: say so now, not at reset
        self.pred_center = np.zeros((e, m, 3))
        self.pred_axes = np.ones((e, m, 3))
        self.pred_heading = np.zeros((e, m))
        self.pred_cos, self.pred_sin = np.ones((e, m)), np.zeros((e, m))
        self.slots = np.zeros((e, n, 3))
        self.plan = PlannedTrajectory(np.tile(np.eye(N_WAYPOINTS, 3)[None], (e, 1, 1)), 1.0)
        # Each UAV's planned offset from the centre along each segment (fixed per episode).
        self._plan_offsets = segment_offsets(self.plan.direction, self.slots)
        self._refresh_plan()
        self.min_uav_dist = np.full((e, n), np.inf)
        self.min_obstacle_dist = np.full((e, n), np.inf)
        self.families: list[str] = [""] * e
        # Obstacle tracks: zero known input; process noise covers a full-rate turn's
        # lateral acceleration v * w_max (at least 0.1 m/s^2).
        self._obstacle_kf = KalmanModel(
            cfg.dt,
            max(cfg.obstacle.speed * cfg.obstacle.max_turn_rate, 0.1),
            nz.obstacle_position_std,
            nz.obstacle_velocity_std,
        )
        self._physics = PhysicsParams(
            cfg.dt, cfg.uav.max_speed, cfg.uav.max_accel, cfg.prediction.kalman,
            self._uav_kf.gains, self._obstacle_kf.gains,
        )  # fmt: skip
        self._has_reset = False
        self._frozen: dict[str, np.ndarray] | None = None

    #: The state arrays the compiled kernels read, by attribute path: allocated once and
    #: written in place, so that a read-only view made once shows the current state.
    _KERNEL_INPUTS = (
        "time", "uav_pos", "accel_cmd", "prev_accel_cmd", "est_pos", "est_vel", "slots",
        "obstacle_est_pos", "obstacle_est_vel", "pred_center", "pred_axes", "pred_heading",
        "pred_cos", "pred_sin", "min_uav_dist", "min_obstacle_dist", "_plan_offsets",
        "obstacles.active", "obstacles.aircraft_class",
    )  # fmt: skip

    def __getstate__(self) -> dict:
        # A copy (copy.deepcopy, pickle) would copy the views as arrays of their own, not as
        # views of its own state: it makes its own on first use.
        return {**self.__dict__, "_frozen": None}

    def frozen_inputs(self) -> dict[str, np.ndarray]:
        """Read-only views of the state arrays the kernels read (:data:`_KERNEL_INPUTS`).

        Made on first use: a kernel's inputs are read-only (one compiled signature,
        ``uasep_env._kernels.common.frozen``), and making a view of ~40 arrays every step
        was a tenth of a one-environment step.
        """
        if self._frozen is None:
            views = {}
            for name in self._KERNEL_INPUTS:
                view = operator.attrgetter(name)(self).view()  # C-contiguous, as allocated
                view.flags.writeable = False
                views[name] = view
            self._frozen = views
        return self._frozen

    # ------------------------------------------------------------------ state
    #: Arrays of the state that may hold ``inf`` (a minimum distance with nothing to meet).
    _MAY_BE_INF = ("min_uav_dist", "min_obstacle_dist")
    #: Entries of :meth:`state_dict` that are not arrays of the world's own.
    _STATE_META = ("noise.generators", "families", "has_reset")

    def _state_arrays(self) -> dict[str, np.ndarray]:
        """The live arrays of the world's state, by name.

        Every array attribute of the world, its obstacles, plans and replayed tracks, and the
        buffered noise.
        """
        arrays = ndarray_attributes(self, "")
        arrays |= ndarray_attributes(self.obstacles, "obstacles.")
        arrays |= ndarray_attributes(self.plan, "plan.")
        if self.replay is not None:
            arrays |= ndarray_attributes(self.replay, "replay.")
        arrays |= {f"noise.{k}": v for k, v in self._noise.state_arrays().items()}
        return arrays

    def state_dict(self) -> dict[str, np.ndarray]:
        """The whole state of the batch, as arrays (copies): what :meth:`load_state_dict` needs.

        Every state array (positions, estimates, obstacles, plans, counters, the noise
        buffered), each environment's generator state (``noise.generators``, ``(E, 6)``
        uint64), the scenario families and whether the world was reset. Plain arrays, so
        ``np.savez`` writes it and ``np.load(allow_pickle=False)`` reads it back: a world that
        loads it steps on exactly as this one would (the same numbers, bit for bit).
        """
        state = {k: v.copy() for k, v in self._state_arrays().items()}
        state["noise.generators"] = generator_states(self._noise.rngs)
        state["families"] = np.array(self.families, dtype=str)
        state["has_reset"] = np.array(self._has_reset)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a :meth:`state_dict` of a world of the same config and size.

        Everything is checked before anything is written (a refused state leaves the world
        as it was): the same arrays, of the same shapes and dtypes, no NaN, finite (but the
        minimum distances) and within :data:`~uasep_env.sim.snapshot.MAX_MAGNITUDE`; the
        step counters within the episode, the noise positions within their blocks.

        Raises:
            ValueError: One line naming the array.
        """
        live = self._state_arrays()
        check_arrays(state, live, self._MAY_BE_INF, self._STATE_META)
        check_range("steps", state["steps"], 0, MAX_MAGNITUDE)
        check_range("_kf_count", state["_kf_count"], 0, MAX_MAGNITUDE)
        check_range("noise.buf_pos", state["noise.buf_pos"], 0, self.noise_block)
        check_range("obstacles.aircraft_class", state["obstacles.aircraft_class"], 0, 255)
        missing = [k for k in self._STATE_META if k not in state]
        if missing:
            raise ValueError(f"{missing[0]}: missing")
        rngs = generators_from("noise.generators", state["noise.generators"], self.n_envs)
        families, has_reset = state["families"], state["has_reset"]
        names = families.dtype.kind == "U" and families.itemsize <= 256  # 64 characters
        if not names or families.shape != (self.n_envs,):
            raise ValueError(f"families: {families.dtype} of shape {families.shape}, expected "
                             f"{self.n_envs} names")  # fmt: skip
        if has_reset.shape != () or has_reset.dtype != bool:
            raise ValueError(f"has_reset: {has_reset.dtype} of shape {has_reset.shape}, not a bool")
        copy_arrays(state, live)
        self._noise.set_generators(rngs)
        self.families = families.tolist()
        self._has_reset = bool(has_reset)
        self._refresh_plan()  # the plan now: recomputed from the restored arrays on first read

    # ------------------------------------------------------------------ reset
    def reset(
        self,
        seed: int | Sequence[int | None] | None = None,
        mask: np.ndarray | None = None,
    ) -> None:
        """Start new episodes in the environments selected by ``mask`` (all by default).

        Args:
            seed: ``None`` (continue each environment's generator; fresh entropy on the
                first reset), an int (environment ``i`` gets ``seed + i``) or one seed per
                environment (``None`` entries continue).
            mask: ``(n_envs,)`` bool; which environments to reset.

        Raises:
            TypeError: If ``seed`` is not None, an int or a sequence of them (named).
            ValueError: If ``mask`` has the wrong shape or type, a seed is negative, or
                the number of seeds is not ``n_envs``.
        """
        e = self.n_envs
        if mask is None:
            mask = np.ones(e, dtype=bool)
        mask = np.asarray(mask)
        if mask.shape != (e,) or mask.dtype != bool:
            raise ValueError(f"mask must be a bool array of shape ({e},), got {mask!r}")
        check_seed(seed, e)
        idx = np.flatnonzero(mask)
        if len(idx) == 0:
            return
        if seed is not None:  # else each generator continues (the autoresets' case)
            seeds = (
                [int(seed) + i for i in range(e)]  # type: ignore[arg-type]
                if is_int(seed)
                else list(seed)  # type: ignore[arg-type]
            )
            for i in idx:
                s = seeds[i]
                if s is not None:
                    self._noise.reseed(i, s)
        # Each environment's scenario from its own generator, the geometry batched over
        # them: the episodes of sample_scenario, bit for bit (uasep_env.scenarios.batched).
        batch = sample_batch([self._noise.rngs[i] for i in idx], self.config)
        for i, family in zip(idx.tolist(), batch.families, strict=True):
            self.families[i] = family
        self._apply_specs(mask, idx, batch)
        self._has_reset = True

    def _apply_specs(self, mask: np.ndarray, idx: np.ndarray, batch: ScenarioBatch) -> None:
        cfg = self.config
        self.time[idx] = 0.0
        self.steps[idx] = 0
        self._kf_count[idx] = 0
        self.slots[idx] = batch.slots
        if batch.plan is not None and batch.plan_offsets is not None:
            # The scenario made the plans and offsets already (the same functions of the same
            # arrays): not again.
            self.plan.copy_rows(idx, batch.plan)
            self._plan_offsets[idx] = batch.plan_offsets
        else:
            self.plan.set_rows(mask, batch.waypoints, batch.cruise_speed)
            self._plan_offsets[idx] = segment_offsets(self.plan.direction[idx], self.slots[idx])
        self.uav_pos[idx] = batch.uav_pos
        self.uav_vel[idx] = batch.uav_vel
        self.uav_acc[idx] = 0.0
        self.accel_cmd[idx] = 0.0
        self.prev_accel_cmd[idx] = 0.0
        ob = self.obstacles
        if self.n_obstacles:
            place_obstacles(ob, idx, batch, cfg)
            # The ellipsoid's shape is fixed by the obstacle's performance; only its pose moves.
            # Inflations keep the true obstacle inside despite wind drift and the track error.
            pred = cfg.prediction
            wind = ob.wind[idx]
            # np.linalg.norm's own sum (add.reduce of the squares), without its wrapper.
            wind_speed = np.sqrt((wind * wind).sum(axis=-1))[:, None]
            track_err = 3.0 * self._obstacle_kf.steady_state_position_std()
            inflation = ob.radius[idx] + wind_speed * pred.horizon + track_err
            if pred.fit == "calibrated":  # sized per step from the estimate (_predict_regions)
                self._pred_inflation[idx] = inflation
            else:
                offset, axes = reachable.ellipsoid(
                    ob.speed[idx],
                    ob.max_turn_rate[idx],
                    ob.max_climb_rate[idx],
                    pred.horizon,
                    inflation,
                    mode=pred.mode,
                    fit=pred.fit,
                )
                self.pred_offset[idx] = offset
                self.pred_axes[idx] = axes
            if self.replay is not None:  # after the ellipsoid: it uses the median speed
                self.replay.start(ob, mask, [batch.spec(k) for k in range(len(batch))])
        # First measurements start the tracks. Only the reset rows are measured, predicted
        # and checked: a partial reset's cost should not grow with the batch.
        self._sense(idx)
        self._predict_regions(idx)
        self._start_safety(idx)
        self._reset_plan_rows(idx, batch)

    # ------------------------------------------------------------------ step
    def step(
        self,
        accel_cmd: np.ndarray,
        active: np.ndarray | None = None,
        reset: np.ndarray | None = None,
    ) -> None:
        """Advance every environment by one environment step.

        Args:
            accel_cmd: ``(n_envs, n_uavs, 3)`` commanded accelerations (m/s^2), finite;
                each axis is bounded by ``uav.max_accel`` (the physical limit).
            active: Optional ``(n_envs,)`` bool; environments outside it do not move and
                consume no randomness.
            reset: Optional ``(n_envs,)`` bool; environments that start a new episode in
                this step instead of moving (the vector envs' autoresets): their commands
                are ignored and they end the step in their reset state, the same numbers as
                ``reset(mask=reset)`` followed by ``step(accel_cmd, active=~reset)``.

        Raises:
            ValueError: Wrong shape or non-finite values (the offending entries are named).
            RuntimeError: If called before :meth:`reset`.
        """
        if not self._has_reset:
            raise RuntimeError("World.step called before World.reset")
        cmd = np.asarray(accel_cmd, dtype=float)
        expected = (self.n_envs, self.n_uavs, 3)
        if cmd.shape != expected:
            raise ValueError(f"accel_cmd must have shape {expected}, got {cmd.shape}")
        if not np.isfinite(cmd).all():
            bad = np.argwhere(~np.isfinite(cmd))[:3].tolist()
            raise ValueError(f"accel_cmd has non-finite values at (env, uav, axis) {bad}")
        cfg = self.config
        active = self._mask("active", active)
        reset = self._mask("reset", reset)
        frozen = None
        if active is not None and not active.all():
            held = ~active if reset is None else ~active & ~reset
            if held.any():
                frozen = self._snapshot(np.flatnonzero(held))
        moving = active
        if reset is not None and reset.any():
            # The reset rows move on from their ended episodes without noise (their rows are
            # rewritten below), so nothing of theirs is saved and put back: a reset before
            # the step would have had them held still (snapshot and restore), to the same
            # numbers.
            moving = ~reset if active is None else active & ~reset
        else:
            reset = None
        if moving is not None and moving.all():
            moving = None
        self.prev_accel_cmd[...] = self.accel_cmd
        np.minimum(np.maximum(cmd, -cfg.uav.max_accel), cfg.uav.max_accel, out=self.accel_cmd)
        self.min_uav_dist.fill(np.inf)
        self.min_obstacle_dist.fill(np.inf)
        for _ in range(cfg.decision_interval):
            self._physics_step(moving)
        self.steps += 1
        self._predict_regions()
        if frozen is not None:
            self._restore(frozen)
        self._refresh_plan()
        if reset is not None:
            self.reset(mask=reset)

    def _mask(self, name: str, mask: np.ndarray | None) -> np.ndarray | None:
        """``mask`` as an ``(n_envs,)`` bool array (``None`` stays ``None``), checked."""
        if mask is None:
            return None
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (self.n_envs,):
            raise ValueError(f"{name} must have shape ({self.n_envs},), got {mask.shape}")
        return mask

    _RENAMED: ClassVar[dict[str, str]] = RENAMED_WORLD_ATTRIBUTES  # read with a warning
    _STATE = (
        "time",
        "steps",
        "_kf_count",
        "uav_pos",
        "uav_vel",
        "uav_acc",
        "accel_cmd",
        "prev_accel_cmd",
        "est_pos",
        "est_vel",
        "obstacle_est_pos",
        "obstacle_est_vel",
        "pred_center",
        "pred_axes",
        "pred_heading",
        "pred_cos",
        "pred_sin",
        "min_uav_dist",
        "min_obstacle_dist",
    )
    _OBSTACLE_STATE = ("pos", "heading", "speed", "turn_rate", "climb_rate")

    def _snapshot(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        # An index array: a few frozen rows of a large batch cost a few rows, not a scan.
        snap = {name: getattr(self, name)[rows] for name in self._STATE}
        for name in self._OBSTACLE_STATE:
            snap["obstacles." + name] = getattr(self.obstacles, name)[rows]
        snap["rows"] = rows
        return snap

    def _restore(self, snap: dict[str, np.ndarray]) -> None:
        rows = snap["rows"]
        for name in self._STATE:
            getattr(self, name)[rows] = snap[name]
        for name in self._OBSTACLE_STATE:
            getattr(self.obstacles, name)[rows] = snap["obstacles." + name]

    def _physics_step(self, active: np.ndarray | None = None) -> None:
        normals, unifs = self._noise.draw(active)
        physics_step(self._physics_arrays(), self.obstacles, normals, unifs, self._physics,
                     self.replay)  # fmt: skip

    def _physics_arrays(self) -> PhysicsArrays:
        return PhysicsArrays(
            self.time, self._kf_count, self.uav_pos, self.uav_vel, self.uav_acc, self.accel_cmd,
            self.est_pos, self.est_vel, self.obstacle_est_pos, self.obstacle_est_vel,
            self.min_uav_dist, self.min_obstacle_dist,
        )  # fmt: skip

    # ------------------------------------------------------------------ sensing
    def _sense(self, rows: np.ndarray) -> None:
        """The first measurements of the environments ``rows`` start their tracks."""
        n, m = self.n_uavs, self.n_obstacles
        # Initial measurements use the next noise draw too (consumed only by those envs).
        z, _ = self._noise.draw_rows(rows)
        z_meas = z[:, n * 3 : n * 9].reshape(-1, n, 6)
        mp, mv = measure(self.uav_pos[rows], self.uav_vel[rows], z_meas[..., :3], z_meas[..., 3:])
        self.est_pos[rows], self.est_vel[rows] = mp, mv
        if m:
            obstacle_vel = obstacle_velocity(self.obstacles, rows)
            z_obs = z[:, n * 9 :].reshape(-1, m, 6)
            omp, omv = measure(
                self.obstacles.pos[rows], obstacle_vel, z_obs[..., :3], z_obs[..., 3:]
            )
            self.obstacle_est_pos[rows], self.obstacle_est_vel[rows] = omp, omv
        self._kf_count[rows] = 0

    # ------------------------------------------------------------------ prediction
    def _predict_regions(self, rows: np.ndarray | None = None) -> None:
        """Place each obstacle's reachable ellipsoid on its current estimate (eqs. 8-18).

        All environments, or the index array ``rows`` (a partial reset).
        """
        if not self.n_obstacles:
            return
        r = slice(None) if rows is None else rows
        pred = self.config.prediction
        if pred.fit == "calibrated":
            # Conformal region per aircraft class: centre along the estimated ground velocity,
            # semi-axes affine in the estimated speed (:mod:`uasep_env.reachable.calibrated`).
            center, axes, heading = calibrated.calibrated_region(
                self.obstacles.aircraft_class[r],
                self.obstacle_est_pos[r],
                self.obstacle_est_vel[r],
                pred.horizon,
                pred.mode,
                self._pred_inflation[r],
            )
            self.pred_heading[r] = heading
            self.pred_cos[r], self.pred_sin[r] = np.cos(heading), np.sin(heading)
            self.pred_center[r] = center
            self.pred_axes[r] = axes
            return
        est_pos, offset = self.obstacle_est_pos[r], self.pred_offset[r]
        air = self.obstacle_est_vel[r] - self.obstacles.wind[r, None, :]  # heading: airspeed's
        # Every environment: written in place (the same numbers, without the copies).
        whole = rows is None
        heading = np.arctan2(air[..., 1], air[..., 0], out=self.pred_heading if whole else None)
        cos_h = np.cos(heading, out=self.pred_cos if whole else None)  # distances, observations
        sin_h = np.sin(heading, out=self.pred_sin if whole else None)
        center = self.pred_center if whole else np.empty_like(est_pos)
        center[..., 0] = est_pos[..., 0] + offset * cos_h
        center[..., 1] = est_pos[..., 1] + offset * sin_h
        center[..., 2] = est_pos[..., 2]
        if not whole:
            self.pred_heading[r] = heading
            self.pred_cos[r], self.pred_sin[r] = cos_h, sin_h
            self.pred_center[r] = center

    # ------------------------------------------------------------------ safety
    def _start_safety(self, rows: np.ndarray) -> None:
        """The separations of the environments ``rows`` at their reset."""
        ob = self.obstacles
        d_uav, d_obstacle = nearest_separations(self.uav_pos[rows], ob.pos[rows], ob.active[rows])
        self.min_uav_dist[rows] = d_uav
        self.min_obstacle_dist[rows] = d_obstacle

    # ------------------------------------------------------------------ queries
    def separations(self) -> tuple[np.ndarray, np.ndarray]:
        """Each UAV's distance to the nearest other UAV and to the nearest active obstacle.

        True positions; ``inf`` where there is none
        (:func:`uasep_env.sim.geometry.nearest_separations`).

        Returns:
            ``(uav, obstacle)``, each ``(E, N)`` (m).
        """
        return nearest_separations(self.uav_pos, self.obstacles.pos, self.obstacles.active)

    def uav_distances(self, pos: np.ndarray | None = None) -> np.ndarray:
        """``(E, N, N)`` distances between UAVs (true positions unless ``pos`` given) (m)."""
        return uav_distances(self.uav_pos if pos is None else pos)

    def obstacle_distances(self, pos: np.ndarray | None = None) -> np.ndarray:
        """``(E, N, M)`` UAV-obstacle centre distances, inf for inactive obstacles (m)."""
        p = self.uav_pos if pos is None else pos
        return obstacle_distances(p, self.obstacles.pos, self.obstacles.active)

    def region_distances(
        self, pos: np.ndarray | None = None, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """``(E, N, M)`` signed distance to each predicted reachable ellipsoid (m).

        Inactive obstacles give ``inf``.

        Args:
            pos: Positions to measure from (true UAV positions by default), ``(E, N, 3)``,
                or ``(len(rows), N, 3)`` with ``rows``.
            rows: Only these environments (an index array); the result has their rows.
        """
        if rows is None:
            arrays = _region_views(self.frozen_inputs())  # the views made once
        else:  # the rows' own inputs (their positions only when none are given)
            names = _REGION_INPUTS if pos is None else _REGION_INPUTS[1:]
            arrays = [operator.attrgetter(n)(self)[rows] for n in names]
            arrays = arrays if pos is None else [pos, *arrays]
        p = arrays[0] if pos is None else pos
        if not self.n_obstacles:
            return np.zeros((*p.shape[:2], 0))
        return reachable.region_distances(p, *arrays[1:])

    def obstacle_velocities(self) -> np.ndarray:
        """``(E, M, 3)`` true obstacle ground velocities (m/s)."""
        return obstacle_velocity(self.obstacles)
