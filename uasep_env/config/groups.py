"""The configuration's groups: frozen, validated dataclasses, one per part of the simulator.

:class:`UAVConfig` (limits of the cooperative UAVs), :class:`NoiseConfig`,
:class:`ObstacleConfig`, :class:`PredictionConfig`, :class:`ObservationConfig`,
:class:`RewardWeights`, :class:`CostWeights` and :class:`ActionConfig`;
:class:`~uasep_env.config.EnvConfig` holds one of each. Every numeric field is bounded to a
physically meaningful range (:mod:`uasep_env.config.checks`); an invalid value raises a
:class:`ValueError` naming the dotted field.

Units are SI throughout: metres (m), seconds (s), radians (rad), m/s, m/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from uasep_env.config.checks import (
    MAX_ACCEL,
    MAX_DIST,
    MAX_OBS,
    MAX_SPEED,
    MAX_TIME,
    MAX_TURN_RATE,
    MAX_WEIGHT,
    MIN_ACCEL,
    MIN_SPEED,
    check,
    check_finite,
    check_int_in,
    check_one_of,
    check_positive,
    check_vector,
)

#: Altitude of every scenario's planned trajectory (m, positive up).
FLIGHT_ALTITUDE = 100.0

#: ``obstacle.model`` values: the 3D Dubins model, or a recorded track replayed.
OBSTACLE_MODELS = ("dubins", "replay")
#: ``obstacle.replay_split`` values (the real-traffic dataset's splits, by flight).
REPLAY_SPLITS = ("train", "validation", "test")
#: Physical range of ``obstacle.replay_speed_scale``: from a recorded glider's 34 m/s down to
#: under 2 m/s, up to twice a recorded speed (fixed wing at 160 m/s, within ``MAX_SPEED``).
REPLAY_SPEED_SCALE_RANGE = (0.05, 2.0)
#: Longest interval between recorded samples a replay interpolates over (s).
MAX_REPLAY_GAP_S = 60.0

__all__ = [
    "ACTION_MODES",
    "FLIGHT_ALTITUDE",
    "OBSTACLE_MODELS",
    "REPLAY_SPEED_SCALE_RANGE",
    "REPLAY_SPLITS",
    "REWARD_PRESETS",
    "ActionConfig",
    "AirspaceConfig",
    "CostWeights",
    "NoiseConfig",
    "ObservationConfig",
    "ObstacleConfig",
    "PredictionConfig",
    "RewardWeights",
    "UAVConfig",
]


@dataclass(frozen=True, kw_only=True)
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
        check_positive("uav.max_speed", self.max_speed, lo=MIN_SPEED, hi=MAX_SPEED)
        check_positive("uav.max_accel", self.max_accel, lo=MIN_ACCEL, hi=MAX_ACCEL)
        check_positive("uav.collision_distance", self.collision_distance, hi=MAX_DIST)
        check_positive("uav.separation_distance", self.separation_distance, hi=MAX_DIST)
        check_positive("uav.obstacle_separation", self.obstacle_separation, hi=MAX_DIST)
        check_positive("uav.lost_distance", self.lost_distance, hi=MAX_DIST)
        check(
            self.separation_distance >= self.collision_distance,
            "uav.separation_distance",
            self.separation_distance,
            "must be >= uav.collision_distance",
        )
        check(
            self.obstacle_separation >= self.collision_distance,
            "uav.obstacle_separation",
            self.obstacle_separation,
            "must be >= uav.collision_distance",
        )
        check(
            self.lost_distance > max(self.separation_distance, self.obstacle_separation),
            "uav.lost_distance",
            self.lost_distance,
            "must be > uav.separation_distance and uav.obstacle_separation",
        )


@dataclass(frozen=True, kw_only=True)
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
            "accel_std": MAX_ACCEL,
            "position_std": MAX_DIST,
            "velocity_std": MAX_SPEED,
            "obstacle_position_std": MAX_DIST,
            "obstacle_velocity_std": MAX_SPEED,
        }
        for f in fields(self):
            check_positive(
                f"noise.{f.name}", getattr(self, f.name), allow_zero=True, hi=bounds[f.name]
            )

    @classmethod
    def off(cls) -> NoiseConfig:
        """All noise sources switched off (runs are deterministic given the actions)."""
        return cls(**{f.name: 0.0 for f in fields(cls)})

    @property
    def is_off(self) -> bool:
        """Whether every noise source is zero."""
        return all(getattr(self, f.name) == 0.0 for f in fields(self))


@dataclass(frozen=True, kw_only=True)
class ObstacleConfig:
    """Motion model of the non-cooperative obstacles (3D Dubins, paper eq. 8, or replay).

    Scenarios that randomise obstacles draw around these values (see
    :mod:`uasep_env.scenarios`); the ``paper`` scenario uses them as given. With
    ``model="replay"`` (the ``real_traffic`` scenario, which requires it) every obstacle flies
    a recorded track instead (:mod:`uasep_env.sim.replay`); ``speed``, ``max_turn_rate`` and
    ``max_climb_rate`` then only shape its predicted reachable set (the speed: the placed
    track's median), as the predictor assumes a Dubins aircraft of these bounds.

    Attributes:
        speed: Constant horizontal airspeed ``v`` (m/s).
        max_turn_rate: ``w_max``, bound on the turn rate (rad/s).
        max_climb_rate: ``vz_max``, bound on the climb/descent rate (m/s).
        radius: Safety radius ``r`` added around the obstacle's reachable positions (m).
        mean_switch_time: Mean time between the pilot's random changes of the turn and
            climb commands (s); a command changes in a step with probability ``dt / mean``.
        straight_probability: Probability that a new command is "fly straight and level".
        wind: Steady wind added to the obstacles' ground velocity, NED (m/s). A replayed
            track is a recorded ground track: the wind does not move it.
        model: ``"dubins"`` (the 3D Dubins model) or ``"replay"`` (recorded tracks); ``None``
            (the default): the one the scenario needs (``"replay"`` for ``real_traffic``,
            else ``"dubins"``), filled in by :class:`~uasep_env.config.EnvConfig`.
        replay_split: Which flights a replay draws from: ``"train"``, ``"validation"`` or
            ``"test"`` (the dataset's split by flight, :mod:`uasep_env.real_traffic`).
        replay_speed_scale: Replayed tracks are scaled about their closest approach by this
            factor (dimensionless, 0.05-2): speeds and climb rates scale by it, turn rates
            and the timing of manoeuvres stay as recorded (1: the recorded speeds).
        replay_max_gap: Longest interval between recorded samples a replay interpolates
            over, linearly (s, 0-60); a track is only replayed over stretches without a
            longer gap.
    """

    speed: float = 4.0  # m/s
    max_turn_rate: float = 0.013  # rad/s
    max_climb_rate: float = 0.5  # m/s
    radius: float = 3.0  # m
    mean_switch_time: float = 30.0  # s
    straight_probability: float = 0.5
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s, NED
    model: str | None = None
    replay_split: str = "train"
    replay_speed_scale: float = 1.0  # dimensionless
    replay_max_gap: float = 20.0  # s

    def __post_init__(self) -> None:
        check_positive("obstacle.speed", self.speed, hi=MAX_SPEED)
        check_one_of("obstacle.model", self.model, (None, *OBSTACLE_MODELS))
        check_one_of("obstacle.replay_split", self.replay_split, REPLAY_SPLITS)
        lo, hi = REPLAY_SPEED_SCALE_RANGE
        check_finite("obstacle.replay_speed_scale", self.replay_speed_scale)
        check(
            lo <= self.replay_speed_scale <= hi,
            "obstacle.replay_speed_scale",
            self.replay_speed_scale,
            f"must be in [{lo}, {hi}] (a factor on the recorded speeds)",
        )
        check_positive("obstacle.replay_max_gap", self.replay_max_gap, hi=MAX_REPLAY_GAP_S)
        check_positive(
            "obstacle.max_turn_rate", self.max_turn_rate, allow_zero=True, hi=MAX_TURN_RATE
        )
        check_positive(
            "obstacle.max_climb_rate", self.max_climb_rate, allow_zero=True, hi=MAX_SPEED
        )
        check_positive("obstacle.radius", self.radius, allow_zero=True, hi=MAX_DIST)
        check_positive("obstacle.mean_switch_time", self.mean_switch_time, hi=MAX_TIME)
        check_finite("obstacle.straight_probability", self.straight_probability)
        check(
            0.0 <= self.straight_probability <= 1.0,
            "obstacle.straight_probability",
            self.straight_probability,
            "must be in [0, 1]",
        )
        wind = check_vector("obstacle.wind", self.wind, 3, MAX_SPEED)  # NED
        object.__setattr__(self, "wind", wind)


@dataclass(frozen=True, kw_only=True)
class AirspaceConfig:
    """The airspace obstacles fly in: the ground, a placement margin above it and a ceiling.

    Altitudes are positive up (m; NED ``z = -altitude``). Every scenario places its
    obstacles between ``ground_altitude + obstacle_margin`` and ``ceiling_altitude`` (a
    climbing obstacle climbs more slowly rather than start lower), and the obstacle model
    (:mod:`uasep_env.sim.obstacles`) never flies below ``ground_altitude``: near the ground its
    descent command is bounded. The scenarios' formations fly at 100 m, which must lie
    between the two.

    Attributes:
        ground_altitude: Altitude of the ground (m).
        obstacle_margin: Least height above the ground an obstacle starts at (m).
        ceiling_altitude: Highest altitude an obstacle starts at (m).
    """

    ground_altitude: float = 0.0  # m
    obstacle_margin: float = 20.0  # m
    ceiling_altitude: float = 500.0  # m

    def __post_init__(self) -> None:
        check_finite("airspace.ground_altitude", self.ground_altitude, MAX_DIST)
        check_positive(
            "airspace.obstacle_margin", self.obstacle_margin, allow_zero=True, hi=MAX_DIST
        )
        check_finite("airspace.ceiling_altitude", self.ceiling_altitude, 2 * MAX_DIST)
        floor = self.ground_altitude + self.obstacle_margin
        check(
            floor < FLIGHT_ALTITUDE,
            "airspace.ground_altitude",
            self.ground_altitude,
            f"ground_altitude + obstacle_margin ({floor:g} m) must be below the scenarios' "
            f"flight altitude ({FLIGHT_ALTITUDE:g} m)",
        )
        check(
            self.ceiling_altitude > FLIGHT_ALTITUDE,
            "airspace.ceiling_altitude",
            self.ceiling_altitude,
            f"must be above the scenarios' flight altitude ({FLIGHT_ALTITUDE:g} m)",
        )


#: Horizons (s) at which ``prediction.fit="calibrated"`` is calibrated (its shipped table).
CALIBRATED_HORIZONS = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0)


@dataclass(frozen=True, kw_only=True)
class PredictionConfig:
    """Reachable-set prediction of the obstacles (paper eqs. 9-18, see notes).

    Attributes:
        horizon: Prediction horizon ``t`` (s); the paper uses 10 s.
        mode: ``"swept"`` (every point reachable within the horizon, the default used for
            separation) or ``"terminal"`` (reachable at exactly the horizon, the paper's S1..S5).
        fit: ``"calibrated"`` (the default since ``-v3``: a constant-velocity region sized
            by split conformal prediction per aircraft class on recorded flights,
            :mod:`uasep_env.reachable.calibrated`; horizons of :data:`CALIBRATED_HORIZONS`
            only), ``"enclosing"`` (an ellipsoid that provably encloses the Dubins set, the
            ``-v2`` default; on recorded aircraft it held the next 10 s in 22 % of windows),
            ``"paper"`` (eqs. 17-18 as published: axes from the set's extents, a circular
            section across the heading; it does not enclose the set; with
            ``mode="terminal"`` this is the paper's prediction as published, see
            :data:`AS_PUBLISHED`).
        kalman: Whether UAVs and obstacle tracks are Kalman filtered; off, the raw noisy
            measurements are used as estimates.
    """

    horizon: float = 10.0  # s
    mode: str = "swept"
    fit: str = "calibrated"
    kalman: bool = True

    def __post_init__(self) -> None:
        check_positive("prediction.horizon", self.horizon, hi=600.0)
        check_one_of("prediction.mode", self.mode, ("swept", "terminal"))
        check_one_of("prediction.fit", self.fit, ("enclosing", "paper", "calibrated"))
        if self.fit == "calibrated":
            check(
                any(abs(self.horizon - h) < 1e-9 for h in CALIBRATED_HORIZONS),
                "prediction.horizon",
                self.horizon,
                f"must be one of {list(CALIBRATED_HORIZONS)} s with prediction.fit="
                "'calibrated' (the horizons its shipped table calibrates)",
            )
        check(isinstance(self.kalman, bool), "prediction.kalman", self.kalman, "must be a bool")


@dataclass(frozen=True, kw_only=True)
class ObservationConfig:
    """What each agent observes (see :mod:`uasep_env.interface.observation`).

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
        optional_features: Optional features to add to the vector (keys of
            :data:`uasep_env.interface.observation_layout.OPTIONAL_FEATURES`; checked when the
            layout is built). None by default.
    """

    k_uavs: int | None = None
    k_obstacles: int | None = None
    position_scale: float = 100.0  # m
    clip: float = 12.0
    sensing_range: float = 1000.0  # m
    optional_features: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        feats = self.optional_features
        check(
            isinstance(feats, (tuple, list)) and all(isinstance(f, str) for f in feats),
            "observation.optional_features",
            feats,
            "must be a list of feature names",
        )
        object.__setattr__(self, "optional_features", tuple(feats))
        if self.k_uavs is not None:
            check_int_in("observation.k_uavs", self.k_uavs, 1, 31)
        if self.k_obstacles is not None:
            check_int_in("observation.k_obstacles", self.k_obstacles, 1, 8)
        check_positive("observation.position_scale", self.position_scale, hi=MAX_OBS)
        check_positive("observation.clip", self.clip, hi=MAX_OBS)
        check_positive("observation.sensing_range", self.sensing_range, hi=MAX_OBS)
        reach = self.clip * self.position_scale
        check(
            self.sensing_range <= reach,
            "observation.sensing_range",
            self.sensing_range,
            f"must be <= observation.clip * observation.position_scale ({reach:g} m): "
            "farther objects would be observed with clipped distances",
        )


@dataclass(frozen=True, kw_only=True)
class RewardWeights:
    """Weights of the named reward terms (see :mod:`uasep_env.interface.rewards`).

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
        deviation_scale: The deviation term's scale (m): the term is ``-d / (d + scale)``,
            -1/2 at ``d = scale``. Larger keeps more of its slope far from the plan (a
            policy 100 m off is paid more to come back), still bounded in ``(-1, 0]``.
    """

    # Defaults: a step's reward is in [0, 1] and a collision costs a whole episode (why:
    # uasep_env.interface.rewards).
    separation_inner: float = 0.25
    separation_obstacle: float = 0.4
    separation_region: float = 0.05
    deviation: float = 0.2
    control: float = 0.0
    smoothness: float = 0.0125
    collision: float = 1.0
    progress: float = 1.0
    shared: float = 0.0
    deviation_scale: float = 20.0  # m (uasep_env.interface.rewards.DEVIATION_SCALE_M)

    def __post_init__(self) -> None:
        for f in fields(self):
            check_finite(f"reward.{f.name}", getattr(self, f.name), MAX_WEIGHT)
        check(0.0 <= self.shared <= 1.0, "reward.shared", self.shared, "must be in [0, 1]")
        check(
            0.1 <= self.deviation_scale <= 1e5, "reward.deviation_scale", self.deviation_scale,
            "must be in [0.1, 1e5] m",
        )  # fmt: skip

    @classmethod
    def task(cls) -> RewardWeights:
        """The task reward for constrained training: no separation or collision terms.

        The default weights of ``deviation``, ``control``, ``smoothness`` and ``progress``,
        every separation term and the collision term at 0: safety is left to the cost
        channel (:mod:`uasep_env.interface.costs`) and its constraint. A step alive still earns
        between 0.75 and 1 (``uasep_env.interface.rewards.reward_bounds``), so ending an episode
        early (a collision, a lost UAV) never pays. ``make_config(reward="task")``.
        """
        return cls(separation_inner=0.0, separation_obstacle=0.0, separation_region=0.0,
                   collision=0.0)  # fmt: skip

    @classmethod
    def preset(cls, name: str) -> RewardWeights:
        """The named weights of :data:`REWARD_PRESETS` (``make_config(reward=name)``).

        Raises:
            ValueError: An unknown name, named with the presets.
        """
        check(name in REWARD_PRESETS, "reward", name, f"must be one of {REWARD_PRESETS} or a dict")
        return cls() if name == "default" else cls.task()


#: Names ``reward=`` accepts in place of a dict (:meth:`RewardWeights.preset`): the default
#: weights, or the task reward of constrained training (:meth:`RewardWeights.task`).
REWARD_PRESETS = ("default", "task")


@dataclass(frozen=True, kw_only=True)
class CostWeights:
    """Weights of the named cost terms (see :mod:`uasep_env.interface.costs`).

    Each agent's cost in a step is ``sum_k w_k * term_k``, each term an indicator (1 in a
    step in which the condition holds, else 0), so a weight is a cost per environment step
    (dimensionless). The cost changes no reward and no episode; constrained training
    (:mod:`uasep_env.training.lagrangian`) bounds its expected sum over an episode.

    Attributes:
        separation_uav: Cost per step in loss of separation with another UAV (closer than
            ``uav.separation_distance`` during the step).
        separation_obstacle: Cost per step in loss of separation with an obstacle (closer
            than ``uav.obstacle_separation`` during the step).
        region: Cost per step inside an obstacle's predicted reachable region (0 by
            default: the region is a prediction, not a loss of separation; with a weight,
            the cost is also positive inside it).
    """

    separation_uav: float = 1.0  # cost per step
    separation_obstacle: float = 1.0  # cost per step
    region: float = 0.0  # cost per step

    def __post_init__(self) -> None:
        for f in fields(self):
            check_positive(f"cost.{f.name}", getattr(self, f.name), allow_zero=True, hi=MAX_WEIGHT)


#: Names accepted for ``ActionConfig.mode`` (see :mod:`uasep_env.interface.actions`).
ACTION_MODES = ("direct", "residual_apf", "residual_mvp_region")


@dataclass(frozen=True, kw_only=True)
class ActionConfig:
    """What an agent's action means (see :mod:`uasep_env.interface.actions`).

    Attributes:
        mode: ``"direct"``: the action is the commanded acceleration, as a fraction of
            ``uav.max_accel`` per axis. ``"residual_apf"``: the action is a bounded
            correction added to the paper's APF command for the same observation; the
            observation then ends with that APF command (3 more entries).
            ``"residual_mvp_region"``: the same on MVP with obstacles on their predicted
            regions (the leaderboard's best classical controller).
        residual_scale: In the residual modes, the largest correction per axis, as a
            fraction of ``uav.max_accel`` (the sum is clipped to the acceleration bound).
        strict: Finite actions outside the action box ``[-1, 1]`` raise a ``ValueError``
            naming them. Off (the default, the ecosystem's convention), they are clipped to
            the box and counted in the step's infos (``clipped_actions``).
    """

    mode: str = "direct"
    residual_scale: float = 0.5  # fraction of uav.max_accel
    strict: bool = False

    def __post_init__(self) -> None:
        check(self.mode in ACTION_MODES, "action.mode", self.mode, f"must be one of {ACTION_MODES}")
        check_finite("action.residual_scale", self.residual_scale)
        check(
            0.0 < self.residual_scale <= 2.0,
            "action.residual_scale",
            self.residual_scale,
            "must be in (0, 2]",
        )
        check(isinstance(self.strict, bool), "action.strict", self.strict, "must be a bool")
