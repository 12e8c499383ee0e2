"""Typed, frozen and validated configuration.

Every setting of the simulator and the environments lives in one of the frozen dataclasses
below. :func:`make_config` builds an :class:`EnvConfig` from keyword arguments or a (nested)
dict; unknown keys raise a :class:`TypeError` (Python's convention for an unexpected
keyword) and invalid or out-of-range values a :class:`ValueError`, each naming the dotted field.
Every numeric field is bounded to a physically meaningful range, so that a config that
validates also simulates (no overflow, no infinite reward, no clipped sensing).

Units are SI throughout: metres (m), seconds (s), radians (rad), m/s, m/s^2.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, TypeVar

import numpy as np

__all__ = [
    "ACTION_MODES",
    "AS_PUBLISHED",
    "FORMATION_PATTERNS",
    "SCENARIOS",
    "ActionConfig",
    "EnvConfig",
    "NoiseConfig",
    "ObservationConfig",
    "ObstacleConfig",
    "PredictionConfig",
    "RewardWeights",
    "UAVConfig",
    "make_config",
]

#: Names accepted for ``EnvConfig.formation`` (see :mod:`uasep_env.formation`).
FORMATION_PATTERNS = ("line_abreast", "paper", "column", "v", "wedge", "grid", "circle")

#: Names accepted for ``EnvConfig.scenario`` (see :mod:`uasep_env.scenarios`).
SCENARIOS = (
    "paper",
    "random",
    "crossing",
    "head_on",
    "overtaking",
    "climbing",
    "multi_obstacle",
    "large_formation",
)

#: Overrides that run the paper's prediction as published: the terminal set S1..S5 and the
#: paper's (non-enclosing) ellipsoid of eqs. 17-18. ``make_config(AS_PUBLISHED,
#: scenario="paper")``; on the command line ``--config prediction.mode=terminal --config
#: prediction.fit=paper``.
AS_PUBLISHED: dict[str, dict[str, str]] = {"prediction": {"mode": "terminal", "fit": "paper"}}

T = TypeVar("T")


def _check(cond: bool, name: str, value: object, what: str) -> None:
    if not cond:
        raise ValueError(f"invalid config value {name}={value!r}: {what}")


def _is_real(value: object) -> bool:
    """A real number: int, float or a numpy integer/floating scalar (not a bool)."""
    return isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(
        value, (bool, np.bool_)
    )


def _finite(name: str, value: float, bound: float | None = None) -> None:
    _check(
        _is_real(value) and math.isfinite(float(value)),
        name,
        value,
        "must be a finite number",
    )
    if bound is not None:
        _check(abs(value) <= bound, name, value, f"must be in [-{bound:g}, {bound:g}]")


def _positive(name: str, value: float, *, allow_zero: bool = False, hi: float) -> None:
    _finite(name, value)
    if allow_zero:
        _check(value >= 0, name, value, "must be >= 0")
    else:
        _check(value > 0, name, value, "must be > 0")
    _check(value <= hi, name, value, f"must be <= {hi:g}")


def _int_in(name: str, value: int, lo: int, hi: int) -> None:
    _check(
        isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)),
        name,
        value,
        "must be an integer",
    )
    _check(lo <= value <= hi, name, value, f"must be in [{lo}, {hi}]")


def _one_of(name: str, value: object, choices: tuple) -> None:
    _check(
        (value is None or isinstance(value, str)) and value in choices,
        name,
        value,
        f"must be one of {choices}",
    )


def _vector(name: str, value: object, length: int, bound: float) -> tuple[float, ...]:
    """A sequence of ``length`` finite reals within ``[-bound, bound]``, as a float tuple."""
    _check(
        isinstance(value, (tuple, list, np.ndarray)) and len(value) == length,
        name,
        value,
        f"must be a sequence of {length} numbers",
    )
    for v in value:  # type: ignore[union-attr]
        _check(_is_real(v) and math.isfinite(float(v)), name, value, "must be finite numbers")
        _check(abs(v) <= bound, name, value, f"components must be in [-{bound:g}, {bound:g}]")
    return tuple(float(v) for v in value)  # type: ignore[union-attr]


# Physical bounds of the fields (SI). Generous, but finite: beyond them a config would
# overflow, give infinite rewards or describe no aircraft.
_MAX_SPEED = 200.0  # m/s (UAVs, obstacles, wind, velocity noise)
_MAX_ACCEL = 100.0  # m/s^2 (about 10 g)
_MAX_DIST = 10_000.0  # m (separation radii, formation sizes, position noise)
_MAX_TURN_RATE = 2.0 * math.pi  # rad/s (a full turn per second)
_MAX_TIME = 1.0e6  # s (episode duration, switch times)
_MAX_WEIGHT = 1.0e6  # reward weights
_MAX_OBS = 1.0e6  # observation scales, clip bound and sensing range


@dataclass(frozen=True)
class UAVConfig:
    """Physical limits of the cooperative UAVs (paper eqs. 3-4).

    Attributes:
        max_speed: ``V_max``, the speed never exceeded after a step (m/s).
        max_accel: Bound on each axis of the commanded acceleration (m/s^2). The action
            ``[-1, 1]^3`` is scaled by it.
        collision_distance: ``r_safe_min``: centre distance below which two aircraft
            collide (m).
        separation_distance: UAV-UAV loss-of-separation threshold (m).
        obstacle_separation: UAV-obstacle loss-of-separation threshold (m), measured
            between centres.
        lost_distance: A UAV farther than this from its planned position is lost: the
            episode ends (terminated) (m). The default is almost three times the APF's
            largest deviation on the random bank (112 m), so it never ends a controlled
            flight; it ends the flights of untrained policies before they drift for
            kilometres, where no reward term can tell them the way back.
    """

    max_speed: float = 10.0  # m/s
    max_accel: float = 2.0  # m/s^2, per axis
    collision_distance: float = 3.0  # m
    separation_distance: float = 8.0  # m
    obstacle_separation: float = 10.0  # m
    lost_distance: float = 300.0  # m

    def __post_init__(self) -> None:
        _positive("uav.max_speed", self.max_speed, hi=_MAX_SPEED)
        _positive("uav.max_accel", self.max_accel, hi=_MAX_ACCEL)
        _positive("uav.collision_distance", self.collision_distance, hi=_MAX_DIST)
        _positive("uav.separation_distance", self.separation_distance, hi=_MAX_DIST)
        _positive("uav.obstacle_separation", self.obstacle_separation, hi=_MAX_DIST)
        _positive("uav.lost_distance", self.lost_distance, hi=_MAX_DIST)
        _check(
            self.separation_distance >= self.collision_distance,
            "uav.separation_distance",
            self.separation_distance,
            "must be >= uav.collision_distance",
        )
        _check(
            self.obstacle_separation >= self.collision_distance,
            "uav.obstacle_separation",
            self.obstacle_separation,
            "must be >= uav.collision_distance",
        )
        _check(
            self.lost_distance > max(self.separation_distance, self.obstacle_separation),
            "uav.lost_distance",
            self.lost_distance,
            "must be > uav.separation_distance and uav.obstacle_separation",
        )


@dataclass(frozen=True)
class NoiseConfig:
    """Process and measurement noise (paper eqs. 1-2). Zero turns a source off.

    Attributes:
        accel_std: ``S_w``: std of the Gaussian noise added to each UAV's commanded
            acceleration, per axis (m/s^2).
        position_std: ``S_v``: std of a UAV's sensed position, per axis (m).
        velocity_std: ``S_v``: std of a UAV's sensed velocity, per axis (m/s).
        obstacle_position_std: std of the radar/ADS-B track of an obstacle's position (m).
        obstacle_velocity_std: std of an obstacle track's velocity (m/s).
    """

    accel_std: float = 0.05  # m/s^2
    position_std: float = 0.5  # m
    velocity_std: float = 0.1  # m/s
    obstacle_position_std: float = 2.0  # m
    obstacle_velocity_std: float = 0.3  # m/s

    def __post_init__(self) -> None:
        bounds = {
            "accel_std": _MAX_ACCEL,
            "position_std": _MAX_DIST,
            "velocity_std": _MAX_SPEED,
            "obstacle_position_std": _MAX_DIST,
            "obstacle_velocity_std": _MAX_SPEED,
        }
        for f in fields(self):
            _positive(f"noise.{f.name}", getattr(self, f.name), allow_zero=True, hi=bounds[f.name])

    @classmethod
    def off(cls) -> NoiseConfig:
        """All noise sources switched off (runs are deterministic given the actions)."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def is_off(self) -> bool:
        """Whether every noise source is zero."""
        return all(getattr(self, f.name) == 0.0 for f in fields(self))


@dataclass(frozen=True)
class ObstacleConfig:
    """Motion model of the non-cooperative obstacles (3D Dubins, paper eq. 8).

    Scenarios that randomise obstacles draw around these values (see
    :mod:`uasep_env.scenarios`); the ``paper`` scenario uses them as given.

    Attributes:
        speed: Constant horizontal airspeed ``v`` (m/s).
        max_turn_rate: ``w_max``, bound on the turn rate (rad/s).
        max_climb_rate: ``vz_max``, bound on the climb/descent rate (m/s).
        radius: Safety radius ``r`` added around the obstacle's reachable positions (m).
        mean_switch_time: Mean time between the pilot's random changes of the turn and
            climb commands (s); a command changes in a step with probability ``dt / mean``.
        straight_probability: Probability that a new command is "fly straight and level".
        wind: Steady wind added to the obstacles' ground velocity, NED (m/s).
    """

    speed: float = 4.0  # m/s
    max_turn_rate: float = 0.013  # rad/s
    max_climb_rate: float = 0.5  # m/s
    radius: float = 3.0  # m
    mean_switch_time: float = 30.0  # s
    straight_probability: float = 0.5
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s, NED

    def __post_init__(self) -> None:
        _positive("obstacle.speed", self.speed, hi=_MAX_SPEED)
        _positive("obstacle.max_turn_rate", self.max_turn_rate, allow_zero=True, hi=_MAX_TURN_RATE)
        _positive("obstacle.max_climb_rate", self.max_climb_rate, allow_zero=True, hi=_MAX_SPEED)
        _positive("obstacle.radius", self.radius, allow_zero=True, hi=_MAX_DIST)
        _positive("obstacle.mean_switch_time", self.mean_switch_time, hi=_MAX_TIME)
        _finite("obstacle.straight_probability", self.straight_probability)
        _check(
            0.0 <= self.straight_probability <= 1.0,
            "obstacle.straight_probability",
            self.straight_probability,
            "must be in [0, 1]",
        )
        wind = _vector("obstacle.wind", self.wind, 3, _MAX_SPEED)  # NED
        object.__setattr__(self, "wind", wind)


@dataclass(frozen=True)
class PredictionConfig:
    """Reachable-set prediction of the obstacles (paper eqs. 9-18, see notes).

    Attributes:
        horizon: Prediction horizon ``t`` (s); the paper uses 10 s.
        mode: ``"swept"`` (every point reachable within the horizon, the default used for
            separation) or ``"terminal"`` (reachable at exactly the horizon, the paper's S1..S5).
        fit: ``"enclosing"`` (an ellipsoid that provably encloses the set, the default) or
            ``"paper"`` (eqs. 17-18 as published: axes from the set's extents, a circular
            section across the heading; it does not enclose the set). With
            ``mode="terminal"`` this is the paper's prediction as published, see
            :data:`AS_PUBLISHED`.
        kalman: Whether UAVs and obstacle tracks are Kalman filtered; off, the raw noisy
            measurements are used as estimates.
    """

    horizon: float = 10.0  # s
    mode: str = "swept"
    fit: str = "enclosing"
    kalman: bool = True

    def __post_init__(self) -> None:
        _positive("prediction.horizon", self.horizon, hi=600.0)
        _one_of("prediction.mode", self.mode, ("swept", "terminal"))
        _one_of("prediction.fit", self.fit, ("enclosing", "paper"))
        _check(isinstance(self.kalman, bool), "prediction.kalman", self.kalman, "must be a bool")


@dataclass(frozen=True)
class ObservationConfig:
    """What each agent observes (see :mod:`uasep_env.observation`).

    Attributes:
        k_uavs: Number of nearest other UAVs observed (``None``: all others, at most 6).
        k_obstacles: Number of nearest obstacles observed (``None``: all, at least 1 slot).
        position_scale: Divisor that normalises positions (m).
        clip: Normalised values are clipped to ``[-clip, clip]``. The default, 12, leaves
            room for the distance to the final way-point of a default plan (1,000 m and the
            formation's start offset; at 10 it read 1,000 m where the truth was up to
            1,012 m).
        sensing_range: Obstacles and UAVs farther than this are not observed (m); at most
            ``clip * position_scale``, the farthest distance an observation can express.
    """

    k_uavs: int | None = None
    k_obstacles: int | None = None
    position_scale: float = 100.0  # m
    clip: float = 12.0
    sensing_range: float = 1000.0  # m

    def __post_init__(self) -> None:
        if self.k_uavs is not None:
            _int_in("observation.k_uavs", self.k_uavs, 1, 31)
        if self.k_obstacles is not None:
            _int_in("observation.k_obstacles", self.k_obstacles, 1, 8)
        _positive("observation.position_scale", self.position_scale, hi=_MAX_OBS)
        _positive("observation.clip", self.clip, hi=_MAX_OBS)
        _positive("observation.sensing_range", self.sensing_range, hi=_MAX_OBS)
        reach = self.clip * self.position_scale
        _check(
            self.sensing_range <= reach,
            "observation.sensing_range",
            self.sensing_range,
            f"must be <= observation.clip * observation.position_scale ({reach:g} m): "
            "farther objects would be observed with clipped distances",
        )


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (see :mod:`uasep_env.rewards`).

    Each agent's reward is ``sum_k w_k * term_k`` over its own terms, mixed with the
    team's mean by ``shared``: ``r_i = (1 - shared) * own_i + shared * mean_j(own_j)``.

    Attributes:
        separation_inner: Weight of the UAV-UAV separation term (<= 0 penalty).
        separation_obstacle: Weight of the UAV-obstacle distance term.
        separation_region: Weight of the reachable-region intrusion term.
        deviation: Weight of the planned-trajectory deviation term.
        control: Weight of the control-effort term.
        smoothness: Weight of the acceleration-change term.
        collision: Weight of the collision term (``-max_steps`` on a collision).
        progress: Weight of the per-step alive bonus.
        shared: Share of the team-mean reward in each agent's reward, in [0, 1].
    """

    # Defaults: a step's reward is in [0, 1] and a collision costs a whole episode (why:
    # uasep_env.rewards).
    separation_inner: float = 0.25
    separation_obstacle: float = 0.4
    separation_region: float = 0.05
    deviation: float = 0.2
    control: float = 0.0
    smoothness: float = 0.0125
    collision: float = 1.0
    progress: float = 1.0
    shared: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            _finite(f"reward.{f.name}", getattr(self, f.name), _MAX_WEIGHT)
        _check(0.0 <= self.shared <= 1.0, "reward.shared", self.shared, "must be in [0, 1]")


#: Names accepted for ``ActionConfig.mode`` (see :mod:`uasep_env.actions`).
ACTION_MODES = ("direct", "residual_apf")


@dataclass(frozen=True)
class ActionConfig:
    """What an agent's action means (see :mod:`uasep_env.actions`).

    Attributes:
        mode: ``"direct"``: the action is the commanded acceleration, as a fraction of
            ``uav.max_accel`` per axis. ``"residual_apf"``: the action is a bounded
            correction added to the paper's APF command for the same observation; the
            observation then ends with that APF command (3 more entries).
        residual_scale: In ``residual_apf`` mode, the largest correction per axis, as a
            fraction of ``uav.max_accel`` (the sum is clipped to the acceleration bound).
        strict: Finite actions outside the action box ``[-1, 1]`` raise a ``ValueError``
            naming them. Off (the default, the ecosystem's convention), they are clipped to
            the box and counted in the step's infos (``clipped_actions``).
    """

    mode: str = "direct"
    residual_scale: float = 0.5  # fraction of uav.max_accel
    strict: bool = False

    def __post_init__(self) -> None:
        _check(
            self.mode in ACTION_MODES, "action.mode", self.mode, f"must be one of {ACTION_MODES}"
        )
        _finite("action.residual_scale", self.residual_scale)
        _check(
            0.0 < self.residual_scale <= 2.0,
            "action.residual_scale",
            self.residual_scale,
            "must be in (0, 2]",
        )
        _check(isinstance(self.strict, bool), "action.strict", self.strict, "must be a bool")


@dataclass(frozen=True)
class EnvConfig:
    """The whole configuration of a world / environment.

    Attributes:
        n_uavs: Number of cooperative UAVs (2-32).
        n_obstacles: Number of obstacle slots (0-8). Scenarios may leave some inactive.
        scenario: Scenario family, one of :data:`SCENARIOS`.
        formation: Pattern name (one of :data:`FORMATION_PATTERNS`) or an explicit
            ``((x, y, z), ...)`` of slots in the formation frame (m, ``Y_f`` forward,
            ``X_f`` lateral horizontal, ``Z_f`` down), one per UAV.
        formation_spacing: Spacing of the named patterns (m).
        cruise_speed: Speed along the planned trajectory (m/s).
        dt: Physics step ``Delta T`` (s).
        decision_interval: Physics steps per environment step (action held).
        episode_duration: Episode time limit (s); the episode is truncated after it.
        uav: UAV limits.
        noise: Noise levels (``False`` for none).
        obstacle: Obstacle model.
        prediction: Reachable-set prediction and filtering.
        observation: Observation options.
        reward: Reward weights.
        action: What an action means (direct command or residual on the APF) and how
            out-of-box actions are treated.
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
    """

    n_uavs: int = 3
    n_obstacles: int = 1
    scenario: str = "paper"
    formation: str | tuple[tuple[float, float, float], ...] = "paper"
    formation_spacing: float = 20.0  # m
    cruise_speed: float = 5.0  # m/s
    dt: float = 0.2  # s
    decision_interval: int = 1
    episode_duration: float = 200.0  # s
    uav: UAVConfig = field(default_factory=UAVConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    obstacle: ObstacleConfig = field(default_factory=ObstacleConfig)
    prediction: PredictionConfig = field(default_factory=PredictionConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    reward: RewardWeights = field(default_factory=RewardWeights)
    action: ActionConfig = field(default_factory=ActionConfig)
    render_mode: str | None = None

    def __post_init__(self) -> None:
        _int_in("n_uavs", self.n_uavs, 2, 32)
        _int_in("n_obstacles", self.n_obstacles, 0, 8)
        _one_of("scenario", self.scenario, SCENARIOS)
        if isinstance(self.formation, str):
            _check(
                self.formation in FORMATION_PATTERNS,
                "formation",
                self.formation,
                f"must be one of {FORMATION_PATTERNS} or a tuple of (x, y, z) slots",
            )
        else:
            _check(
                isinstance(self.formation, (tuple, list, np.ndarray))
                and len(self.formation) == self.n_uavs,
                "formation",
                self.formation,
                f"explicit pattern must have shape ({self.n_uavs}, 3): one (x, y, z) per UAV",
            )
            slots = tuple(
                _vector(f"formation[{i}]", row, 3, _MAX_DIST)
                for i, row in enumerate(self.formation)  # type: ignore[arg-type]
            )
            object.__setattr__(self, "formation", slots)
        _positive("formation_spacing", self.formation_spacing, hi=_MAX_DIST)
        _positive("cruise_speed", self.cruise_speed, hi=_MAX_SPEED)
        _check(
            self.cruise_speed <= self.uav.max_speed,
            "cruise_speed",
            self.cruise_speed,
            f"must be <= uav.max_speed ({self.uav.max_speed})",
        )
        _positive("dt", self.dt, hi=5.0)
        _int_in("decision_interval", self.decision_interval, 1, 1000)
        _positive("episode_duration", self.episode_duration, hi=_MAX_TIME)
        _check(
            self.episode_duration >= self.dt * self.decision_interval,
            "episode_duration",
            self.episode_duration,
            "must be at least one environment step",
        )
        _one_of("render_mode", self.render_mode, (None, "human", "rgb_array"))
        for name, cls in _NESTED.items():
            _check(
                isinstance(getattr(self, name), cls),
                name,
                getattr(self, name),
                f"must be a {cls.__name__} (use make_config to build from dicts)",
            )
        _check(
            self.action.mode != "residual_apf" or self.observation.clip >= 1.0,
            "observation.clip",
            self.observation.clip,
            "must be >= 1 with action.mode='residual_apf' (the observed APF command is in [-1, 1])",
        )

    @property
    def step_duration(self) -> float:
        """Duration of one environment step (s)."""
        return self.dt * self.decision_interval

    @property
    def max_steps(self) -> int:
        """Environment steps before truncation."""
        return max(1, round(self.episode_duration / self.step_duration))

    def replace(self, **changes: Any) -> EnvConfig:
        """Return a copy with ``changes`` applied (validated like :func:`make_config`)."""
        return make_config(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-friendly nested dict of the configuration."""
        return dataclasses.asdict(self)


_NESTED: dict[str, type] = {
    "uav": UAVConfig,
    "noise": NoiseConfig,
    "obstacle": ObstacleConfig,
    "prediction": PredictionConfig,
    "observation": ObservationConfig,
    "reward": RewardWeights,
    "action": ActionConfig,
}


def _build(cls: type[T], base: T | None, values: Mapping[str, Any], prefix: str) -> T:
    """Build dataclass ``cls`` from ``base`` updated with ``values``.

    Raises:
        TypeError: For unknown keys (named, dotted).
        ValueError: For invalid values (named, dotted).
    """
    names = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    bad_keys = [k for k in values if not isinstance(k, str)]
    if bad_keys:
        raise TypeError(f"config keys must be strings, got {bad_keys[0]!r} in {prefix or 'config'}")
    unknown = sorted(set(values) - names)
    if unknown:
        full = ", ".join(prefix + k for k in unknown)
        # Python's own wording first: clients such as TorchRL's GymEnv recognise an
        # optional keyword the env does not take by "unexpected keyword argument 'name'".
        python = ", ".join(f"unexpected keyword argument {prefix + k!r}" for k in unknown)
        raise TypeError(f"{python} (unknown config key(s): {full}); valid keys: {sorted(names)}")
    current = {f.name: getattr(base, f.name) for f in fields(cls)} if base is not None else {}
    for key, value in values.items():
        sub = _NESTED.get(key) if cls is EnvConfig else None
        if sub is not None:
            if value is False and sub is NoiseConfig:
                value = NoiseConfig.off()
            elif value is True and sub is NoiseConfig:
                value = NoiseConfig()
            elif isinstance(value, Mapping):
                value = _build(sub, current.get(key, sub()), value, prefix + key + ".")
            elif not isinstance(value, sub):
                raise ValueError(
                    f"invalid config value {prefix}{key}={value!r}: "
                    f"must be a dict or {sub.__name__}"
                )
        current[key] = value
    return cls(**current)


def make_config(config: EnvConfig | Mapping[str, Any] | None = None, **kwargs: Any) -> EnvConfig:
    """Build a validated :class:`EnvConfig`.

    Args:
        config: A base config, a (nested) dict of overrides, or ``None`` for defaults.
        **kwargs: Further overrides (nested dicts allowed, e.g. ``noise={"accel_std": 0}``).

    Returns:
        The frozen config.

    Raises:
        TypeError: For unknown keys (named, e.g. ``noise.acel_std``).
        ValueError: For invalid or out-of-range values (the dotted field and the value).
    """
    if config is None:
        base, values = EnvConfig(), {}
    elif isinstance(config, EnvConfig):
        base, values = config, {}
    elif isinstance(config, Mapping):
        base, values = EnvConfig(), dict(config)
    elif is_dataclass(config):
        raise ValueError(f"config must be an EnvConfig or a dict, got {type(config).__name__}")
    else:
        raise ValueError(f"config must be an EnvConfig or a dict, got {config!r}")
    values.update(kwargs)
    return _build(EnvConfig, base, values, "")
