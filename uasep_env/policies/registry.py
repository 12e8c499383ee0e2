"""The policy registry: every built-in controller by name, filled by the controllers' modules.

A controller registers itself where it is defined, with :func:`register_policy`; the
registry is what ``uasep-eval --policy``, :func:`~uasep_env.policies.make_policy`, the
benchmark scripts (``baselines/tradeoff.py``, ``scaling.py``, ``real_traffic_eval.py``,
``learned_vs_apf.py``) and the tests parametrised over :data:`POLICIES` read, so a new
controller is its module plus the import of that module in ``uasep_env/policies/__init__.py``
(``docs/extending.md``), for example::

    @register_policy("mine", label="my method", reference=True)
    class Mine:
        @classmethod
        def with_margin(cls, config, s):  # the trade-off sweep (or pass margin=)
            return cls(config, MineParams(margin_scale=s))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uasep_env.config import EnvConfig
from uasep_env.policies.guard import finite_observations

__all__ = ["POLICIES", "REGISTRY", "RegisteredPolicy", "reference_controllers", "register_policy"]


@dataclass(frozen=True, kw_only=True)
class RegisteredPolicy:
    """One registry entry.

    Attributes:
        name: The name ``--policy`` takes.
        factory: ``config -> policy``.
        label: Its name in tables and figures.
        reference: A reference controller: every comparison script plays it (zero and
            random are not).
        margin: ``(config, scale) -> policy`` with the controller's own safety distances
            scaled (``baselines/tradeoff.py`` sweeps it); None: no margin to sweep.
        default_margin: The scale its default parameters correspond to.
        knob: What the sweep's scale is called in the trade-off tables.
        summary: One line on what it is (the docs' table; default: the class docstring's
            first line).
    """

    name: str
    factory: Callable[[EnvConfig], Any]
    label: str
    reference: bool = False
    margin: Callable[[EnvConfig, float], Any] | None = None
    default_margin: float = 1.0
    knob: str = "margin scale"
    summary: str = ""


#: Every registered entry, by name, in registration order.
REGISTRY: dict[str, RegisteredPolicy] = {}
#: The built-in policies by name, each a factory taking the config (the registry's view).
POLICIES: dict[str, Callable[[EnvConfig], Any]] = {}


def register_policy(
    name: str,
    *,
    label: str | None = None,
    reference: bool = False,
    margin: Callable[[EnvConfig, float], Any] | None = None,
    default_margin: float = 1.0,
    knob: str = "margin scale",
    factory: Callable[[EnvConfig], Any] | None = None,
    summary: str | None = None,
) -> Callable[[Any], Any]:
    """Register a controller under ``name`` (a class decorator, or called with ``factory``).

    Args:
        name: The name ``--policy`` and :func:`~uasep_env.policies.make_policy` take.
        label: Its name in tables (default: ``name``).
        reference: Whether every comparison plays it.
        margin: ``(config, scale) -> policy`` with its safety distances scaled (default: the
            class's ``with_margin`` classmethod where it has one, else no sweep).
        default_margin: The scale of its default parameters.
        knob: The sweep's name in the trade-off tables.
        factory: ``config -> policy`` (default: the decorated class itself), for a second
            name of one class (``mvp-region``).
        summary: One line for the docs' table (default: the docstring's first line).

    A registered class refuses observations that are not finite
    (:func:`~uasep_env.policies.guard.finite_observations` wraps its ``__call__``): every
    controller behaves alike on them without checking them itself. A ``factory`` must make
    instances of such a class (``tests/test_policy_inputs.py`` plays every name on them).

    Returns:
        A decorator returning the class, its ``__call__`` checked.

    Raises:
        ValueError: If ``name`` is taken.
    """

    def add(obj: Any) -> Any:
        if name in REGISTRY:
            raise ValueError(f"policy {name!r} is already registered")
        if isinstance(obj, type):
            finite_observations(obj)
        make = factory if factory is not None else obj
        sweep = margin if margin is not None or factory is not None else _with_margin(obj)
        doc = (getattr(obj, "__doc__", None) or "").strip().splitlines()
        REGISTRY[name] = RegisteredPolicy(
            name=name,
            factory=make,
            label=label or name,
            reference=reference,
            margin=sweep,
            default_margin=default_margin,
            knob=knob,
            summary=summary if summary is not None else (doc[0] if doc else ""),
        )
        POLICIES[name] = make
        return obj

    if factory is not None:
        add(factory)
    return add


def _with_margin(obj: Any) -> Callable[[EnvConfig, float], Any] | None:
    """A class's own margin sweep, ``cls.with_margin(config, scale)``, if it has one."""
    return getattr(obj, "with_margin", None) if isinstance(obj, type) else None


def reference_controllers() -> tuple[str, ...]:
    """The names of the reference controllers, in registration order (the APFs first)."""
    return tuple(n for n, e in REGISTRY.items() if e.reference)
