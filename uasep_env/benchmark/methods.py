"""Each method's safety knob and the values it is swept over (the trade-off sweep's table).

``uasep-tradeoff`` (:mod:`.tradeoff`) plots these sweeps; ``uasep-bench`` plays the same sweeps on
its banks to find each method's deviation at equal safety. The knobs (``scale`` multiplies the
gains that set the margin in the reference gains, :class:`~uasep_env.policies.apf.APFGains`'s
field defaults; each method's own default is the knee of its front on the trade-off bank):

* ``apf``, ``motion-state-apf``: ``obstacle_safe_min`` and ``obstacle_time``;
* ``apf-published``: the APF with the paper's prediction as published (a config, no name);
* ``traditional-apf``: ``traditional_range`` (Khatib's influence distance);
* ``ppo-residual`` (``ppo_residual_apf``): the APF base under the residual, scaled;
* ``ppo-shared``, ``mappo``: no gain; the prediction horizon the policy observes is swept;
* every other registered reference controller with a margin (``mvp``, ``orca``, ...): its
  registry entry's ``margin`` over :data:`SCALES` (:func:`registry_methods`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from uasep_env.config import AS_PUBLISHED, EnvConfig
from uasep_env.config.groups import CALIBRATED_HORIZONS
from uasep_env.policies import (
    APF,
    REGISTRY,
    APFGains,
    MotionStateAPF,
    TraditionalAPF,
    load_policy,
    shipped_policy_path,
)

__all__ = ["HORIZONS_S", "METHODS", "SCALES", "Method", "registry_methods", "sweep_of"]

#: Margin scales: 9 settings from a quarter to three times the default margin.
SCALES = (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0)
#: Prediction horizons (s) for the pure learned policies (trained at 10 s): the calibrated
#: prediction's (the default fit from -v3 on), which it calibrates at these horizons only.
HORIZONS_S = CALIBRATED_HORIZONS


def _scaled(names: Sequence[str], scale: float) -> APFGains:
    """The reference gains (:class:`APFGains`'s field defaults) with ``names`` scaled."""
    return APFGains().scaled(names, scale)


@dataclass(frozen=True, kw_only=True)
class Method:
    """A controller and the knob swept over its safety margin.

    Attributes:
        name: Key in the trade-off CSV and figures.
        label: Legend label.
        knob: What the values set.
        values: The grid.
        default: The value that is the controller's default (its ``default_gains``).
        policy: ``(config, value) -> policy`` for one setting.
        config: Overrides of the environment config for one setting (default: none).
        policy_name: The registered or shipped policy name whose default setting this
            sweep passes through (``uasep-bench`` sweeps it for that name); None: no name.
    """

    name: str
    label: str
    knob: str
    values: tuple[float, ...]
    default: float
    policy: Callable[[EnvConfig, float], Any]
    config: Callable[[float], dict[str, Any]] = lambda _v: {}
    policy_name: str | None = None


def _shipped(name: str) -> Any:
    """A shipped checkpoint's path (``ValueError`` naming it when the install has none)."""
    path = shipped_policy_path(name)
    if path is None:
        raise ValueError(f"policy {name!r}: not shipped with this install")
    return path


def _residual(cfg: EnvConfig, s: float) -> Any:
    return load_policy(
        _shipped("ppo_residual_apf"), cfg, "ppo-residual", base_gains=_scaled(APF.margin_gains, s)
    )


def _horizon(h: float) -> dict[str, Any]:
    return {"prediction": {"horizon": h}}


_HAND_WRITTEN: tuple[Method, ...] = (
    Method(
        name="apf",
        label="APF (proposed)",
        knob="margin scale",
        values=SCALES,
        default=REGISTRY["apf"].default_margin,
        policy=lambda c, s: APF(c, _scaled(APF.margin_gains, s)),
        policy_name="apf",
    ),
    Method(
        name="apf-published",
        label="APF, paper's prediction",
        knob="margin scale",
        values=SCALES,
        default=REGISTRY["apf"].default_margin,
        policy=lambda c, s: APF(c, _scaled(APF.margin_gains, s)),
        config=lambda _s: AS_PUBLISHED,
    ),
    Method(
        name="motion-state-apf",
        label="motion-state APF",
        knob="margin scale",
        values=SCALES,
        default=REGISTRY["motion-state-apf"].default_margin,
        policy=lambda c, s: MotionStateAPF(c, _scaled(MotionStateAPF.margin_gains, s)),
        policy_name="motion-state-apf",
    ),
    Method(
        name="traditional-apf",
        label="traditional APF",
        knob="range scale",
        values=SCALES,
        default=REGISTRY["traditional-apf"].default_margin,
        policy=lambda c, s: TraditionalAPF(c, _scaled(TraditionalAPF.margin_gains, s)),
        policy_name="traditional-apf",
    ),
    Method(
        name="ppo-residual",
        label="PPO residual on APF",
        knob="base margin scale",
        values=SCALES,
        default=1.0,
        policy=_residual,
        policy_name="ppo_residual_apf",
    ),
    Method(
        name="ppo-shared",
        label="PPO (pure)",
        knob="prediction horizon (s)",
        values=HORIZONS_S,
        default=10.0,
        policy=lambda c, _h: load_policy(_shipped("ppo_shared"), c, "ppo-shared"),
        config=_horizon,
        policy_name="ppo_shared",
    ),
    Method(
        name="mappo",
        label="MAPPO",
        knob="prediction horizon (s)",
        values=HORIZONS_S,
        default=10.0,
        policy=lambda c, _h: load_policy(_shipped("mappo"), c, "mappo"),
        config=_horizon,
        policy_name="mappo",
    ),
)


def _from_registry(name: str) -> Method:
    """The sweep of a registered controller: its registry ``margin`` over :data:`SCALES`."""
    e = REGISTRY[name]
    return Method(
        name=e.name,
        label=e.label,
        knob=e.knob,
        values=SCALES,
        default=e.default_margin,
        policy=e.margin,  # type: ignore[arg-type]
        policy_name=e.name,
    )


def registry_methods(taken: Sequence[str]) -> tuple[Method, ...]:
    """A :class:`Method` for every registered reference controller with a margin to sweep.

    Its knob is its registry entry's ``margin`` (``(config, scale) -> policy``) over
    :data:`SCALES`; controllers already in ``taken`` (the APFs, swept above) are left out.
    """
    return tuple(
        _from_registry(e.name)
        for e in REGISTRY.values()
        if e.reference and e.margin is not None and e.name not in taken
    )


#: The hand-written methods, then every other registered reference controller.
METHODS: tuple[Method, ...] = _HAND_WRITTEN + registry_methods([m.name for m in _HAND_WRITTEN])


def sweep_of(policy_name: str) -> Method | None:
    """The sweep through ``policy_name``'s default setting, or None (no knob to sweep).

    A registered name without a hand-written sweep gets its registry margin (registered
    after this module was imported, too).
    """
    for m in METHODS:
        if m.policy_name == policy_name:
            return m
    entry = REGISTRY.get(policy_name)
    return _from_registry(policy_name) if entry is not None and entry.margin is not None else None
