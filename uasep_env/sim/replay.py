"""Replayed obstacles: recorded tracks flown sample by sample (``obstacle.model="replay"``).

A replayed obstacle flies a recorded track (:mod:`uasep_env.real_traffic`) that its scenario
(``real_traffic``, :mod:`uasep_env.scenarios.real_traffic`) has resampled at the physics
step ``dt`` and placed: ``(K, 3)`` positions, one per physics step from the reset (``K``:
the episode's physics steps + 1, at most the 200 s timeline's). :class:`ReplayTracks` holds
them for the batch, ``(E, M, K, 3)``. After the Dubins step (:meth:`ReplayTracks.step`,
called from :meth:`uasep_env.sim.world.World.step`) it writes each replayed obstacle's state
into the world's :class:`~uasep_env.sim.obstacles.ObstacleState`: the position from the track,
and heading, airspeed and climb rate such that
:func:`~uasep_env.sim.obstacles.obstacle_velocity` gives the track's velocity (central
differences of the positions; one-sided at the ends). Everything downstream (sensing, the
Kalman filter, the reachable-set prediction, the observations) reads that state as it reads
a Dubins obstacle's.

Past the last sample (an episode longer than the 200 s its scenario draws, or a world
stepped beyond its episode) the obstacle flies on level at its last horizontal velocity: it
stays at the altitude of its last sample, inside the airspace its scenario placed it in.
The Dubins step still runs for the replayed slots (its uniforms are drawn either way, so the
noise streams keep their layout); its result is overwritten. No randomness here: the
scenario drew everything at reset.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from uasep_env.sim.obstacles import ObstacleState

__all__ = ["ReplayTracks", "track_velocities"]


def track_velocities(pos: np.ndarray, dt: float) -> np.ndarray:
    """Velocities of tracks sampled every ``dt``: central differences, one-sided at the ends.

    Args:
        pos: ``(..., K, 3)`` positions (m), ``K >= 2``.
        dt: Sample interval (s).

    Returns:
        ``(..., K, 3)`` velocities (m/s).
    """
    return np.gradient(pos, dt, axis=-2)


class ReplayTracks:
    """The replayed tracks of a batch of worlds.

    Args:
        n_envs: ``E``.
        n_obstacles: ``M``.
        n_samples: ``K``: samples per track (one per physics step from the reset).
        dt: Physics step (s).

    Attributes:
        pos: ``(E, M, K, 3)`` positions at physics step ``k`` after the reset (m, NED).
        on: ``(E, M)`` which slots replay a track (the others fly the Dubins model).

    The velocities are not stored: :meth:`velocity` takes them from the positions at the
    step that needs them, with the arithmetic of :func:`track_velocities` (bit for bit), so
    a batch holds one ``(E, M, K, 3)`` array, not two.
    """

    def __init__(self, n_envs: int, n_obstacles: int, n_samples: int, dt: float) -> None:
        self.dt = float(dt)
        self.n_samples = int(n_samples)
        self.pos = np.zeros((n_envs, n_obstacles, n_samples, 3))
        self.on = np.zeros((n_envs, n_obstacles), dtype=bool)

    def start(self, obs: ObstacleState, mask: np.ndarray, specs: Sequence[Any]) -> None:
        """Load the tracks of ``specs`` into the environments of ``mask`` and start them.

        Args:
            obs: The batch's obstacle state (position, heading, airspeed and climb rate of
                the replayed slots are written).
            mask: ``(E,)`` bool; the environments starting an episode.
            specs: Their scenarios, in order; a spec without ``obstacle_track`` replays
                nothing.

        Raises:
            ValueError: A track of the wrong length (named).
        """
        idx = np.flatnonzero(mask)
        m, k = self.pos.shape[1], self.n_samples
        for i, spec in zip(idx, specs, strict=True):
            track = getattr(spec, "obstacle_track", None)
            if track is None:
                self.on[i] = False
                continue
            if track.shape != (m, k, 3):
                raise ValueError(
                    f"obstacle_track of a {spec.family!r} scenario has shape {track.shape}, "
                    f"expected ({m}, {k}, 3): one position per physics step of the episode"
                )
            self.on[i] = spec.obstacle_replay
            self.pos[i] = track
            classes = getattr(spec, "obstacle_aircraft_class", None)
            if classes is not None:  # the recorded class, like ADS-B's emitter category
                obs.aircraft_class[i] = np.where(self.on[i], classes, obs.aircraft_class[i])
        self._write(obs, mask, np.zeros(len(idx), dtype=np.int64))

    def step(self, obs: ObstacleState, time: np.ndarray) -> None:
        """Move the replayed obstacles to their next sample (after the Dubins step).

        Args:
            obs: The batch's obstacle state, written in place.
            time: ``(E,)`` the time before this physics step (s).
        """
        if self.on.any():
            self._write(obs, slice(None), np.rint(time / self.dt).astype(np.int64) + 1)

    def velocity(self, envs: np.ndarray, slots: np.ndarray, k: np.ndarray) -> np.ndarray:
        """The tracks' velocities at sample ``k``, as :func:`track_velocities` gives them.

        Args:
            envs: ``(R, 1)`` environment indices.
            slots: ``(1, M)`` obstacle slots.
            k: ``(R,)`` sample indices in ``[0, K)``.

        Returns:
            ``(R, M, 3)`` velocities (m/s): central differences, one-sided at the ends.
        """
        last = self.n_samples - 1
        lo, hi = np.maximum(k - 1, 0), np.minimum(k + 1, last)
        diff = self.pos[envs, slots, hi[:, None]] - self.pos[envs, slots, lo[:, None]]
        # np.gradient's own expressions (uniform spacing, edge_order 1), so the floats match.
        inner = ((k > 0) & (k < last))[:, None, None]
        return np.where(inner, diff / (2.0 * self.dt), diff / self.dt)

    def _write(self, obs: ObstacleState, rows: Any, step: np.ndarray) -> None:
        """Set the replayed slots of ``rows`` to their tracks at physics step ``step``."""
        on = self.on[rows]
        if not on.any():
            return
        last = self.n_samples - 1
        k = np.minimum(step, last)
        beyond = ((step - k) * self.dt)[:, None, None]
        envs = np.arange(self.pos.shape[0])[rows][:, None]
        slots = np.arange(self.pos.shape[1])[None, :]
        pos = self.pos[envs, slots, k[:, None]]
        vel = self.velocity(envs, slots, k)
        if (beyond > 0).any():  # past the record: level, at the last horizontal velocity
            vel = np.where(beyond > 0, vel * [1.0, 1.0, 0.0], vel)
            pos = pos + vel * beyond
        # Heading, airspeed and climb such that obstacle_velocity() is the track's velocity.
        air = vel - obs.wind[rows][:, None, :]
        on3 = on[..., None]
        obs.pos[rows] = np.where(on3, pos, obs.pos[rows])
        obs.heading[rows] = np.where(on, np.arctan2(air[..., 1], air[..., 0]), obs.heading[rows])
        obs.speed[rows] = np.where(on, np.hypot(air[..., 0], air[..., 1]), obs.speed[rows])
        obs.climb_rate[rows] = np.where(on, -air[..., 2], obs.climb_rate[rows])
        obs.turn_rate[rows] = np.where(on, 0.0, obs.turn_rate[rows])
