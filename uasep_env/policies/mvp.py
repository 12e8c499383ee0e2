"""The Modified Voltage Potential (MVP): BlueSky's default conflict resolver, in 3D.

After Hoekstra et al. (2002) and BlueSky's ``bluesky/traffic/asas/mvp.py`` (TU Delft), adapted
to the formation (``docs/controllers.md``). For every intruder ``j`` (an observed UAV or
obstacle) with relative position ``d = p_j - p_i`` and relative velocity ``w = v_j - v_i``:

* time to the closest point of approach ``t_cpa = -d.w / |w|^2`` and the intruder's relative
  position there, ``d_cpa = d + w t_cpa``;
  (as BlueSky, also for a past CPA, ``t_cpa < 0``: a diverging intrusion);
* a conflict when ``0 < t_cpa < T_la`` (the look-ahead) and ``|d_cpa| < R`` (the protected
  zone's radius times the margin factor), or when already inside (``|d| < R``);
* the displacement that moves the CPA to the protected zone's boundary,
  ``R / cos(asin(R/|d|) - asin(|d_cpa|/|d|)) - |d_cpa|`` (BlueSky's correction, so the new
  path does not graze the zone; ``R - |d_cpa|`` inside it), along ``d_cpa`` away from the
  intruder, turned into a velocity change over the time to the CPA:
  ``dv_j = -(displacement / max(|t_cpa|, t_min)) d_cpa / |d_cpa|``;
* a head-on conflict (``|d_cpa|`` below ``head_on_distance``) resolved sideways: ``d_cpa``
  is replaced by the horizontal perpendicular of ``d``, right of the line of sight and odd
  in ``d`` so that both UAVs of a pair turn right (the rules of the air); straight above or
  below, BlueSky's vertical resolution (the whole zone over the time to the CPA, along
  ``w``);
* the changes summed over conflicts; a UAV-UAV conflict is shared (each UAV takes
  ``uav_share`` = 1/2 of the whole change, both seeing it: this package's reciprocal split;
  BlueSky halves only the vertical part), an obstacle is not cooperative (the UAV takes all
  of it).

Obstacles are resolved on their estimated state (``mvp``) or, in the ``mvp-region``
variant, on their predicted reachable region: the UAV's straight path is checked against
the region's surface over the look-ahead, and the closest point is pushed out along the
surface normal to the region's protected distance.

The velocity change becomes an acceleration over ``response_time`` and is added to the
shared plan tracking (:func:`~uasep_env.policies.nominal.plan_tracking`); the sum is bounded
like every controller's (:func:`~uasep_env.policies.nominal.bounded_action`). MVP is
memoryless and recomputed every step (as in BlueSky), so as the conflict is resolved its
change fades and the plan tracking takes the UAV back.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from uasep_env import reachable
from uasep_env.config import EnvConfig
from uasep_env.config.checks import check, check_one_of, check_positive
from uasep_env.policies.nominal import norm, plan_tracking
from uasep_env.policies.registry import register_policy
from uasep_env.policies.tracking import TrackingController

__all__ = ["MVP", "MVPParams", "mvp_velocity_change"]

_OBSTACLE_MODELS = ("state", "region")
# Fractions of the look-ahead at which the straight path is checked against a region.
_REGION_SAMPLES = np.linspace(0.0, 1.0, 21)
_PARAM_MAX = 1e4


@dataclass(frozen=True, kw_only=True)
class MVPParams:
    """Parameters of :class:`MVP` (units in comments; the source of each default).

    Attributes:
        look_ahead: ``T_la``, conflicts are detected this far ahead (s). BlueSky's
            ``asas_dtlookahead`` is 300 s for airliners at 5 NM; here the APF's prediction
            horizon ``K_s`` (10 s), so the methods look equally far.
        margin_factor: Resolution margin on the protected zone (BlueSky's ``asas_marh``,
            1.05 in its shipped settings).
        margin_scale: Multiplies the protected-zone radii (the trade-off sweep's knob;
            default 1.5, the knee of MVP's front on the ``-v3`` validation bank).
        uav_share: Part of a UAV-UAV conflict's whole change each UAV takes (1/2: both
            resolve it, reciprocally; 1: each as if alone). BlueSky's cooperative rule
            halves only the vertical part.
        response_time: Time over which the velocity change is commanded (s): the
            acceleration is ``dv / response_time``. 1 s: the change is flown within about a
            second at the 2 m/s^2 bound for the few-m/s changes of an encounter.
        min_time: Floor on the time to the CPA the change is spread over (s), so an
            intrusion (``t_cpa`` near 0) asks for a finite change: ``max(|t_cpa|, t_min)``.
            BlueSky takes ``|t_cpa|`` alone;
            one 0.1 s step would demand 10 times the acceleration bound.
        head_on_distance: Below this miss distance at the CPA the conflict is head-on and is
            resolved sideways (m). BlueSky's 10 m is 0.1 % of its 5 NM zone; 0.1 % of 10 m.
        obstacle_model: ``"state"`` (the obstacle's estimated position and velocity) or
            ``"region"`` (its predicted reachable region, as the APF sees it).
        uav_separation: Protected radius between UAVs (m); None: ``uav.separation_distance``.
        obstacle_separation: Protected radius from an obstacle's centre (m); None:
            ``uav.obstacle_separation``. From a region's surface the zone is this less the
            obstacle's safety radius (the region already holds it).
    """

    look_ahead: float = 10.0  # s
    margin_factor: float = 1.05  # -
    # The knee of MVP's front on the -v3 validation bank (docs/figures/tradeoff.md).
    margin_scale: float = 1.5  # -
    uav_share: float = 0.5  # -
    response_time: float = 1.0  # s
    min_time: float = 1.0  # s
    head_on_distance: float = 0.01  # m
    obstacle_model: str = "state"
    uav_separation: float | None = None  # m
    obstacle_separation: float | None = None  # m

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "obstacle_model":
                check_one_of("mvp.obstacle_model", value, _OBSTACLE_MODELS)
            elif value is not None:
                zero_ok = f.name in ("margin_scale", "uav_share", "head_on_distance")
                check_positive(f"mvp.{f.name}", value, allow_zero=zero_ok, hi=_PARAM_MAX)
        check(self.uav_share <= 1.0, "mvp.uav_share", self.uav_share, "must be <= 1")
        check(self.margin_factor >= 1.0, "mvp.margin_factor", self.margin_factor, "must be >= 1")


def mvp_velocity_change(
    rel_pos: np.ndarray,
    rel_vel: np.ndarray,
    mask: np.ndarray,
    radius: float,
    look_ahead: float,
    min_time: float,
    head_on_distance: float = 0.01,
) -> np.ndarray:
    """MVP's velocity change of the ownship for each intruder (m/s), zero where no conflict.

    Args:
        rel_pos: ``d = p_j - p_i``, ``(..., K, 3)`` (m).
        rel_vel: ``w = v_j - v_i``, ``(..., K, 3)`` (m/s).
        mask: ``(..., K)``: which intruders exist.
        radius: ``R``, the protected zone's radius with its margin (m).
        look_ahead: ``T_la`` (s).
        min_time: Floor on the time to the CPA (s).
        head_on_distance: Miss distance below which the conflict is resolved sideways (m).

    Returns:
        ``(..., K, 3)`` velocity changes of the ownship (m/s).
    """
    dist = norm(rel_pos)
    w2 = np.einsum("...i,...i->...", rel_vel, rel_vel)
    closing = -np.einsum("...i,...i->...", rel_pos, rel_vel)
    t_cpa = np.where(w2 > 1e-12, closing / np.maximum(w2, 1e-12), 0.0)
    # As BlueSky: the CPA at t_cpa even when it is past (a diverging intrusion), and the
    # change spread over |t_cpa| ("abs(tcpa) because it becomes negative during intrusion").
    d_cpa = rel_pos + rel_vel * t_cpa[..., None]
    miss = norm(d_cpa)
    conflict = mask & (((t_cpa > 0.0) & (t_cpa < look_ahead) & (miss < radius)) | (dist < radius))
    # Head-on: resolve sideways, perpendicular to d in the horizontal plane (odd in d), so
    # each UAV turns right of its line of sight (the rules of the air: both turn right).
    side = np.stack([rel_pos[..., 1], -rel_pos[..., 0], np.zeros_like(dist)], axis=-1)
    side_n = norm(side)
    head_on = miss < head_on_distance
    # Straight above or below there is no horizontal perpendicular: resolve vertically,
    # as BlueSky's vertical resolution, the whole zone over the time to the CPA along the
    # relative velocity w (the ownship moves the way the intruder comes, away from it).
    vertical = head_on & (side_n <= 1e-9 * dist)
    w_dir = rel_vel / np.sqrt(np.maximum(w2, 1e-300))[..., None]
    side_dir = np.where(vertical[..., None], -w_dir, side / np.maximum(side_n, 1e-300)[..., None])
    cpa_dir = np.where(head_on[..., None], side_dir, d_cpa / np.maximum(miss, 1e-12)[..., None])
    miss = np.where(head_on, head_on_distance, miss)
    # BlueSky's correction for an intruder outside the zone: reach the tangent, not the chord.
    outside = (radius < dist) & (miss < dist) & ~vertical
    safe_dist = np.maximum(dist, 1e-12)
    erratum = np.cos(
        np.arcsin(np.clip(radius / safe_dist, 0.0, 1.0))
        - np.arcsin(np.clip(miss / safe_dist, 0.0, 1.0))
    )
    push = np.where(outside, radius / np.maximum(erratum, 1e-6) - miss, radius - miss)
    push = np.where(vertical, radius, push)
    dv = -(push / np.maximum(np.abs(t_cpa), min_time))[..., None] * cpa_dir
    return np.where(conflict[..., None], dv, 0.0)


def _region_velocity_change(
    o: dict[str, np.ndarray], radius: float, look_ahead: float, min_time: float
) -> np.ndarray:
    """MVP against the predicted regions: velocity changes ``(..., K, 3)`` (m/s).

    The UAV's straight path is checked against each region's surface over the look-ahead;
    its closest point is pushed out along the surface normal to the protected distance.
    """
    center = o["obstacle_center"]  # region centre relative to the UAV
    axes = np.maximum(o["obstacle_axes"], 1e-3)
    cs = o["obstacle_heading_cs"]
    heading = np.arctan2(cs[..., 1], cs[..., 0])
    vel = np.broadcast_to(o["velocity"][..., None, :], center.shape)
    times = _REGION_SAMPLES * look_ahead  # (S,)
    future = vel[..., None, :] * times[:, None]  # (..., K, S, 3)
    d = reachable.distance_to_ellipsoid(
        future, center[..., None, :], axes[..., None, :], heading[..., None]
    )  # (..., K, S)
    k = np.argmin(d, axis=-1)
    d_min = np.take_along_axis(d, k[..., None], axis=-1)[..., 0]
    t_star = times[k]
    closest = np.take_along_axis(future, k[..., None, None], axis=-2)[..., 0, :]
    _, normal = reachable.distance_to_ellipsoid(closest, center, axes, heading, return_normal=True)
    conflict = o["obstacle_mask"] & (d_min < radius)
    dv = ((radius - d_min) / np.maximum(t_star, min_time))[..., None] * normal
    return np.where(conflict[..., None], dv, 0.0)


@register_policy("mvp", label="MVP", reference=True, default_margin=1.5)
class MVP(TrackingController):
    """Modified Voltage Potential conflict resolution on the shared plan tracking.

    Args:
        config: The environment config (observation layout, bounds, separation radii).
        params: :class:`MVPParams` (default: the defaults, obstacles on their state).
    """

    name = "mvp"
    params_type = MVPParams

    def __init__(self, config: EnvConfig, params: MVPParams | None = None) -> None:
        super().__init__(config, params)
        p = self.params
        sep, obs_sep = self.separations(p.uav_separation, p.obstacle_separation)
        scale = p.margin_factor * p.margin_scale
        self.uav_radius = scale * sep  # m
        self.obstacle_radius = scale * obs_sep  # m, from the centre
        self.region_radius = scale * max(obs_sep - config.obstacle.radius, 0.0)  # m, surface

    def velocity_change(self, o: dict[str, np.ndarray]) -> np.ndarray:
        """The summed resolution ``dv`` (m/s) for decoded observations, ``(..., 3)``."""
        p = self.params
        dv_uav = mvp_velocity_change(
            o["uav_rel_pos"], o["uav_rel_vel"], o["uav_mask"], self.uav_radius,
            p.look_ahead, p.min_time, p.head_on_distance,
        )  # fmt: skip
        if p.obstacle_model == "state":
            dv_obs = mvp_velocity_change(
                o["obstacle_rel_pos"], o["obstacle_rel_vel"], o["obstacle_mask"],
                self.obstacle_radius, p.look_ahead, p.min_time, p.head_on_distance,
            )  # fmt: skip
        else:
            dv_obs = _region_velocity_change(o, self.region_radius, p.look_ahead, p.min_time)
        return p.uav_share * dv_uav.sum(axis=-2) + dv_obs.sum(axis=-2)

    def __call__(self, observations: np.ndarray) -> np.ndarray:
        """Normalised accelerations ``(..., 3)`` for observations ``(..., obs_dim)``."""
        o = self.layout.decode(np.asarray(observations))
        dv = self.velocity_change(o)
        accel = plan_tracking(o, self.tracking) + dv / self.params.response_time
        return self.bounded(accel, o["velocity"]).astype(np.float32)


register_policy(
    "mvp-region",
    label="MVP (region)",
    reference=True,
    default_margin=1.5,  # its knee on the -v3 validation bank, as MVP's (MVPParams' default)
    margin=lambda c, s: MVP(c, MVPParams(obstacle_model="region", margin_scale=s)),
    factory=lambda c: MVP(c, MVPParams(obstacle_model="region")),
    summary="MVP with obstacles resolved on their predicted reachable region "
    '(`MVP(config, MVPParams(obstacle_model="region"))`)',
)
