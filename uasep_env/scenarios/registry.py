"""The registry of scenario families, and weighted mixes of them.

A family is one :class:`ScenarioFamily` object: its name, its generator (a
:class:`numpy.random.Generator` and the config in, one episode's :class:`ScenarioSpec` out)
and its documentation (a one-line summary and its parameters), registered once with
:func:`register`. Everything that lists families reads :data:`FAMILIES`: the config's
accepted names, the CLI's choices, the gym ids and the README's table
(``tools/sync_readme.py``). A :class:`Mix` draws one of several named entries by integer
weights, so that a mix of equal weights draws exactly as ``rng.integers(len(mix))`` did.

This module imports nothing of the package (the config validates ``scenario`` against it),
hence the plain ``Any`` for the config and the spec in the generator's signature.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "FAMILIES",
    "Mix",
    "ScenarioFamily",
    "get_family",
    "register",
    "scenario_defaults",
    "scenario_names",
]


@dataclass(frozen=True, kw_only=True)
class Mix:
    """Named entries drawn with integer weights: ``k`` with probability ``w_k / sum(w)``.

    One draw is ``rng.integers(sum(w))`` mapped onto the entries in order, so equal weights
    of 1 draw exactly as ``entries[rng.integers(len(entries))]``.

    Attributes:
        weights: Entry -> positive integer weight, in drawing order.
    """

    weights: Mapping[str, int]

    def __post_init__(self) -> None:
        bad = {k: w for k, w in self.weights.items() if not isinstance(w, int) or w < 1}
        if not self.weights or bad:
            raise ValueError(f"a Mix needs positive integer weights, got {dict(self.weights)!r}")

    @property
    def names(self) -> tuple[str, ...]:
        """The entries' names, in drawing order."""
        return tuple(self.weights)

    def draw(self, rng: np.random.Generator) -> str:
        """Draw one entry's name (one ``rng.integers`` call)."""
        k = int(rng.integers(sum(self.weights.values())))
        for name, w in self.weights.items():
            if k < w:
                return name
            k -= w
        raise AssertionError("unreachable: k < sum of the weights")

    def describe(self) -> str:
        """``a (1), b (2)``: the entries with their weights."""
        return ", ".join(f"`{n}` ({w})" for n, w in self.weights.items())


@dataclass(frozen=True, kw_only=True)
class ScenarioFamily:
    """One family of scenarios.

    Attributes:
        name: The ``EnvConfig.scenario`` value that selects it.
        summary: One line: what encounter it makes.
        parameters: What it draws per episode and from which ranges (units).
        generate: ``(rng, config: EnvConfig) -> ScenarioSpec``; all randomness from ``rng``.
        gym_name: Registers ``uasep/<gym_name>-v<version>`` with :attr:`defaults`
            (``None``: no gym id of its own).
        defaults: The config the family is meant to be flown with, applied where it is
            chosen by name (its gym id, ``uasep-eval --scenario``) before any override.
        mix: For a family that draws another family per episode (``random``), that mix.
        obstacle_model: The ``obstacle.model`` its episodes need (``"dubins"``, or
            ``"replay"`` for a family of recorded tracks); the config checks it.
        draws: Its batched form, ``(rng, config) -> EpisodeDraws``: the same draws as
            :attr:`generate`, in the same order, with the geometry left to
            :func:`uasep_env.scenarios.batched.geometry` (``None``: a batch of its episodes
            is generated one at a time).
        draw_tables: Its draws as tables, ``() -> (DrawTables, member)`` (made on first use;
            ``member`` -1: drawn per episode by the tables' mix): a batch of its episodes is
            drawn by :func:`uasep_env.scenarios.batched.encounter_draws`, compiled
            (``None``: by :attr:`draws`, one episode at a time).
    """

    name: str
    summary: str
    parameters: str
    generate: Callable[[np.random.Generator, Any], Any]
    gym_name: str | None = None
    defaults: Mapping[str, Any] = field(default_factory=dict)
    mix: Mix | None = None
    obstacle_model: str = "dubins"
    draws: Callable[[np.random.Generator, Any], Any] | None = None
    draw_tables: Callable[[], tuple[Any, int]] | None = None


#: Every registered family by name, in registration order.
FAMILIES: dict[str, ScenarioFamily] = {}


def register(family: ScenarioFamily) -> ScenarioFamily:
    """Add ``family`` to :data:`FAMILIES` (its name must be new) and return it."""
    if not family.name.isidentifier() or family.name in FAMILIES:
        raise ValueError(f"scenario family name {family.name!r} is taken or not an identifier")
    FAMILIES[family.name] = family
    return family


def scenario_names() -> tuple[str, ...]:
    """The names ``EnvConfig.scenario`` accepts, in registration order."""
    return tuple(FAMILIES)


def scenario_defaults(name: str) -> dict[str, Any]:
    """The config family ``name`` is meant to be flown with (empty if it has none)."""
    return dict(get_family(name).defaults)


def get_family(name: str) -> ScenarioFamily:
    """The family called ``name``.

    Raises:
        ValueError: Naming ``scenario`` and the known names, if there is none.
    """
    try:
        return FAMILIES[name]
    except KeyError:
        raise ValueError(
            f"invalid config value scenario={name!r}: must be one of {scenario_names()}"
        ) from None
