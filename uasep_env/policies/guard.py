"""Every policy's one check on its input: an observation that is not finite is refused.

A NaN or an infinity in one entry of an observation (one obstacle's relative position, say)
would otherwise come out of the controllers as NaN actions (the APFs, the CBF-QP, and the
CBF shield, which turns any policy's finite action into NaN), and the environment would
fly them. Every policy raises instead, with the same one-line ``ValueError`` naming the
entry (its name from :meth:`~uasep_env.interface.observation.ObservationLayout.feature_names`).

The check is applied to a policy class by :func:`finite_observations`:
:func:`~uasep_env.policies.registry.register_policy` applies it to every registered
controller, and the shield and the learned policies' classes are decorated with it, so no
controller repeats it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from uasep_env.config import EnvConfig
from uasep_env.interface.observation_layout import ObservationLayout

__all__ = ["check_finite_observations", "finite_observations"]

_T = TypeVar("_T", bound=type)


def _entry_name(config: Any, width: int, column: int) -> str:
    """The name of column ``column`` in the layout of ``config`` (its index if none fits)."""
    if isinstance(config, EnvConfig):
        names = ObservationLayout.from_config(config).feature_names()
        if len(names) == width:
            return f"{names[column]!r} (column {column})"
    return f"column {column}"


def check_finite_observations(observations: Any, config: EnvConfig | None = None) -> None:
    """Raise if any entry of ``observations`` (``(..., obs_dim)``) is NaN or infinite.

    Args:
        observations: The observations a policy is called with.
        config: The environment config whose layout names the entries (None: by index).

    Raises:
        ValueError: Naming the first entry that is not finite, its value and where.
    """
    obs = np.asarray(observations)
    if obs.dtype.kind not in "fc" or obs.ndim == 0 or bool(np.isfinite(obs).all()):
        return  # the per-step cost: one isfinite over the array
    index = tuple(int(i) for i in np.argwhere(~np.isfinite(obs))[0])
    where = f" of row {index[:-1]}" if obs.ndim > 1 else ""
    raise ValueError(
        f"observation entry {_entry_name(config, obs.shape[-1], index[-1])}{where} is not "
        f"finite: {obs[index]}"
    )


def finite_observations(cls: _T) -> _T:
    """Make ``cls.__call__`` check its observations first (a class decorator; idempotent).

    The entries are named from the instance's ``config`` attribute when it has one.
    """
    call: Callable[..., Any] = cls.__call__
    if getattr(call, "_checks_finite", False):
        return cls

    @functools.wraps(call)
    def checked(self: Any, observations: Any, *args: Any, **kwargs: Any) -> Any:
        check_finite_observations(observations, getattr(self, "config", None))
        return call(self, observations, *args, **kwargs)

    checked._checks_finite = True  # type: ignore[attr-defined]
    cls.__call__ = checked  # type: ignore[assignment]
    return cls
