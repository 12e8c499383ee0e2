"""Non-cooperative obstacles: a 3D Dubins model with random pilot commands (paper eq. 8).

Each obstacle flies at a constant horizontal airspeed ``v`` (m/s) with heading ``psi``
(rad, from north towards east), a turn rate ``|omega| <= w_max`` (rad/s) and a climb rate
``|c| <= vz_max`` (m/s, positive up; NED ``v_z = -c``). A steady wind (m/s, NED) adds to the
ground velocity. The pilot changes the commands at random: in each physics step of
``dt`` a new command is drawn with probability ``dt / mean_switch_time`` (a discretised
exponential reaction time); a new command is "straight and level" with probability
``straight_probability``, else turn and climb rates uniform within their bounds. An
obstacle that would leave its altitude band holds its altitude instead.

The ground (``ground``, m of altitude) is never flown through. Near it the descent command
is bounded: the climb command ``c`` is raised to at least ``min(vz_max, w_d + (g - h) / dt)``
(``h`` the altitude, ``g`` the ground, ``w_d`` the wind's downward component), so the next
altitude is at or above the ground whenever the obstacle can out-climb the wind. The command
stays within ``|c| <= vz_max``, so the reachable-set prediction's enclosing fit remains
valid. Only a downward wind stronger than ``vz_max`` could still push it lower; then the
obstacle rests on the ground (its altitude is floored there), which only shortens the wind's
drift and so stays inside the prediction's wind inflation (``|wind| * horizon``). Above the
ground (and its band's floor) neither rule acts, so flights in the air are unchanged.

The horizontal motion over a step is integrated exactly (a circular arc: the chord has
length ``v dt sinc(omega dt / 2)`` and direction ``psi + omega dt / 2``), so the bounds of the
model hold exactly and the reachable-set prediction (:mod:`uasep_env.reachable`) is sound.

Arrays are batch-first: ``(n_envs, n_obstacles)``. Randomness comes in as pre-drawn
uniforms (see :mod:`uasep_env.sim.world`), never from global state.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uasep_env._numba import compiled_twin

__all__ = [
    "AIRCRAFT_CLASSES",
    "AIRCRAFT_TABLE",
    "CALIBRATED_CLASSES",
    "DUBINS_CLASS",
    "N_UNIFORMS",
    "REAL_TRAFFIC_CLASSES",
    "UNKNOWN_CLASS",
    "AircraftClass",
    "ObstacleState",
    "aircraft_class_code",
    "obstacle_velocity",
    "step_obstacles",
]

#: Uniform draws each obstacle consumes per physics step (switch?, straight?, turn, climb).
N_UNIFORMS = 4


class AircraftClass(NamedTuple):
    """One row of the aircraft class table.

    Attributes:
        name: The class's name (in the real-traffic dataset's ``aircraft_class`` field and
            the calibration table's cells).
        source: Where the calibration builder (``tools/build_prediction_calibration.py``)
            draws this class's paths: ``"synthetic"`` (episodes of the Dubins obstacle
            model), ``"real_traffic"`` (the dataset's tracks of this class) or ``None``
            (never calibrated: it gets the most conservative region).
    """

    name: str
    source: str | None


#: Aircraft classes an obstacle can carry (its code is the row's index), like ADS-B's emitter
#: category: ``"dubins"`` for the synthetic model, the real-traffic dataset's classes for
#: replayed tracks, ``"unknown"`` (code 0) for anything else. The one table the codes, the
#: ``obstacle_class`` one-hot's width, the calibrated prediction's coefficient rows, the
#: calibration builder's class list and the real-traffic dataset's classes derive from
#: (``docs/extending.md``, "Adding an aircraft class"). Append rows: a code is an index.
AIRCRAFT_TABLE: tuple[AircraftClass, ...] = (
    AircraftClass("unknown", None),
    AircraftClass("dubins", "synthetic"),
    AircraftClass("glider", "real_traffic"),
    AircraftClass("helicopter", "real_traffic"),
    AircraftClass("fixed_wing", "real_traffic"),
)
#: The class names, by code.
AIRCRAFT_CLASSES: tuple[str, ...] = tuple(c.name for c in AIRCRAFT_TABLE)
#: The classes the calibration builder calibrates, in table order.
CALIBRATED_CLASSES: tuple[str, ...] = tuple(c.name for c in AIRCRAFT_TABLE if c.source)
#: The classes of the real-traffic dataset's tracks, in table order.
REAL_TRAFFIC_CLASSES: tuple[str, ...] = tuple(
    c.name for c in AIRCRAFT_TABLE if c.source == "real_traffic"
)
UNKNOWN_CLASS = AIRCRAFT_CLASSES.index("unknown")
DUBINS_CLASS = AIRCRAFT_CLASSES.index("dubins")


def aircraft_class_code(name: str) -> int:
    """The code of an aircraft class name; unknown names get :data:`UNKNOWN_CLASS`."""
    return AIRCRAFT_CLASSES.index(name) if name in AIRCRAFT_CLASSES else UNKNOWN_CLASS


class ObstacleState:
    """Batched obstacle state and parameters (all arrays ``(n_envs, n_obstacles)``).

    Attributes:
        pos: ``(E, M, 3)`` true position, NED (m).
        heading: ``psi`` (rad).
        speed: Constant horizontal airspeed (m/s).
        turn_rate: Current turn command (rad/s).
        climb_rate: Current climb command, positive up (m/s).
        max_turn_rate: ``w_max`` (rad/s).
        max_climb_rate: ``vz_max`` (m/s).
        radius: Safety radius ``r`` (m).
        alt_band: ``(E, M, 2)`` allowed altitude band ``(min, max)`` (m, positive up).
        active: Whether the obstacle slot is in use.
        switch_prob: Per-step command-change probability.
        straight_prob: Probability of a straight-and-level command.
        hold_until: Time before which the pilot keeps the initial commands (s).
        ground: Altitude of the ground, never flown below (m, positive up).
        wind: ``(E, 3)`` steady wind (m/s, NED).
        aircraft_class: Class code (:data:`AIRCRAFT_CLASSES`): ``"dubins"`` for the
            synthetic model, the recorded class for a replayed track.
    """

    def __init__(self, n_envs: int, n_obstacles: int) -> None:
        shape = (n_envs, n_obstacles)
        self.pos = np.zeros((*shape, 3))
        self.heading = np.zeros(shape)
        self.speed = np.zeros(shape)
        self.turn_rate = np.zeros(shape)
        self.climb_rate = np.zeros(shape)
        self.max_turn_rate = np.zeros(shape)
        self.max_climb_rate = np.zeros(shape)
        self.radius = np.zeros(shape)
        self.alt_band = np.zeros((*shape, 2))
        self.alt_band[..., 1] = 1e9
        self.active = np.zeros(shape, dtype=bool)
        self.switch_prob = np.zeros(shape)
        self.straight_prob = np.zeros(shape)
        self.hold_until = np.zeros(shape)
        self.ground = np.zeros(shape)
        self.wind = np.zeros((n_envs, 3))
        self.aircraft_class = np.full(shape, DUBINS_CLASS, dtype=np.int64)


_EPS = float(np.finfo(float).eps)  # np.sinc's guard against 0 / 0


def sinc(x: np.ndarray) -> np.ndarray:
    """``np.sinc(x)`` written out, the same operations, without its own Python overhead.

    It shows at one environment and in a partial reset's fit of a few rows.
    """
    y = np.pi * x
    y = np.where(y, y, _EPS)
    return np.sin(y) / y


def obstacle_velocity(obs: ObstacleState, rows: np.ndarray | None = None) -> np.ndarray:
    """Ground velocity of every obstacle, NED (m/s), ``(E, M, 3)``.

    Args:
        obs: The batched obstacle state.
        rows: Only these environments (a bool mask or index array).
    """
    r = slice(None) if rows is None else rows
    speed, heading = obs.speed[r], obs.heading[r]
    vel = np.empty((*heading.shape, 3))
    wind = obs.wind[r, None, :]
    np.add(speed * np.cos(heading), wind[..., 0], out=vel[..., 0])
    np.add(speed * np.sin(heading), wind[..., 1], out=vel[..., 1])
    np.add(-obs.climb_rate[r], wind[..., 2], out=vel[..., 2])
    return vel


@compiled_twin("obstacle_step")
def step_obstacles(
    obs: ObstacleState, uniforms: np.ndarray, dt: float, time: np.ndarray | None = None
) -> None:
    """Advance every obstacle one physics step, in place.

    Args:
        obs: The batched obstacle state.
        uniforms: ``(E, M, N_UNIFORMS)`` uniforms in ``[0, 1)`` for the pilot's commands.
        dt: Physics step (s).
        time: ``(E,)`` current time (s), compared with ``hold_until``; ``None``: no hold.
    """
    switch = uniforms[..., 0] < obs.switch_prob
    if time is not None:
        switch &= time[:, None] >= obs.hold_until
    straight = uniforms[..., 1] < obs.straight_prob
    new_turn = np.where(straight, 0.0, (2.0 * uniforms[..., 2] - 1.0) * obs.max_turn_rate)
    new_climb = np.where(straight, 0.0, (2.0 * uniforms[..., 3] - 1.0) * obs.max_climb_rate)
    obs.turn_rate = np.where(switch, new_turn, obs.turn_rate)
    obs.climb_rate = np.where(switch, new_climb, obs.climb_rate)

    # Hold altitude rather than leave the band (keeps the climb bound: |c| only shrinks).
    alt_next = -obs.pos[..., 2] + obs.climb_rate * dt
    leave = ((alt_next > obs.alt_band[..., 1]) & (obs.climb_rate > 0)) | (
        (alt_next < obs.alt_band[..., 0]) & (obs.climb_rate < 0)
    )
    obs.climb_rate = np.where(leave, 0.0, obs.climb_rate)
    # Near the ground the descent is bounded (a no-op higher up: the bound is then far below
    # -vz_max); |c| <= vz_max still holds, so the prediction stays sound.
    least = np.minimum(
        obs.max_climb_rate, obs.wind[:, None, 2] + (obs.ground + obs.pos[..., 2]) / dt
    )
    obs.climb_rate = np.maximum(obs.climb_rate, least)

    half = 0.5 * obs.turn_rate * dt
    # sin(y) / y with y = half: the chord factor of a circular arc.
    chord = obs.speed * dt * sinc(half / np.pi)
    mid = obs.heading + half
    wind_step = obs.wind * dt
    moves = (
        chord * np.cos(mid) + wind_step[:, None, 0],
        chord * np.sin(mid) + wind_step[:, None, 1],
        -obs.climb_rate * dt + wind_step[:, None, 2],
    )
    heading = np.mod(obs.heading + 2.0 * half + np.pi, 2 * np.pi) - np.pi
    active = obs.active
    if not active.all():  # inactive obstacles stay where they are
        moves = tuple(np.where(active, move, 0.0) for move in moves)
        heading = np.where(active, heading, obs.heading)
    for axis, move in enumerate(moves):
        obs.pos[..., axis] += move
    # Only a downward wind stronger than vz_max (or rounding) reaches here: rest on the ground.
    np.minimum(obs.pos[..., 2], -obs.ground, out=obs.pos[..., 2])
    obs.heading = heading
