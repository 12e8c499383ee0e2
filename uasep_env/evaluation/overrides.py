"""The evaluation's environment config: a scenario, ``KEY=VALUE`` overrides and a base config."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import Any

from uasep_env.config import EnvConfig, make_config
from uasep_env.runtime.jsonio import json_depth
from uasep_env.scenarios import SCENARIO_DEFAULTS

__all__ = ["build_config", "parse_config_overrides"]


#: Deepest nesting a ``--config`` value may have (the config's deepest field is 2 levels).
MAX_VALUE_DEPTH = 8


def _short(text: str, limit: int = 80) -> str:
    """``repr`` of ``text``, cut to about ``limit`` characters (errors echo bad values)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text):,} chars)"


def _parse_value(text: str) -> Any:
    """JSON when it parses (numbers, true/false/null, lists, dicts), else the string."""
    depth = json_depth(text)
    if depth > MAX_VALUE_DEPTH:
        raise ValueError(f"value {_short(text)} nests {depth} levels, limit {MAX_VALUE_DEPTH}")
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_config_overrides(items: Iterable[str]) -> dict[str, Any]:
    """Turn ``KEY=VALUE`` strings into a nested override dict for :func:`make_config`.

    Dotted keys address nested fields (``noise.accel_std=0`` gives
    ``{"noise": {"accel_std": 0}}``). Values are parsed as JSON when possible (``0.5``,
    ``true``, ``null``, ``[1, 2, 3]``), otherwise kept as strings (``scenario=crossing``).

    Args:
        items: The ``KEY=VALUE`` strings, applied in order (later ones win).

    Returns:
        The nested overrides.

    Raises:
        ValueError: For an item without ``=``, an empty key, or a key that is used both as a
            value and as a section (e.g. ``noise=false`` and ``noise.accel_std=0``).
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"config override {_short(item)}: expected KEY=VALUE (e.g. dt=0.1)")
        parts = key.split(".")
        if any(not p for p in parts):
            raise ValueError(f"config override {_short(item)}: malformed key {_short(key)}")
        node = out
        for depth, part in enumerate(parts[:-1]):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise ValueError(
                    f"config override {_short(item)}: {where!r} was already set to a value"
                )
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise ValueError(
                f"config override {_short(item)}: {key!r} is a section with fields set"
            )
        try:
            node[parts[-1]] = _parse_value(raw.strip())
        except ValueError as err:
            raise ValueError(f"config override {key!r}: {err}") from None
    return out


def build_config(
    scenario: str | None = None,
    overrides: Iterable[str] | Mapping[str, Any] = (),
    base: EnvConfig | Mapping[str, Any] | None = None,
) -> EnvConfig:
    """Build the evaluation config: ``base``, then ``scenario``, then the overrides.

    Args:
        scenario: Scenario family (one of :data:`uasep_env.config.SCENARIOS`), or None to
            keep the base's. Its defaults (:data:`uasep_env.scenarios.SCENARIO_DEFAULTS`,
            e.g. 8 UAVs for ``large_formation``, as its gym id) come with it.
        overrides: ``KEY=VALUE`` strings (see :func:`parse_config_overrides`) or a nested dict.
        base: Base config or dict (defaults when None).

    Returns:
        The validated config.

    Raises:
        TypeError: For unknown keys (named).
        ValueError: For malformed overrides or invalid values (named).
    """
    values: dict[str, Any] = {}
    if scenario is not None:
        values.update(SCENARIO_DEFAULTS.get(scenario, {}))
        values["scenario"] = scenario
    if isinstance(overrides, Mapping):
        values.update(overrides)
    else:
        values.update(parse_config_overrides(overrides))
    cfg = base if isinstance(base, EnvConfig) else make_config(base)
    return make_config(cfg, **values)
