"""Checks of user input: each raises an error that names the bad field and its value.

The configuration's range and type validators (a :class:`ValueError` naming the dotted
field), the physical bounds they apply, and the checks of the arguments the world and the
environments take (batch sizes, reset seeds). They import nothing of the package, so every
layer (config, world, policies, environments) can use them.

Units are SI throughout: metres (m), seconds (s), radians (rad), m/s, m/s^2.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np

# Physical bounds of the fields (SI). Generous, but finite: beyond them a config would
# overflow, give infinite rewards or describe no aircraft.
MAX_SPEED = 200.0  # m/s (UAVs, obstacles, wind, velocity noise)
MAX_ACCEL = 100.0  # m/s^2 (about 10 g)
MAX_DIST = 10_000.0  # m (separation radii, formation sizes, position noise)
MAX_TURN_RATE = 2.0 * math.pi  # rad/s (a full turn per second)
MAX_TIME = 1.0e6  # s (episode duration, switch times)
MAX_WEIGHT = 1.0e6  # reward weights
MAX_OBS = 1.0e6  # observation scales, clip bound and sensing range
# Lower bounds where a tiny positive value is accepted by "> 0" but describes nothing
# (an aircraft that cannot accelerate, a step of a picosecond: 10^14 steps per episode).
MIN_DT = 1.0e-3  # s
MIN_ACCEL = 1.0e-2  # m/s^2
MIN_SPEED = 1.0e-2  # m/s
#: Most environment steps in one episode (episode_duration / (dt * decision_interval)):
#: every step is simulated and, in an evaluation, recorded.
MAX_STEPS = 1_000_000


def check(cond: bool, name: str, value: object, what: str) -> None:
    """Raise unless ``cond``.

    Raises:
        ValueError: ``invalid config value {name}={value!r}: {what}``.
    """
    if not cond:
        raise ValueError(f"invalid config value {name}={value!r}: {what}")


def is_sequence(value: object) -> bool:
    """A sequence of values: any :class:`~collections.abc.Sequence` but text, or an array.

    Any sequence, not just ``tuple``/``list``: configs arrive as OmegaConf ``ListConfig``
    (Hydra, BenchMARL's YAML) and other sequence types.
    """
    if isinstance(value, np.ndarray):
        return True
    return isinstance(value, Sequence) and not isinstance(value, (str, bytes, bytearray))


def is_int(value: object) -> bool:
    """An integer: Python int or a numpy integer scalar (not a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real(value: object, *, any_real: bool = False) -> bool:
    """A real number: int, float or a numpy integer/floating scalar (not a bool).

    Args:
        value: The value to test.
        any_real: Also accept any :class:`numbers.Real` (e.g. a ``Fraction``) and 0-d
            integer/floating arrays. For values converted to float at once (actions);
            config fields keep the type they are given, so they take only the plain kinds.
    """
    if isinstance(value, (bool, np.bool_)):
        return False
    if not any_real:
        return isinstance(value, (int, float, np.floating, np.integer))
    if isinstance(value, np.ndarray):
        return value.ndim == 0 and value.dtype.kind in "fiu"
    return isinstance(value, (numbers.Real, np.integer, np.floating))


def check_finite(name: str, value: float, bound: float | None = None) -> None:
    """Check that ``value`` is a finite real, within ``[-bound, bound]`` if given.

    Raises:
        ValueError: Naming ``name`` and the value.
    """
    check(
        is_real(value) and math.isfinite(float(value)),
        name,
        value,
        "must be a finite number",
    )
    if bound is not None:
        check(abs(value) <= bound, name, value, f"must be in [-{bound:g}, {bound:g}]")


def check_positive(
    name: str, value: float, *, allow_zero: bool = False, hi: float, lo: float | None = None
) -> None:
    """Check that ``value`` is a finite real in ``(0, hi]``, or ``[0, hi]``, or ``[lo, hi]``.

    ``[0, hi]`` with ``allow_zero``; ``[lo, hi]`` with ``lo``.

    Raises:
        ValueError: Naming ``name`` and the value.
    """
    check_finite(name, value)
    if allow_zero:
        check(value >= 0, name, value, "must be >= 0")
    else:
        check(value > 0, name, value, "must be > 0")
    if lo is not None:
        check(value >= lo, name, value, f"must be >= {lo:g}")
    check(value <= hi, name, value, f"must be <= {hi:g}")


def check_int_in(name: str, value: int, lo: int, hi: int) -> None:
    """Check that ``value`` is an integer (not a bool) in ``[lo, hi]``.

    Raises:
        ValueError: Naming ``name`` and the value.
    """
    check(is_int(value), name, value, "must be an integer")
    check(lo <= value <= hi, name, value, f"must be in [{lo}, {hi}]")


def check_one_of(name: str, value: object, choices: tuple) -> None:
    """Check that ``value`` (``None`` or a string) is one of ``choices``.

    Raises:
        ValueError: Naming ``name``, the value and the choices.
    """
    check(
        (value is None or isinstance(value, str)) and value in choices,
        name,
        value,
        f"must be one of {choices}",
    )


def check_vector(name: str, value: object, length: int, bound: float) -> tuple[float, ...]:
    """A sequence of ``length`` finite reals within ``[-bound, bound]``, as a float tuple.

    Raises:
        ValueError: Naming ``name`` and the value.
    """
    check(
        is_sequence(value) and len(value) == length,
        name,
        value,
        f"must be a sequence of {length} numbers",
    )
    for v in value:  # type: ignore[union-attr]
        check(is_real(v) and math.isfinite(float(v)), name, value, "must be finite numbers")
        check(abs(v) <= bound, name, value, f"components must be in [-{bound:g}, {bound:g}]")
    return tuple(float(v) for v in value)  # type: ignore[union-attr]


def check_positive_int(name: str, value: object) -> int:
    """``value`` as an int when it is a positive integer (not a bool); else a named error.

    Raises:
        ValueError: ``{name} must be a positive integer, got {value!r}``.
    """
    if not is_int(value) or value < 1:  # type: ignore[operator]
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)  # type: ignore[call-overload]


def check_seed(seed: object, n_envs: int | None = None) -> None:
    """Check a reset seed as Gymnasium does; name the bad value.

    Args:
        seed: ``None`` or a non-negative int; with ``n_envs`` (the batched views) also a
            sequence of ``n_envs`` entries, each ``None`` or a non-negative int.
        n_envs: The batch size when sequences are accepted, else ``None``.

    Raises:
        TypeError: A seed that is not None, an int (bools, floats and strings are not) or,
            for batches, a list/tuple/array of them.
        ValueError: A negative seed, or a sequence of the wrong length.
    """
    if seed is None:
        return
    if is_int(seed):
        if seed < 0:  # type: ignore[operator]
            raise ValueError(f"seed must be >= 0, got {seed!r}")
        return
    kinds = "None or a non-negative int"
    if n_envs is None or not isinstance(seed, (list, tuple, np.ndarray)):
        if n_envs is not None:
            kinds += f", or a list of {n_envs} of them (one per environment)"
        raise TypeError(f"seed must be {kinds}, got {seed!r}")
    seeds = list(seed)
    if len(seeds) != n_envs:
        raise ValueError(f"expected {n_envs} seeds, got {len(seeds)}: {seed!r}")
    for i, s in enumerate(seeds):
        if s is not None and not is_int(s):
            raise TypeError(f"seed[{i}] must be None or a non-negative int, got {s!r}")
        if s is not None and s < 0:
            raise ValueError(f"seed[{i}] must be >= 0, got {s!r}")
