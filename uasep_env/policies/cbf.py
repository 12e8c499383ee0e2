r"""Control barrier functions: the CBF-QP controller and the CBF filter it shares with the shield.

Each UAV is a double integrator, ``p'' = u`` with ``u`` the commanded acceleration. For a
neighbour UAV or an obstacle at relative position ``dp = p_i - p_j`` and relative velocity
``dv = v_i - v_j`` (read from the observation, so from the UAV's estimates), the barrier

.. math:: h = |dp|^2 - R^2

is non-negative outside the sphere of radius ``R`` around it. Its relative degree in ``u``
is two, so it is handled as a high-order CBF (Xiao & Belta 2019/2021): with
``psi_1 = h' + alpha_1 h``, the constraint ``psi_1' + alpha_2 psi_1 >= 0`` reads

.. math:: 2 dp \cdot (u_i - u_j) \ge -\Phi, \quad
          \Phi = 2 |dv|^2 + (\alpha_1 + \alpha_2) h' + \alpha_1 \alpha_2 h,
          \quad h' = 2 dp \cdot dv,

linear in the accelerations; it keeps ``h >= 0`` for all time if it holds throughout and
``h`` and ``psi_1`` start non-negative. An obstacle is not cooperative and its acceleration
is unknown (a Dubins aircraft turning at its bound accelerates by under 0.1 m/s^2): it is
taken as zero, and the UAV carries the whole constraint. Between two UAVs each carries the
share ``uav_share`` (one half: the reciprocal split of Wang, Ames & Egerstedt 2017).
Dividing by ``2 |dp|`` gives a unit normal ``n = dp / |dp|`` and the row
``n . u_i >= b`` in m/s^2.

The filter keeps the ``max_constraints`` most demanding barriers (those the desired
command falls shortest of) and solves, per UAV, the QP of Ames et al. (2017, 2019): the
acceleration nearest the desired one that satisfies them, within the acceleration bounds,
with one slack of weight ``slack_penalty`` so that it always has a solution
(:mod:`uasep_env.policies.qp`, exact).
The radii are ``R = margin_scale (separation + buffer)``, the separation being the config's
loss-of-separation distance (``uav.separation_distance`` between UAVs,
``uav.obstacle_separation`` from an obstacle), the buffer covering estimation noise and the
time between decisions.

:class:`CBFQP` (``"cbf-qp"``) filters a nominal plan-tracking command (the APF's attraction
terms alone, eqs. 19-22, with its speed bound); :class:`~uasep_env.policies.shield.Shielded`
filters any policy's command with the same :class:`CBFFilter`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.config.checks import MAX_DIST, check_int_in, check_positive
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies.nominal import plan_tracking
from uasep_env.policies.qp import solve_filter_qp
from uasep_env.policies.registry import register_policy
from uasep_env.policies.tracking import TrackingController

__all__ = ["CBFQP", "CBFFilter", "CBFParams"]

_GAIN_MAX = 1e6  # any larger gain is a typo


@dataclass(frozen=True, kw_only=True)
class CBFParams:
    """Parameters of the CBF filter (units in comments; ``cbf.<name>`` in errors).

    Attributes:
        alpha1: ``alpha_1`` [1/s], class-K gain of ``h`` in ``psi_1 = h' + alpha_1 h``.
        alpha2: ``alpha_2`` [1/s], class-K gain of ``psi_1`` in the constraint.
        uav_buffer: Added to ``uav.separation_distance`` for the UAV-UAV radius [m].
        obstacle_buffer: Added to ``uav.obstacle_separation`` for the obstacle radius [m].
        margin_scale: Scales both radii (dimensionless; the trade-off sweep's knob; default
            2, the knee of CBF-QP's front on the ``-v3`` validation bank, and so the
            shield's: CBF-QP is the shield over plan tracking).
        max_constraints: ``K``, the barriers kept per UAV (the most demanding).
        uav_share: Share of a UAV-UAV constraint each of the two UAVs carries (0-1].
        slack_penalty: ``rho``, weight of the squared slack against the squared change of
            acceleration (dimensionless). A quadratic penalty leaves a constraint short by
            ``1 / (1 + rho)`` of the change it asks for (1e-4 with the default: a 3 m/s^2
            change is 0.3 mm/s^2 short); the slack is large only where the constraints
            cannot all hold within the acceleration bounds. At most 1e6, where the exact
            solver's range ends (:mod:`uasep_env.policies.qp`).
        deadlock_gain: Weight of the sidestep added to the command where a barrier binds
            (:meth:`CBFFilter.sidestep`; dimensionless, 0: pure minimal change).
    """

    # Defaults: alpha1/alpha2 chosen so that the constraint starts acting about 5-8 s
    # before a head-on meeting at the UAVs' 10 m/s plus an obstacle's 4 m/s, i.e. soon
    # enough for the 2 m/s^2 bound (measured on the collision-course families,
    # tests/test_cbf.py); the buffers cover the position noise (0.5 m UAV, 2 m obstacle
    # estimate) and one 0.2 s decision interval at the closing speed.
    alpha1: float = 0.4  # 1/s
    alpha2: float = 0.8  # 1/s
    uav_buffer: float = 2.0  # m
    obstacle_buffer: float = 4.0  # m
    # The knee of CBF-QP's front on the -v3 validation bank (docs/figures/tradeoff.md);
    # the shield is the same filter, so its margin is the same.
    margin_scale: float = 2.0  # dimensionless
    max_constraints: int = 4  # K: the 1-3 obstacles of a bank encounter and a neighbour
    uav_share: float = 0.5  # Wang, Ames & Egerstedt (2017): reciprocal halves
    slack_penalty: float = 1.0e4  # dimensionless
    deadlock_gain: float = 1.0  # dimensionless; 0 turns the sidestep off

    def __post_init__(self) -> None:
        for f in fields(self):
            name, value = f"cbf.{f.name}", getattr(self, f.name)
            if f.name == "max_constraints":
                check_int_in(name, value, 1, 8)
            elif f.name in ("uav_buffer", "obstacle_buffer", "deadlock_gain"):
                check_positive(name, value, allow_zero=True, hi=MAX_DIST)
            elif f.name == "uav_share":
                check_positive(name, value, hi=1.0)
            else:
                check_positive(name, value, hi=_GAIN_MAX)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.sqrt(np.einsum("...i,...i->...", v, v))
    return v / np.maximum(n, 1e-9)[..., None], n


class CBFFilter:
    """The CBF safety filter: the minimal change of a command that satisfies the barriers.

    Args:
        config: The environment config (bounds, separations, observation layout, action
            mode).
        params: Filter parameters (default :class:`CBFParams`).
    """

    def __init__(self, config: EnvConfig, params: CBFParams | None = None) -> None:
        if params is not None and not isinstance(params, CBFParams):
            raise TypeError(f"params must be a CBFParams, got {type(params).__name__}")
        self.config = config
        self.params = params if params is not None else CBFParams()
        self.layout = ObservationLayout.from_config(config)
        p, uav = self.params, config.uav
        self.max_accel = uav.max_accel
        self.uav_radius = p.margin_scale * (uav.separation_distance + p.uav_buffer)
        self.obstacle_radius = p.margin_scale * (uav.obstacle_separation + p.obstacle_buffer)
        self.residual_scale = config.action.residual_scale

    def constraints(
        self, o: dict[str, np.ndarray], u0: np.ndarray | None = None
    ) -> tuple[np.ndarray, ...]:
        """The ``K`` most demanding barrier rows ``n . u >= b`` of decoded observations.

        With the desired acceleration ``u0`` (m/s^2), the rows it falls shortest of
        (largest ``b - n . u0``); without, the nearest (smallest ``|dp| - R``). Nearest is
        not most urgent: in a formation a UAV's idle neighbours are nearer than an obstacle
        closing at 14 m/s, which must be enforced some 90 m out (measured: ranked by
        distance, ``cbf-qp`` lost obstacle separation in 18 % of encounters at 8 UAVs).

        Returns:
            ``n`` ``(..., K, 3)`` unit normals, ``b`` ``(..., K)`` (m/s^2), ``valid``
            ``(..., K)``, the margins ``|dp| - R`` ``(..., K)`` (m, inf where invalid) and
            whether each row is an obstacle's ``(..., K)``.
        """
        p = self.params
        parts = []
        for key, radius, share in (
            ("uav", self.uav_radius, p.uav_share),
            ("obstacle", self.obstacle_radius, 1.0),
        ):
            if f"{key}_rel_pos" not in o:
                continue
            dp = -o[f"{key}_rel_pos"]  # own position minus theirs
            dv = -o[f"{key}_rel_vel"]
            n, dist = _unit(dp)
            h = dist * dist - radius * radius
            h_dot = 2.0 * np.einsum("...i,...i->...", dp, dv)
            phi = (
                2.0 * np.einsum("...i,...i->...", dv, dv)
                + (p.alpha1 + p.alpha2) * h_dot
                + p.alpha1 * p.alpha2 * h
            )
            b = -share * phi / (2.0 * np.maximum(dist, 1e-9))
            mask = o[f"{key}_mask"]
            parts.append(
                (n, b, mask, np.where(mask, dist - radius, np.inf), np.full(b.shape, key != "uav"))
            )
        n = np.concatenate([q[0] for q in parts], axis=-2)
        b = np.concatenate([q[1] for q in parts], axis=-1)
        valid = np.concatenate([q[2] for q in parts], axis=-1)
        margin = np.concatenate([q[3] for q in parts], axis=-1)
        obstacle = np.concatenate([q[4] for q in parts], axis=-1)
        k = min(p.max_constraints, margin.shape[-1])
        if u0 is None:
            key = margin
        else:
            short = b - np.einsum("...kj,...j->...k", n, u0)
            key = np.where(valid, -short, np.inf)
        order = np.argsort(key, axis=-1, kind="stable")[..., :k]
        take = np.take_along_axis
        return (
            take(n, order[..., None], axis=-2),
            take(b, order, axis=-1),
            take(valid, order, axis=-1),
            take(margin, order, axis=-1),
            take(obstacle, order, axis=-1),
        )

    @staticmethod
    def sidestep(n: np.ndarray, b: np.ndarray, valid: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """The deadlock breaker: a turn to the right of each binding barrier (m/s^2).

        A barrier binds where the command falls short of it (``n . u_0 < b``); the filter's
        nearest safe command then only brakes along ``n``, and head-on (``n`` along the
        relative velocity) braking alone can hold a UAV in front of an obstacle that keeps
        coming until it is lost (measured: one seed of six on ``collision_head_on`` flew
        over 300 m off its plan). Each binding barrier of ``valid`` (the filter passes the
        obstacles' only: a formation's neighbours fly alongside, and turning from them
        pushed UAVs into each other) adds its shortfall along ``n x down``: horizontal, to
        the right of the line of sight to the obstacle (``-n``; in NED, flying north at an
        obstacle ahead, east), as the rules of the air turn aircraft right head-on. It
        vanishes with the shortfall, so a command that keeps every barrier is not changed.
        """
        short = np.where(valid, np.maximum(b - np.einsum("...kj,...j->...k", n, u0), 0.0), 0.0)
        # n points from the obstacle to the UAV: right of the line of sight -n is
        # down x (-n) = n x down (NED, z down).
        right = np.cross(n, np.array([0.0, 0.0, 1.0]))
        right, _ = _unit(right)
        return np.einsum("...k,...kj->...j", short, right)

    def bounds(self, o: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Per-axis bounds of the commanded acceleration (m/s^2).

        ``[-a_max, a_max]``; in the ``residual_apf`` mode also within ``residual_scale`` of
        the APF's command, the most a residual action can change it.
        """
        shape = (*o["velocity"].shape[:-1], 3)
        lo, hi = np.full(shape, -1.0), np.full(shape, 1.0)
        if self.layout.base_action:
            base = o["base_action"]
            lo = np.maximum(lo, base - self.residual_scale)
            hi = np.minimum(hi, base + self.residual_scale)
        return lo * self.max_accel, hi * self.max_accel

    def filter_command(self, o: dict[str, np.ndarray], command: np.ndarray) -> np.ndarray:
        """Filter a normalised command (the acceleration flown, over ``max_accel``).

        Args:
            o: Decoded observations (:meth:`ObservationLayout.decode`).
            command: Desired normalised commands ``(..., 3)`` (clipped to ``[-1, 1]``).

        Returns:
            The filtered normalised commands ``(..., 3)`` float64.
        """
        lo, hi = self.bounds(o)
        u0 = np.clip(np.asarray(command, dtype=float), -1.0, 1.0) * self.max_accel
        n, b, valid, _, obstacle = self.constraints(o, u0)
        if self.params.deadlock_gain > 0.0:
            u0 = u0 + self.params.deadlock_gain * self.sidestep(n, b, valid & obstacle, u0)
        u0 = np.clip(u0, lo, hi)
        u, _ = solve_filter_qp(u0, n, b, valid, lo, hi, self.params.slack_penalty)
        return np.clip(u / self.max_accel, -1.0, 1.0)

    def filter(self, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Filter actions (as the environment takes them) for their observations.

        In the ``residual_apf`` mode the actions are corrections of the APF's command
        (``base_action`` in the observation): the filtered command is turned back into one.

        Args:
            observations: ``(..., obs_dim)``.
            actions: ``(..., 3)`` actions in ``[-1, 1]``.

        Returns:
            The filtered actions ``(..., 3)`` float32.
        """
        o = self.layout.decode(observations)
        actions = np.clip(np.asarray(actions, dtype=float), -1.0, 1.0)
        if not self.layout.base_action:
            return self.filter_command(o, actions).astype(np.float32)
        base = o["base_action"]
        command = self.filter_command(o, base + self.residual_scale * actions)
        return np.clip((command - base) / self.residual_scale, -1.0, 1.0).astype(np.float32)


@register_policy("cbf-qp", label="CBF-QP", reference=True, default_margin=2.0)
class CBFQP(TrackingController):
    """CBF-QP: a nominal plan-tracking command, filtered by :class:`CBFFilter`.

    The nominal command is the shared plan tracking
    (:func:`~uasep_env.policies.nominal.plan_tracking`: the APF's goal, slot and velocity
    tracking and damping, eqs. 19-22) under the speed bound (eq. 4), with no repulsion: all
    avoidance comes from the barriers.

    Args:
        config: The environment config.
        params: Filter parameters (default :class:`CBFParams`).
    """

    name = "cbf-qp"
    params_type = CBFParams

    def __init__(self, config: EnvConfig, params: CBFParams | None = None) -> None:
        self.cbf = CBFFilter(config, params)
        super().__init__(config, self.cbf.params)

    def nominal(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """The plan-tracking command, normalised ``(..., 3)``."""
        return self.bounded(plan_tracking(o, self.tracking), o["velocity"])

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(..., 3)`` float32 for observations ``(..., obs_dim)``."""
        o = self.layout.decode(np.asarray(observations))
        command = self.cbf.filter_command(o, self.nominal(o))
        if not self.layout.base_action:
            return command.astype(np.float32)
        base = o["base_action"]
        residual = (command - base) / self.cbf.residual_scale
        return np.clip(residual, -1.0, 1.0).astype(np.float32)
