"""The leaderboard's policies: a name, a shipped policy, a checkpoint, or ``module:callable``.

A row's default setting is played exactly as ``uasep-eval --policy`` plays it (by name, so
:func:`~uasep_env.evaluation.evaluate` rebuilds it for every chunk); a user's
``module:callable`` is a factory called with the bank's :class:`~uasep_env.EnvConfig`
that returns a policy (as ``uasep-report`` takes it). Any of these followed by ``+cbf``
is that policy under the shield. Each entry's front is its sweep's settings
(:func:`~uasep_env.benchmark.methods.sweep_of`; a shielded entry sweeps its base's knob
under the shield); an entry without a knob is its single point.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uasep_env.benchmark.methods import Method, sweep_of
from uasep_env.config import EnvConfig, make_config

__all__ = ["Entry", "build_point", "parse_entries", "point_config"]


@dataclass(frozen=True, kw_only=True)
class Entry:
    """One policy of the leaderboard.

    Attributes:
        label: Its row's name.
        spec: What the user gave (a name, ``name+cbf``, a path or ``module:callable``).
        kind: ``"name"`` (registered, shipped or a checkpoint file) or ``"factory"``.
        sweep: Its knob's sweep, or None (a single point).
        trained_version: For a policy checkpoint, the env version it was trained in (its
            row plays that version of every bank); None for anything else.
    """

    label: str
    spec: str
    kind: str
    sweep: Method | None
    trained_version: int | None = None

    @property
    def env_version(self) -> int:
        """The env version its row plays: a checkpoint's own, else the current one."""
        from uasep_env.policies.env_version import current_version

        return self.trained_version if self.trained_version is not None else current_version()

    @property
    def earlier_version(self) -> bool:
        """Whether its row plays an env version older than the current one."""
        from uasep_env.policies.env_version import current_version

        return self.env_version < current_version()

    @property
    def base(self) -> str:
        """The spec without its shield."""
        from uasep_env.policies import split_shield

        return split_shield(self.spec)[0]

    @property
    def shield(self) -> str | None:
        """The shield's name, or None."""
        from uasep_env.policies import split_shield

        return split_shield(self.spec)[1]


def parse_entries(specs: Sequence[str]) -> list[Entry]:
    """Entries for ``--policy`` values, in order, duplicates dropped.

    ``LABEL=SPEC`` names a policy's row (two checkpoint files of the same name, say); a
    shielded one's row keeps its ``+cbf``.

    Raises:
        ValueError: Naming a value that is no policy name, file or importable
            ``module:callable``, or a checkpoint of an env version this package does not
            play.
    """
    from uasep_env.policies import check_policy_name, split_label, split_shield
    from uasep_env.policies.env_version import policy_env_version
    from uasep_env.reporting.scaling import load_factory

    out: list[Entry] = []
    for item in dict.fromkeys(s.strip() for s in specs if s.strip()):
        try:
            named, spec = split_label(item)  # LABEL=SPEC: the row named LABEL
        except ValueError as err:
            raise ValueError(f"unknown policy {err}") from None
        base, _shield = split_shield(spec)
        if ":" in base and not Path(base).exists():
            try:
                load_factory(base)
            except ValueError as err:
                raise ValueError(f"unknown policy {spec!r}: {err}") from None
            out.append(Entry(label=named or spec, spec=spec, kind="factory", sweep=None))
            continue
        check_policy_name(spec)  # ValueError: "unknown policy 'x': use one of ..."
        sweep = sweep_of(base) if not Path(base).exists() else None
        label = spec if not Path(base).exists() else Path(base).stem + spec[len(base) :]
        if named:  # the shield stays in the row's name: "+cbf" rows are shielded
            label = named + spec[len(base) :]
        version = policy_env_version(base)  # a checkpoint's; ValueError: one not reproduced
        out.append(Entry(label=label, spec=spec, kind="name", sweep=sweep, trained_version=version))
    if not out:
        raise ValueError("no policy given")
    labels = [e.label for e in out]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two policies share a row name: {labels}")
    return out


def point_config(entry: Entry, bank_cfg: EnvConfig, value: float | None) -> EnvConfig:
    """The config a setting of ``entry`` is played with on a bank.

    Its knob's config, and a checkpoint's training observation where the bank's does not
    fit it (:func:`~uasep_env.evaluation.runner.policy_config`; the same episodes).
    """
    from uasep_env.evaluation.runner import policy_config

    cfg = bank_cfg
    if value is not None and entry.sweep is not None:
        extra = entry.sweep.config(value)
        cfg = make_config(cfg, **extra) if extra else cfg
    return policy_config(entry.base, cfg) if entry.kind == "name" else cfg


def build_point(entry: Entry, cfg: EnvConfig, value: float | None) -> Any:
    """The policy of one setting (``value`` None: the default).

    The name itself for a named policy's default (the evaluation builds it per chunk, as
    ``uasep-eval`` does), else a policy object.
    """
    from uasep_env.policies import SHIELDS
    from uasep_env.reporting.scaling import load_factory

    if value is None:
        if entry.kind == "name":
            return entry.spec
        policy = load_factory(entry.base)(cfg)
    else:
        assert entry.sweep is not None
        policy = entry.sweep.policy(cfg, value)
    return SHIELDS[entry.shield](policy, cfg) if entry.shield else policy
