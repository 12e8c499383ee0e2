"""The one JSON writer: plain-Python views of results, strict JSON text, and ``.json[.gz]`` files.

Every result of the package (episode metrics, evaluation results, aggregates) goes through
:func:`to_plain` on its way to JSON, so there is one set of conversion rules:

* a dataclass becomes a dict of its fields, in declaration order; a field's metadata may
  give it its own converter (``{PLAIN: fn}``, e.g. per-axis triples as ``{"x", "y", "z"}``)
  or leave it out (``{OMIT: True}`` always, ``{OMIT: None}`` when its value is None);
* mappings keep their order with ``str`` keys; tuples, lists and arrays become lists;
* numpy scalars become Python ``bool`` / ``int`` / ``float``;
* with ``strict``, non-finite floats become ``None`` (``null``), which strict JSON needs.
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_write

__all__ = [
    "OMIT",
    "PLAIN",
    "DuplicateKeyError",
    "dumps",
    "json_depth",
    "json_shape",
    "loads_bounded",
    "loads_unique",
    "to_plain",
    "write_json",
]

#: Field-metadata key: a function applied to the field's value before conversion.
PLAIN = "uasep_plain"
#: Field-metadata key: ``True`` leaves the field out of the plain view, ``None`` only when
#: its value is None.
OMIT = "uasep_omit"


def to_plain(value: Any, *, strict: bool = False) -> Any:
    """Return a plain-Python (JSON-able) view of ``value``; see the module docstring.

    Args:
        value: A dataclass, mapping, sequence, array, numpy or Python scalar (nested).
        strict: Write non-finite floats as None (strict JSON has no NaN / inf).

    Returns:
        Nested dict / list / bool / int / float / str / None.
    """
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(value):
            item = getattr(value, f.name)
            omit = f.metadata.get(OMIT, False)
            if omit is True or (omit is None and item is None):
                continue
            convert = f.metadata.get(PLAIN)
            out[f.name] = to_plain(convert(item) if convert else item, strict=strict)
        return out
    if isinstance(value, Mapping):
        return {str(k): to_plain(v, strict=strict) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return None if strict and not math.isfinite(v) else v
    if isinstance(value, (tuple, list, np.ndarray)):
        return [to_plain(v, strict=strict) for v in value]
    return value


def dumps(value: Any, **kwargs: Any) -> str:
    """Strict JSON text of ``value`` (non-finite floats written as ``null``).

    Args:
        value: Anything :func:`to_plain` takes.
        **kwargs: Passed on to :func:`json.dumps` (e.g. ``indent``).

    Returns:
        The JSON text.
    """
    return json.dumps(to_plain(value, strict=True), allow_nan=False, **kwargs)


def write_json(value: Any, path: str | Path) -> Path:
    """Write :func:`dumps` (indented, newline-terminated) to ``path``, creating its folders.

    A path ending in ``.gz`` is gzip-compressed with a zero time stamp, so the same value
    gives the same bytes (per-episode results of large banks shrink about tenfold). The file
    is written atomically (:func:`uasep_env.runtime.atomic.atomic_write`).

    Args:
        value: Anything :func:`to_plain` takes.
        path: Output file.

    Returns:
        The path written.
    """
    path = Path(path)
    data = (dumps(value, indent=2) + "\n").encode("utf-8")
    if path.suffix == ".gz":
        data = gzip.compress(data, mtime=0)
    return atomic_write(path, data)


#: What :func:`json_depth` looks at: an escape pair, a quote, a bracket.
_TOKENS = re.compile(r'\\.|["\[\]{}]', re.DOTALL)


def json_depth(text: str) -> int:
    """Deepest ``[``/``{`` nesting of JSON text, found without parsing it (strings skipped).

    Lets a reader refuse deeply nested input before :func:`json.loads` recurses into it.

    Args:
        text: JSON text (need not be valid).

    Returns:
        The largest number of open brackets at any point.
    """
    return json_shape(text)[0]


def json_shape(text: str) -> tuple[int, int]:
    """Deepest nesting and number of arrays and objects of JSON text, without parsing it.

    What :func:`json.loads` would build is bounded by them (a list or dict costs at least
    56 bytes of Python objects, ``[]`` two bytes of text), so a reader can refuse before.

    Args:
        text: JSON text (need not be valid).

    Returns:
        ``(deepest nesting, number of [ and { outside strings)``.
    """
    # One pass over the tokens that matter: linear time, little memory. (A regex that skips
    # whole strings backtracks quadratically on an unterminated string of escaped quotes.)
    # Exact for valid JSON; on invalid JSON exact up to the first backslash outside a string,
    # which is where json.loads stops anyway.
    depth = deepest = containers = 0
    inside = False
    for match in _TOKENS.finditer(text):
        token = match[0]
        if token == '"':
            inside = not inside
        elif inside or len(token) == 2:  # in a string, or an escape pair
            continue
        elif token in "[{":
            depth += 1
            containers += 1
            deepest = max(deepest, depth)
        else:
            depth -= 1
    return deepest, containers


class DuplicateKeyError(ValueError):
    """A JSON object names one key twice (:func:`json.loads` would silently keep the last)."""


def _unique_pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            shown = repr(key) if len(key) <= 60 else repr(key[:57]) + "..."
            raise DuplicateKeyError(f"duplicate key {shown}")
        out[key] = value
    return out


def loads_unique(text: str | bytes) -> Any:
    """:func:`json.loads`, refusing an object that names a key twice.

    Files from elsewhere are read with it: with two ``clip_obs`` fields, which one a reader
    obeys should not be decided silently.

    Raises:
        DuplicateKeyError: An object with a repeated key (a :class:`ValueError`, named).
        json.JSONDecodeError: Not JSON.
    """
    return json.loads(text, object_pairs_hook=_unique_pairs)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number (strict JSON has no NaN or Infinity)")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e999 parses to inf
        raise ValueError(f"{text[:40]} is beyond the float range")
    return value


def loads_bounded(text: str | bytes, *, max_depth: int = 16, max_containers: int = 100_000) -> Any:
    """Strict JSON from elsewhere, within limits: the one reader of untrusted JSON text.

    Nesting and the number of arrays and objects are bounded before parsing
    (:func:`json_shape`), a repeated key is refused (:func:`loads_unique`), and so are
    ``NaN`` and ``Infinity`` and numbers beyond the float range (Python's :mod:`json` accepts
    them; strict JSON does not).

    Raises:
        ValueError: Not UTF-8, not JSON, too deep, too many containers, a repeated key or a
            non-finite constant: one line without the path (the caller adds it).
    """
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as err:
            raise ValueError(f"not UTF-8 ({err.reason} at byte {err.start})") from None
    depth, containers = json_shape(text)
    if depth > max_depth:
        raise ValueError(f"nests {depth} levels deep, limit {max_depth}")
    if containers > max_containers:
        raise ValueError(f"holds {containers:,} arrays and objects, limit {max_containers:,}")
    try:
        return json.loads(
            text,
            object_pairs_hook=_unique_pairs,
            parse_constant=_no_constant,
            parse_float=_finite_float,
        )
    except json.JSONDecodeError as err:
        raise ValueError(f"not JSON ({err.msg} at line {err.lineno} column {err.colno})") from None
