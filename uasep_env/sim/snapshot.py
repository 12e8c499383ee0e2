"""A batched simulation's state as plain arrays: saved without pickle, restored once checked.

What a training run needs to continue its environments' episodes exactly (``--resume`` of
the SB3 recipes): the :class:`~uasep_env.sim.world.World`'s arrays, its per-environment
generators' states and the views' running figures, as a flat ``{name: array}`` dict that
``np.savez`` writes and ``np.load(allow_pickle=False)`` reads back. A state read from a file
is untrusted: :func:`check_arrays` compares every array with the one it will be copied
into (the same names, shapes and dtypes; no NaN; finite and within :data:`MAX_MAGNITUDE`
unless named as possibly infinite) before anything is written, so a refused state leaves the
world as it was. Errors are one-line ``ValueError`` naming the array.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

__all__ = [
    "MAX_MAGNITUDE",
    "check_arrays",
    "check_range",
    "copy_arrays",
    "generator_states",
    "generators_from",
    "ndarray_attributes",
]

#: Largest magnitude of a finite number in a saved state (m, s, m/s ... and counters): far
#: beyond any episode's, far below where the arithmetic would overflow.
MAX_MAGNITUDE = 1.0e12
_MASK64 = (1 << 64) - 1
#: The columns of a packed PCG64 state: the state's and the increment's 128-bit words (high,
#: low), whether a 32-bit half is cached, and that half.
_PCG64_COLUMNS = 6


def ndarray_attributes(obj: object, prefix: str, skip: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Every array attribute of ``obj`` (the live arrays, not copies), named ``prefix + name``.

    The generic part of a state: an array a class gains later is saved and restored without
    a list to update.
    """
    skipped = set(skip)
    return {
        prefix + name: value
        for name, value in vars(obj).items()
        if isinstance(value, np.ndarray) and name not in skipped
    }


def check_arrays(
    state: Mapping[str, Any],
    like: Mapping[str, np.ndarray],
    may_be_inf: Iterable[str] = (),
    meta: Iterable[str] = (),
) -> None:
    """``state`` has an array of ``like[name]``'s shape and dtype for every name of ``like``.

    Args:
        state: The saved arrays (from a file: untrusted).
        like: The arrays they will be copied into (or arrays of the shapes and dtypes
            expected).
        may_be_inf: Names whose values may be ``+-inf`` (a minimum over nothing).
        meta: Names of ``state`` checked elsewhere (not refused as unexpected).

    Raises:
        ValueError: One line naming the array: missing, unexpected, of the wrong shape or
            dtype, NaN, infinite or beyond :data:`MAX_MAGNITUDE`.
    """
    missing = sorted(set(like) - set(state))
    extra = sorted(set(state) - set(like) - set(meta))
    if missing:
        raise ValueError(f"{missing[0]}: missing")
    if extra:
        raise ValueError(f"{extra[0]!r:.60}: not part of the state")
    inf_ok = set(may_be_inf)
    for name, own in like.items():
        value = state[name]
        if not isinstance(value, np.ndarray):
            raise ValueError(f"{name}: {type(value).__name__}, not an array")
        if value.shape != own.shape:
            raise ValueError(f"{name}: shape {value.shape}, expected {own.shape}")
        if value.dtype != own.dtype:
            raise ValueError(f"{name}: dtype {value.dtype}, expected {own.dtype}")
        if value.dtype.kind in "fc":
            if np.isnan(value).any():
                raise ValueError(f"{name}: NaN values")
            finite = value[np.isfinite(value)]
            if name not in inf_ok and finite.size != value.size:
                raise ValueError(f"{name}: infinite values")
        elif value.dtype.kind in "iu":
            finite = value
        else:
            continue  # bools
        if finite.size and float(np.abs(finite).max()) > MAX_MAGNITUDE:
            raise ValueError(f"{name}: values beyond {MAX_MAGNITUDE:g} in magnitude")


def check_range(name: str, value: np.ndarray, low: float, high: float) -> None:
    """Every element of ``value`` in ``[low, high]`` (a counter, an index), else one line."""
    if value.size and not (value.min() >= low and value.max() <= high):
        raise ValueError(f"{name}: values outside [{low:g}, {high:g}]")


def copy_arrays(state: Mapping[str, np.ndarray], live: Mapping[str, np.ndarray]) -> None:
    """Copy each checked array of ``state`` into ``live``'s, in place.

    In place: the compiled kernels read read-only views made once of the live arrays
    (:meth:`uasep_env.sim.world.World.frozen_inputs`), which then show the restored state.
    """
    for name, own in live.items():
        np.copyto(own, state[name])


def generator_states(rngs: Iterable[np.random.Generator]) -> np.ndarray:
    """The states of PCG64 generators as a ``(n, 6)`` uint64 array (no pickle needed).

    Raises:
        TypeError: A generator over another bit generator (the worlds make PCG64 only).
    """
    rows = []
    for rng in rngs:
        if type(rng.bit_generator) is not np.random.PCG64:
            raise TypeError(f"only PCG64 generators are saved, not {rng.bit_generator!r}")
        s = rng.bit_generator.state
        state, inc = int(s["state"]["state"]), int(s["state"]["inc"])
        rows.append([state >> 64, state & _MASK64, inc >> 64, inc & _MASK64,
                     int(s["has_uint32"]), int(s["uinteger"])])  # fmt: skip
    return np.array(rows, dtype=np.uint64).reshape(-1, _PCG64_COLUMNS)


def generators_from(name: str, packed: Any, n: int) -> list[np.random.Generator]:
    """The ``n`` generators :func:`generator_states` packed into ``packed`` (checked first).

    Raises:
        ValueError: One line naming ``name``: not a ``(n, 6)`` uint64 array, a cached-half
            flag other than 0 or 1, or a cached half beyond 32 bits.
    """
    want = (n, _PCG64_COLUMNS)
    if not isinstance(packed, np.ndarray) or packed.shape != want or packed.dtype != np.uint64:
        shape = getattr(packed, "shape", None)
        dtype = getattr(packed, "dtype", type(packed).__name__)
        raise ValueError(f"{name}: {dtype} of shape {shape}, expected uint64 of shape {want}")
    if packed.size and (packed[:, 4].max() > 1 or packed[:, 5].max() > 0xFFFFFFFF):
        raise ValueError(f"{name}: a cached 32-bit half out of range")
    rngs = []
    for row in packed.tolist():
        bits = np.random.PCG64()
        bits.state = {
            "bit_generator": "PCG64",
            "state": {"state": (row[0] << 64) | row[1], "inc": (row[2] << 64) | row[3]},
            "has_uint32": row[4],
            "uinteger": row[5],
        }
        rngs.append(np.random.Generator(bits))
    return rngs
