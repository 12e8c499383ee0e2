"""The frame of a controller that modifies the shared plan tracking: MVP, ORCA, the CBF-QP.

Each holds its config, its parameters (a frozen dataclass with a ``margin_scale`` field, the
trade-off sweep's knob), the observation layout it decodes with and the tracking gains of
every reference controller (:data:`~uasep_env.policies.apf.APF.default_gains`), and bounds
its command like every controller (:func:`~uasep_env.policies.nominal.bounded_action`). One
copy of that frame, so the methods differ only in how they resolve conflicts.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies.apf import APF, APFGains
from uasep_env.policies.nominal import bounded_action

__all__ = ["TrackingController"]


class TrackingController:
    """Config, parameters, layout and tracking gains; the bounded command; the margin sweep.

    Args:
        config: The environment config (observation layout, bounds, separation radii).
        params: An instance of :attr:`params_type` (default: its defaults).
    """

    #: The parameters dataclass (a ``margin_scale`` field scales the safety distances).
    params_type: ClassVar[type]

    def __init__(self, config: EnvConfig, params: Any = None) -> None:
        self.config = config
        self.params = params if params is not None else self.params_type()
        self.layout = ObservationLayout.from_config(config)
        self.tracking: APFGains = APF.default_gains

    @classmethod
    def with_margin(cls, config: EnvConfig, scale: float) -> Any:
        """The controller with its safety distances scaled (the registry's ``margin``)."""
        return cls(config, cls.params_type(margin_scale=scale))

    def separations(self, uav: float | None, obstacle: float | None) -> tuple[float, float]:
        """The protected radii between UAVs and from an obstacle's centre (m), before margins.

        A parameter left None is the config's separation threshold (``uav.separation_distance``,
        ``uav.obstacle_separation``): the method has no zone of its own.
        """
        c = self.config.uav
        return (
            uav if uav is not None else c.separation_distance,
            obstacle if obstacle is not None else c.obstacle_separation,
        )

    def reset(self) -> None:
        """Memoryless: recomputed every step."""

    def bounded(self, accel: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Commanded accelerations (m/s^2) as normalised actions under the config's bounds."""
        uav = self.config.uav
        return bounded_action(
            accel, velocity, uav.max_speed, uav.max_accel, self.config.step_duration
        )
