"""The whole configuration, :class:`EnvConfig`, and :func:`make_config`, which builds it.

:func:`make_config` builds an :class:`EnvConfig` from keyword arguments or a (nested) dict;
unknown keys raise a :class:`TypeError` (Python's convention for an unexpected keyword) and
invalid or out-of-range values a :class:`ValueError`, each naming the dotted field. Also the
names the top-level fields accept (:data:`SCENARIOS`, read from the scenario registry, and
:data:`FORMATION_PATTERNS`) and the
overrides of the paper's prediction as published (:data:`AS_PUBLISHED`) and of each env
version's defaults (:data:`VERSION_DEFAULTS`).

Units are SI throughout: metres (m), seconds (s), radians (rad), m/s, m/s^2.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any, TypeVar

from uasep_env.config.checks import (
    MAX_DIST,
    MAX_SPEED,
    MAX_STEPS,
    MAX_TIME,
    MIN_DT,
    MIN_SPEED,
    check,
    check_int_in,
    check_one_of,
    check_positive,
    check_vector,
    is_sequence,
)
from uasep_env.config.groups import (
    ActionConfig,
    AirspaceConfig,
    CostWeights,
    NoiseConfig,
    ObservationConfig,
    ObstacleConfig,
    PredictionConfig,
    RewardWeights,
    UAVConfig,
)
from uasep_env.scenarios.registry import get_family, scenario_names

__all__ = [
    "AS_PUBLISHED",
    "FORMATION_PATTERNS",
    "SCENARIOS",  # noqa: F822 (read by __getattr__ below)
    "VERSION_DEFAULTS",
    "EnvConfig",
    "make_config",
]

#: Names accepted for ``EnvConfig.formation`` (see :mod:`uasep_env.sim.formation`).
FORMATION_PATTERNS = ("line_abreast", "paper", "column", "v", "wedge", "grid", "circle")


def __getattr__(name: str) -> Any:
    # SCENARIOS: the registered scenario families, read from the registry when asked for
    # (importing the registry registers the families: the scenarios package's init).
    if name == "SCENARIOS":
        return scenario_names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Overrides that run the paper's prediction as published: the terminal set S1..S5 and the
#: paper's (non-enclosing) ellipsoid of eqs. 17-18. ``make_config(AS_PUBLISHED,
#: scenario="paper")``; on the command line ``--config prediction.mode=terminal --config
#: prediction.fit=paper``.
AS_PUBLISHED: dict[str, dict[str, str]] = {"prediction": {"mode": "terminal", "fit": "paper"}}

#: Overrides that give each env version's defaults from today's (``make_config(
#: VERSION_DEFAULTS[2], scenario="random")`` plays the ``-v2`` episodes bit for bit; the
#: ``uasep/...-v2`` ids are registered with them). Versions 0 and 1 are not reproducible
#: (their dynamics changed in code, not in a default).
VERSION_DEFAULTS: dict[int, dict[str, dict[str, str]]] = {
    3: {},
    # -v3 made the calibrated prediction the default; -v2 predicted the enclosing region.
    2: {"prediction": {"fit": "enclosing"}},
}

T = TypeVar("T")


@dataclass(frozen=True, kw_only=True)
class EnvConfig:
    """The whole configuration of a world / environment.

    Attributes:
        n_uavs: Number of cooperative UAVs (2-64).
        n_obstacles: Number of obstacle slots (0-8). Scenarios may leave some inactive.
        scenario: Scenario family, one of the registered families (:data:`SCENARIOS`, see
            :mod:`uasep_env.scenarios`).
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
        airspace: The ground, the obstacles' placement margin above it and the ceiling.
        prediction: Reachable-set prediction and filtering.
        observation: Observation options.
        reward: Reward weights (or a preset's name: ``"default"``, ``"task"``).
        cost: Cost weights (the cost channel of constrained training; changes no reward).
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
    airspace: AirspaceConfig = field(default_factory=AirspaceConfig)
    prediction: PredictionConfig = field(default_factory=PredictionConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    reward: RewardWeights = field(default_factory=RewardWeights)
    cost: CostWeights = field(default_factory=CostWeights)
    action: ActionConfig = field(default_factory=ActionConfig)
    render_mode: str | None = None

    def __post_init__(self) -> None:
        check_int_in("n_uavs", self.n_uavs, 2, 64)
        check_int_in("n_obstacles", self.n_obstacles, 0, 8)
        check_one_of("scenario", self.scenario, scenario_names())
        if isinstance(self.formation, str):
            check(
                self.formation in FORMATION_PATTERNS,
                "formation",
                self.formation,
                f"must be one of {FORMATION_PATTERNS} or a tuple of (x, y, z) slots",
            )
        else:
            check(
                is_sequence(self.formation) and len(self.formation) == self.n_uavs,
                "formation",
                self.formation,
                f"explicit pattern must have shape ({self.n_uavs}, 3): one (x, y, z) per UAV",
            )
            slots = tuple(
                check_vector(f"formation[{i}]", row, 3, MAX_DIST)
                for i, row in enumerate(self.formation)  # type: ignore[arg-type]
            )
            object.__setattr__(self, "formation", slots)
        check_positive("formation_spacing", self.formation_spacing, hi=MAX_DIST)
        check_positive("cruise_speed", self.cruise_speed, lo=MIN_SPEED, hi=MAX_SPEED)
        check(
            self.cruise_speed <= self.uav.max_speed,
            "cruise_speed",
            self.cruise_speed,
            f"must be <= uav.max_speed ({self.uav.max_speed})",
        )
        check_positive("dt", self.dt, lo=MIN_DT, hi=5.0)
        check_int_in("decision_interval", self.decision_interval, 1, 1000)
        check_positive("episode_duration", self.episode_duration, hi=MAX_TIME)
        check(
            self.episode_duration >= self.dt * self.decision_interval,
            "episode_duration",
            self.episode_duration,
            "must be at least one environment step",
        )
        steps = self.episode_duration / (self.dt * self.decision_interval)
        check(
            steps <= MAX_STEPS,
            "episode_duration",
            self.episode_duration,
            f"is {steps:.3g} steps of dt * decision_interval = {self.dt * self.decision_interval:g}"
            f" s; at most {MAX_STEPS:,} steps per episode",
        )
        check_one_of("render_mode", self.render_mode, (None, "human", "rgb_array"))
        for name, cls in _NESTED.items():
            check(
                isinstance(getattr(self, name), cls),
                name,
                getattr(self, name),
                f"must be a {cls.__name__} (use make_config to build from dicts)",
            )
        # The scenario places the obstacles for one motion model (recorded tracks: replay);
        # an unset model is the scenario's.
        needs = get_family(self.scenario).obstacle_model
        if self.obstacle.model is None:
            object.__setattr__(self, "obstacle", dataclasses.replace(self.obstacle, model=needs))
        check(
            self.obstacle.model == needs,
            "obstacle.model",
            self.obstacle.model,
            f"scenario={self.scenario!r} needs obstacle.model={needs!r}"
            + (" (recorded tracks: scenario 'real_traffic')" if needs == "dubins" else ""),
        )
        check(
            self.action.mode == "direct" or self.observation.clip >= 1.0,
            "observation.clip",
            self.observation.clip,
            f"must be >= 1 with action.mode={self.action.mode!r} (the observed base command is "
            "in [-1, 1])",
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
    "airspace": AirspaceConfig,
    "prediction": PredictionConfig,
    "observation": ObservationConfig,
    "reward": RewardWeights,
    "cost": CostWeights,
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
            elif isinstance(value, str) and sub is RewardWeights:
                value = RewardWeights.preset(value)
            elif isinstance(value, Mapping):
                value = _build(sub, current.get(key, sub()), value, prefix + key + ".")
            elif not isinstance(value, sub):
                raise ValueError(
                    f"invalid config value {prefix}{key}={value!r}: "
                    f"must be a dict or {sub.__name__}"
                )
        current[key] = value
    if cls is EnvConfig and "scenario" in values and not _names_model(values.get("obstacle")):
        # A new scenario brings its own obstacle model unless one is given with it.
        current["obstacle"] = dataclasses.replace(current["obstacle"], model=None)
    return cls(**current)


def _names_model(obstacle: Any) -> bool:
    """Whether an ``obstacle`` override sets ``model`` (a dict naming it, or a whole group)."""
    return isinstance(obstacle, ObstacleConfig) or (
        isinstance(obstacle, Mapping) and "model" in obstacle
    )


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

    Examples:
        >>> cfg = make_config(scenario="crossing", noise={"position_std": 1.0})
        >>> cfg.scenario, cfg.noise.position_std, cfg.n_uavs
        ('crossing', 1.0, 3)
        >>> make_config(uav={"max_speed": -1})
        Traceback (most recent call last):
        ...
        ValueError: invalid config value uav.max_speed=-1: must be > 0
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
