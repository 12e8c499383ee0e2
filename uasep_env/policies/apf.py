"""The paper's improved artificial potential field (APF) and its two comparison methods.

All three act on the environments' observations (decoded to SI units by
:class:`~uasep_env.interface.observation.ObservationLayout`), batched over any leading shape such as
``(n_envs, n_uavs)``, and return normalised accelerations in ``[-1, 1]^3``.

:class:`APF` -- the proposed method (paper eqs. 19-32, with the notes' errata):

* attraction (eqs. 19-22): ``F_att = K_g sat(p_g - p_o) + K_p (p_d - p) + K_v (v_d - v)
  - K_d (v - v_o)``. ``p_g`` is the planned position of the formation centre now (a key
  point of the planned trajectory; the goal term is saturated at ``goal_saturation`` so a
  far goal cannot demand unbounded force), ``p_d`` the slot of eq. 7, ``v_d`` the planned
  velocity. Eq. 21's damping ``-K v`` is applied to the velocity relative to the formation
  (``v - v_o``): it damps the oscillation about the slot that the paper describes, without
  the steady lag that damping the absolute velocity of a cruising formation would cause.
* obstacle repulsion (eqs. 23-25): from the obstacle's predicted reachable ellipsoid,
  ``F = K_obs (1/d - 1/r_safe) n`` for ``d < r_safe``, with ``d`` the true distance to the
  ellipsoid's surface (the notes: eq. 25's ``r_elli`` only bounds it) and ``n`` the outward
  normal at the nearest surface point. The safe distance grows with the approach speed,
  ``r_safe = r_min + K_t v cos(delta)`` for ``delta`` in ``[0, pi/2]`` (eq. 24; measured from
  the surface, so ``r_elli`` is already included). The force is active only when the UAV,
  flying straight on, is predicted to come within ``r_min`` of the region within the
  horizon ``K_s`` (or already is) -- otherwise it keeps its motion, as the paper says.
* inner repulsion (eqs. 26-30, garbled in the paper; the notes' intent): for a UAV ``j``
  closer than ``r_inner = 2 r_min_inner + K_safe s`` (eq. 29; ``s`` = approach speed
  ``|v_j - v_i| cos(delta)`` when closing, else 0),
  ``F_ij = (1/d - 1/r_inner) (alpha u + beta (v_j - v_i))`` with ``u`` the unit vector from
  ``j`` to ``i``; the velocity part only acts while closing. Both parts have a non-negative
  component along ``u``, so the force always pushes the pair apart (tested).
* bounds: each axis is clipped to ``a_max`` and the component along the velocity is capped
  so that the speed stays below ``V_max`` after the step (eq. 4).

:class:`MotionStateAPF` -- the authors' earlier method: the same structure without
trajectory prediction; the obstacle is a sphere of radius ``r`` around its current
position, the safe distance grows with the relative approach speed, always active.

:class:`TraditionalAPF` -- distance-only repulsion (Khatib's potential,
``F = eta (1/rho - 1/rho_0) / rho^2``) from the obstacle's current position and between
UAVs, with fixed influence distances.

The attraction is the same for the three methods, so the comparison isolates how each
treats conflicts. Gains are not given in the paper. :class:`APFGains` holds the reference
gains, with their units; the gains that set each method's safety margin were then swept
(``baselines/tradeoff.py``) and each method's ``default_gains`` is the knee of its own
safety/efficiency front, so the three are compared at their best trade-offs, not at one
shared margin.
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numpy as np

from uasep_env import reachable
from uasep_env._deprecation import RenamedAttributes, warn_renamed
from uasep_env._numba import compiled_twin
from uasep_env.config import EnvConfig
from uasep_env.config.checks import check_positive
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies.nominal import bounded_action, plan_tracking
from uasep_env.policies.registry import register_policy
from uasep_env.reachable.distance import _N_NEWTON
from uasep_env.reachable.distance import _check_axes as check_semi_axes

__all__ = ["APF", "APFGains", "MotionStateAPF", "TraditionalAPF"]

# Fractions of the horizon at which the straight-line prediction is checked.
_PREDICTION_SAMPLES = np.linspace(0.0, 1.0, 11)
# Gains that divide or bound a distance must be > 0; the others may be 0 (term off).
_POSITIVE_GAINS = frozenset({"goal_saturation", "obstacle_safe_min", "horizon", "inner_safe_min"})
_GAIN_MAX = 1e6  # any larger gain is a typo, whatever its unit


#: Gains renamed after 0.1.0 (``obs`` also means observation): the old names still work as
#: keywords, in :meth:`APFGains.scaled` and as attributes, with a DeprecationWarning.
RENAMED_GAINS = {
    "k_obs": "k_obstacle",
    "obs_safe_min": "obstacle_safe_min",
    "obs_time": "obstacle_time",
}


def _new_gain_names(names: dict[str, Any] | Sequence[str], stacklevel: int) -> Any:
    """``names`` (keywords or a sequence of names) with old gain names renamed, warning."""
    items = names.items() if isinstance(names, dict) else ((n, None) for n in names)
    out = {}
    for name, value in items:
        new = RENAMED_GAINS.get(name)
        if new is not None:
            warn_renamed(f"APFGains.{name}", f"APFGains.{new}", stacklevel)
            if new in out or (isinstance(names, dict) and new in names):
                raise TypeError(f"APFGains got both {name!r} and its new name {new!r}")
            name = new
        out[name] = value
    return out if isinstance(names, dict) else tuple(out)


@dataclass(frozen=True, kw_only=True)
class APFGains(RenamedAttributes):
    """Gains of the APF controllers (units in brackets; accelerations in m/s^2).

    Attributes:
        k_goal: ``K_g`` [1/s^2], pull of the formation centre towards the planned centre.
        goal_saturation: Distance beyond which the goal term stops growing [m].
        k_slot: ``K_p`` [1/s^2], pull towards the formation slot (eq. 19).
        k_vel: ``K_v`` [1/s], velocity matching with the planned velocity (eq. 20).
        k_damp: ``K`` of eq. 21 [1/s], damping of the velocity relative to the formation.
        k_obstacle: ``K_obs`` [m^2/s^2], obstacle repulsion (eq. 23).
        obstacle_safe_min: ``r_safe^min`` [m], safe distance from the reachable region (eq. 24).
        obstacle_time: ``K`` of eq. 24 [s], growth of the safe distance with approach speed.
        horizon: ``K_s`` [s], look-ahead of the entry prediction.
        alpha: Weight of the line-of-sight part of the inner repulsion [m^2/s^2].
        beta: Weight of the relative-velocity part of the inner repulsion [m/s].
        inner_safe_min: ``r_safe^min`` of eq. 29 [m]; the base inner distance is twice it.
        k_safe: ``K_safe`` of eq. 29 [s], growth of the inner distance with approach speed.
        traditional_eta: ``eta`` of the traditional APF [m^4/s^2].
        traditional_range: ``rho_0`` of the traditional APF from obstacles [m].
        traditional_inner_range: ``rho_0`` of the traditional APF between UAVs [m].
        max_repulsion: Cap on the norm of each repulsive force [m/s^2] (before the
            acceleration bound), so a singular ``1/d`` stays finite.
    """

    k_goal: float = 0.04
    goal_saturation: float = 15.0
    k_slot: float = 0.08
    k_vel: float = 0.6
    k_damp: float = 0.3
    k_obstacle: float = 40.0
    obstacle_safe_min: float = 6.0
    obstacle_time: float = 2.0
    horizon: float = 10.0
    alpha: float = 30.0
    beta: float = 3.0
    inner_safe_min: float = 5.0
    k_safe: float = 2.0
    traditional_eta: float = 4000.0
    traditional_range: float = 25.0
    traditional_inner_range: float = 10.0
    max_repulsion: float = 20.0

    def __post_init__(self) -> None:
        # The config's range checks, so a bad gain reads like a bad config value.
        for f in fields(self):
            check_positive(
                f"gains.{f.name}",
                getattr(self, f.name),
                allow_zero=f.name not in _POSITIVE_GAINS,
                hi=_GAIN_MAX,
            )

    _RENAMED: ClassVar[dict[str, str]] = RENAMED_GAINS

    def scaled(self, names: Sequence[str], factor: float) -> APFGains:
        """These gains with the named ones multiplied by ``factor`` (the trade-off sweeps)."""
        names = _new_gain_names(names, stacklevel=4)
        return replace(self, **{n: getattr(self, n) * factor for n in names})


_dataclass_init = APFGains.__init__


@functools.wraps(_dataclass_init)
def _init_accepting_old_names(self: APFGains, *args: Any, **kwargs: Any) -> None:
    _dataclass_init(self, *args, **_new_gain_names(kwargs, stacklevel=4))


APFGains.__init__ = _init_accepting_old_names  # type: ignore[method-assign]


def _unit(v: np.ndarray, eps: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    n = np.sqrt(np.einsum("...i,...i->...", v, v))
    return v / np.maximum(n, eps)[..., None], n


def _cap_norm(f: np.ndarray, cap: float) -> np.ndarray:
    n = np.sqrt(np.einsum("...i,...i->...", f, f))
    return f * np.minimum(1.0, cap / np.maximum(n, 1e-12))[..., None]


def _inner_repulsion(o: dict[str, np.ndarray], g: APFGains) -> np.ndarray:
    """Eqs. 26-30 (:meth:`_APFBase.inner_repulsion`)."""
    rel = o["uav_rel_pos"]  # p_j - p_i
    relv = o["uav_rel_vel"]  # v_j - v_i
    away, d = _unit(-rel)  # from j towards i
    closing = np.maximum(0.0, np.einsum("...i,...i->...", relv, away))  # s >= 0
    r_inner = 2.0 * g.inner_safe_min + g.k_safe * closing
    dd = np.maximum(d, 0.1)
    mag = np.where((d < r_inner) & o["uav_mask"], 1.0 / dd - 1.0 / r_inner, 0.0)
    vel_part = np.where((closing > 0.0)[..., None], relv, 0.0)
    f = mag[..., None] * (g.alpha * away + g.beta * vel_part)
    return _cap_norm(f, g.max_repulsion).sum(axis=-2)


class _APFBase(ABC):
    """Shared machinery: decoding, attraction, inner repulsion and the bounds.

    Args:
        config: The environment config (layout, bounds and step duration).
        gains: Controller gains (default: the class's :attr:`default_gains`).
    """

    name = "apf-base"
    #: The gains that set the method's safety margin (what its trade-off curve sweeps).
    margin_gains: ClassVar[tuple[str, ...]] = ("obstacle_safe_min", "obstacle_time")
    #: The gains used when none are given; each method's come from its trade-off curve.
    default_gains: ClassVar[APFGains] = APFGains()

    def __init__(self, config: EnvConfig, gains: APFGains | None = None) -> None:
        self.config = config
        self.gains = gains if gains is not None else self.default_gains
        self.layout = ObservationLayout.from_config(config)
        self.max_accel = config.uav.max_accel
        self.max_speed = config.uav.max_speed
        self.dt = config.step_duration

    def reset(self) -> None:  # noqa: B027 -- a deliberate no-op: the APFs are memoryless
        """The APFs are memoryless."""

    @classmethod
    def with_margin(cls, config: EnvConfig, scale: float) -> _APFBase:
        """The method with its :attr:`margin_gains` scaled from the reference gains."""
        return cls(config, APFGains().scaled(cls.margin_gains, scale))

    # -- pieces --------------------------------------------------------------------
    def attraction(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Eqs. 19-22: goal, slot, velocity matching and damping (m/s^2).

        :func:`~uasep_env.policies.nominal.plan_tracking`, the nominal command every
        reference controller shares.
        """
        return plan_tracking(o, self.gains)

    def inner_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Eqs. 26-30: relative-motion repulsion from the other UAVs (m/s^2)."""
        return _inner_repulsion(o, self.gains)

    @abstractmethod
    def obstacle_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Repulsion from the obstacles (method-specific), (..., 3) in m/s^2."""

    def bound(self, accel: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Eq. 4 and the acceleration bound; returns normalised actions."""
        return bounded_action(accel, velocity, self.max_speed, self.max_accel, self.dt)

    def forces(self, observations: np.ndarray) -> dict[str, np.ndarray]:
        """Every force term (m/s^2) for the observations, by name (for analysis/tests)."""
        o = self.layout.decode(observations)
        return {
            "attraction": self.attraction(o),
            "obstacle": self.obstacle_repulsion(o),
            "inner": self.inner_repulsion(o),
        }

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(..., 3)`` for observations ``(..., obs_dim)``."""
        observations = np.asarray(observations)
        o = self.layout.decode(observations)
        total = self.attraction(o) + self.obstacle_repulsion(o) + self.inner_repulsion(o)
        return self.bound(total, o["velocity"]).astype(np.float32)


@register_policy("apf", label="APF (proposed)", reference=True, default_margin=2.0)
class APF(_APFBase):
    """The paper's method: reachable-set repulsion with entry prediction (eqs. 19-32).

    Default gains: ``obstacle_safe_min`` 12 m and ``obstacle_time`` 4 s, twice the
    reference :class:`APFGains` (the knee of the APF's trade-off front on the ``-v3``
    validation bank, ``baselines/tradeoff.py``, ``docs/figures/tradeoff.md``). With the
    calibrated prediction every margin scale of 0.5-3 loses separation in 1 of 200
    encounters and none collides; the front of max deviation against min UAV-obstacle
    distance is nearly straight, so the knee is weakly determined (scales 0.75 and 1 come
    within 3 % and 8 % of its distance from the chord). The paper gives no gains;
    ``APF(config, APFGains())`` flies the reference ones.

    Args:
        config: The environment config (layout, bounds and step duration).
        gains: Controller gains (default: :attr:`default_gains`).
    """

    name = "apf"
    default_gains = APFGains().scaled(_APFBase.margin_gains, 2.0)

    def obstacle_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Eqs. 23-25 with entry prediction over the horizon ``K_s``."""
        return _obstacle_repulsion(o, self.gains)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(..., 3)`` for observations ``(..., obs_dim)``.

        One compiled call when numba is in use and no piece is overridden (a subclass's own
        pieces run as numpy, :meth:`_APFBase.__call__`).
        """
        if not _plain(type(self)):
            return super().__call__(observations)
        observations = np.asarray(observations)
        _check_observations(observations, self.layout)
        actions = _apf_actions(
            observations, self.layout, self.gains, self.max_speed, self.max_accel, self.dt
        )
        return actions.astype(np.float32)


def _check_observations(observations: np.ndarray, layout: ObservationLayout) -> None:
    """The numpy form's checks, made before the compiled call.

    :meth:`ObservationLayout.decode`'s width, and the distance solve's semi-axes.

    Raises:
        ValueError: A width other than the layout's; a region's semi-axis NaN or infinite.
    """
    if observations.shape[-1] != layout.dim:
        raise ValueError(f"observation width must be {layout.dim}, got {observations.shape[-1]}")
    cols, scale = layout.feature_columns("obstacle_axes")
    check_semi_axes(np.maximum(observations[..., cols].astype(float) * scale, 1e-3))


def _plain(cls: type) -> bool:
    """Whether ``cls`` uses :class:`APF`'s pieces as they are (what the kernel computes)."""
    return (
        cls.attraction is _APFBase.attraction
        and cls.inner_repulsion is _APFBase.inner_repulsion
        and cls.obstacle_repulsion is APF.obstacle_repulsion
        and cls.bound is _APFBase.bound
    )


def _obstacle_repulsion(o: dict[str, np.ndarray], g: APFGains) -> np.ndarray:
    """Eqs. 23-25 (:meth:`APF.obstacle_repulsion`)."""
    center = o["obstacle_center"]  # ellipsoid centre relative to the UAV
    axes = np.maximum(o["obstacle_axes"], 1e-3)
    cs = o["obstacle_heading_cs"]
    heading = np.arctan2(cs[..., 1], cs[..., 0])
    mask = o["obstacle_mask"]
    origin = np.zeros_like(center)
    d, normal = reachable.distance_to_ellipsoid(origin, center, axes, heading, return_normal=True)
    # Approach speed towards the region: velocity against the outward normal.
    v_hat, speed = _unit(o["velocity"])
    cos_delta = np.einsum("...ki,...i->...k", -normal, v_hat)
    approach = np.where(cos_delta > 0.0, speed[..., None] * cos_delta, 0.0)
    r_safe = g.obstacle_safe_min + g.obstacle_time * approach
    dd = np.maximum(d, 0.5)  # inside the region: the strongest push, outwards
    near = mask & (d < r_safe)
    # Straight-line prediction: does the UAV come within r_min of the region? Only asked
    # where the force could act at all (usually a few UAVs of a batch).
    will_enter = np.zeros_like(near)
    if near.any():
        idx = np.nonzero(near)
        vel = np.broadcast_to(o["velocity"][..., None, :], center.shape)[idx]  # (P, 3)
        future = vel[:, None, :] * (_PREDICTION_SAMPLES * g.horizon)[:, None]  # (P, S, 3)
        d_future = reachable.distance_to_ellipsoid(
            future, center[idx][:, None, :], axes[idx][:, None, :], heading[idx][:, None]
        )
        will_enter[idx] = d_future.min(axis=-1) < g.obstacle_safe_min
    active = near & will_enter
    mag = np.where(active, g.k_obstacle * (1.0 / dd - 1.0 / r_safe), 0.0)
    f = mag[..., None] * normal
    return _cap_norm(f, g.max_repulsion).sum(axis=-2)


@compiled_twin("apf_actions", samples=_PREDICTION_SAMPLES, n_newton=_N_NEWTON)
def _apf_actions(
    observations: np.ndarray,
    layout: ObservationLayout,
    gains: APFGains,
    max_speed: float,
    max_accel: float,
    dt: float,
) -> np.ndarray:
    """:class:`APF`'s decision: normalised accelerations ``(..., 3)``, float64.

    :meth:`_APFBase.__call__` with :class:`APF`'s pieces, as one function of arrays and
    numbers: compiled as ``apf_actions`` (an evaluation at a few dozen environments spent
    about half its time in the numpy form's small calls).
    """
    o = layout.decode(observations)
    total = plan_tracking(o, gains) + _obstacle_repulsion(o, gains) + _inner_repulsion(o, gains)
    return bounded_action(total, o["velocity"], max_speed, max_accel, dt)


@register_policy(
    "motion-state-apf",
    label="motion-state APF",
    reference=True,
    default_margin=1.0,
)
class MotionStateAPF(_APFBase):
    """The authors' earlier method [23]: motion-state repulsion, no trajectory prediction.

    The obstacle is a sphere of its safety radius around its current (estimated) position;
    the safe distance grows with the relative approach speed; always active inside it.

    Default gains: the reference :class:`APFGains` (``obstacle_safe_min`` 6 m,
    ``obstacle_time`` 2 s), the knee of its trade-off front on the ``-v3``
    validation bank (``baselines/tradeoff.py``, ``docs/figures/tradeoff.md``): collisions
    fall from 23.5 % at a quarter of the margin to 10.5 % at the knee and 7.5 % at three
    times it, while the max deviation grows from 6.5 to 10.6 and 15.7 m. It does not read
    the prediction, so ``-v3`` changed only the bank its knee is read on (``-v2``'s: 1.5).
    """

    name = "motion-state-apf"
    default_gains = APFGains().scaled(_APFBase.margin_gains, 1.0)

    def obstacle_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Repulsion from the obstacle's current position and motion."""
        g = self.gains
        rel = o["obstacle_rel_pos"]  # obstacle - UAV
        away, dist = _unit(-rel)
        radius = self.config.obstacle.radius
        d = dist - radius
        relv = o["obstacle_rel_vel"]  # v_obs - v_i
        closing = np.maximum(0.0, np.einsum("...ki,...ki->...k", relv, away))
        r_safe = g.obstacle_safe_min + g.obstacle_time * closing
        dd = np.maximum(d, 0.5)
        active = o["obstacle_mask"] & (d < r_safe)
        mag = np.where(active, g.k_obstacle * (1.0 / dd - 1.0 / r_safe), 0.0)
        return _cap_norm(mag[..., None] * away, g.max_repulsion).sum(axis=-2)


@register_policy(
    "traditional-apf",
    label="traditional APF",
    reference=True,
    default_margin=0.5,
    knob="range scale",
)
class TraditionalAPF(_APFBase):
    """Distance-only APF (Khatib): ``eta (1/rho - 1/rho_0) / rho^2`` away from each source.

    Default gains: ``traditional_range`` (``rho_0`` from obstacles) 12.5 m, half the
    reference 25 m, the knee of its trade-off front on the ``-v3`` validation bank
    (``baselines/tradeoff.py``, ``docs/figures/tradeoff.md``): collisions 10.5 % there
    against 16.5 % at a quarter of the range and 9.5-10 % at longer ranges, while the
    deviation keeps growing (12 m at the knee, 16 m at three times the range). It does not
    read the prediction, so ``-v3`` changed only the bank its knee is read on (``-v2``'s:
    0.75).
    """

    name = "traditional-apf"
    margin_gains = ("traditional_range",)
    default_gains = APFGains().scaled(margin_gains, 0.5)

    def obstacle_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Repulsion from the obstacle's current position, by distance only."""
        g = self.gains
        away, dist = _unit(-o["obstacle_rel_pos"])
        rho = np.maximum(dist - self.config.obstacle.radius, 0.5)
        active = o["obstacle_mask"] & (rho < g.traditional_range)
        mag = np.where(
            active, g.traditional_eta * (1.0 / rho - 1.0 / g.traditional_range) / rho**2, 0.0
        )
        return _cap_norm(mag[..., None] * away, g.max_repulsion).sum(axis=-2)

    def inner_repulsion(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """Repulsion between UAVs by distance only."""
        g = self.gains
        away, dist = _unit(-o["uav_rel_pos"])
        rho = np.maximum(dist, 0.5)
        active = o["uav_mask"] & (rho < g.traditional_inner_range)
        mag = np.where(
            active, g.traditional_eta * (1.0 / rho - 1.0 / g.traditional_inner_range) / rho**2, 0.0
        )
        return _cap_norm(mag[..., None] * away, g.max_repulsion).sum(axis=-2)
