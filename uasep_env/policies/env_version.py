"""The env version a policy is played in: a checkpoint's own, the one it was trained in.

A policy checkpoint records the env version it was trained in
(:attr:`~uasep_env.policies.checkpoint.PolicyCheckpoint.env_version`); this package still
plays every version of :data:`~uasep_env.config.VERSION_DEFAULTS` (their defaults as
overrides of today's). ``uasep-eval``, ``uasep-bench`` and ``uasep-report`` read the
version of the checkpoints they are given here and play them in it: a policy is evaluated
in the env it was trained in, unless the user asks for another version.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from uasep_env.config import VERSION_DEFAULTS, EnvConfig, make_config
from uasep_env.policies.checkpoint import CheckpointError, PolicyCheckpoint
from uasep_env.policies.checkpoint_policy import EnvVersionWarning, _read, checkpoint_path
from uasep_env.policies.registry import POLICIES
from uasep_env.policies.shield import split_shield

__all__ = [
    "EnvVersionWarning",
    "choose_env_version",
    "current_version",
    "env_defaults_for",
    "policy_env_version",
    "version_config",
    "version_label",
]


def current_version() -> int:
    """This package's env version: the newest of :data:`~uasep_env.config.VERSION_DEFAULTS`.

    It is :data:`uasep_env.registration.ENV_VERSION` (``tests/test_env_versions.py``), read
    from the config layer, below the policies.
    """
    return max(VERSION_DEFAULTS)


def env_defaults_for(meta: PolicyCheckpoint, path: str | Path | None = None) -> dict[str, Any]:
    """The config overrides of the env version ``meta`` was trained in.

    Args:
        meta: The checkpoint's description.
        path: Its file, for the message.

    Returns:
        ``VERSION_DEFAULTS[meta.env_version]`` (empty for the current version).

    Raises:
        CheckpointError: (a ``ValueError``) for a version this package does not reproduce,
            naming the file and the version.
    """
    version = meta.env_version
    if version not in VERSION_DEFAULTS:
        playable = ", ".join(f"-v{v}" for v in sorted(VERSION_DEFAULTS))
        raise CheckpointError(
            f"{path if path is not None else 'checkpoint'}: trained in env -v{version}, which "
            f"this uasep-env does not reproduce (it plays {playable}); retrain it"
        )
    return VERSION_DEFAULTS[version]


def policy_env_version(spec: Any) -> int | None:
    """The env version the checkpoint named by ``spec`` was trained in; None for others.

    Args:
        spec: A policy name, shipped name or path, shielded (``+cbf``) or not, or a
            policy object (None: no checkpoint to read).

    Raises:
        CheckpointError: For a checkpoint of a version that is not reproduced
            (:func:`env_defaults_for`) or a file that is not a valid checkpoint.
    """
    if not isinstance(spec, (str, Path)):
        return None
    base = split_shield(str(spec))[0]
    path = None if base in POLICIES else checkpoint_path(base)
    if path is None:
        return None
    meta = _read(path)[0]
    env_defaults_for(meta, path)
    return meta.env_version


def choose_env_version(
    versions: Mapping[str, int], requested: int | None = None
) -> tuple[int, list[str]]:
    """The env version one comparison plays, and the lines that say why.

    Args:
        versions: ``policy label -> env version`` of the checkpoints among its policies.
        requested: The version the user asked for (``--env-version``), or None.

    Returns:
        ``(version, notes)``: ``requested`` if given (a note per checkpoint of another
        version: played anyway); else the checkpoints' common version (a note when it is
        not the current one); else the current version.

    Raises:
        ValueError: Without ``requested``, for checkpoints of different versions, naming them.
    """
    current = current_version()
    notes: list[str] = []
    if requested is not None:
        for label, v in versions.items():
            if v != requested:
                notes.append(
                    f"warning: {label} was trained in -v{v}, playing it in -v{requested} "
                    f"episodes (--env-version {v} to play its own)"
                )
        return requested, notes
    found = sorted(set(versions.values()))
    if len(found) > 1:
        named = ", ".join(f"{label} (-v{v})" for label, v in versions.items())
        raise ValueError(
            f"the checkpoints were trained in different env versions: {named}; evaluate them "
            "separately, or pick one with --env-version"
        )
    if not found or found[0] == current:
        return current, notes
    version = found[0]
    trained = ", ".join(label for label, v in versions.items())
    were = "were" if len(versions) > 1 else "was"
    notes.append(
        f"playing -v{version} episodes: {trained} {were} trained in -v{version} "
        f"(--env-version {current} to play the current ones)"
    )
    return version, notes


def version_config(config: EnvConfig, version: int, overrides: Mapping[str, Any] = ()) -> EnvConfig:
    """``config`` in env ``version``: that version's defaults on it, then ``overrides``.

    For a config built from today's defaults (a bank's, a report cell's): none of them sets
    a field a version changed, so the version's defaults replace today's there.
    """
    cfg = make_config(config, **VERSION_DEFAULTS[version]) if VERSION_DEFAULTS[version] else config
    return make_config(cfg, **dict(overrides)) if overrides else cfg


def version_label(label: str, version: int | None) -> str:
    """``label``, with `` (-vN)`` where ``version`` is not the current one (printed tables)."""
    if version is None or version == current_version():
        return label
    return f"{label} (-v{version})"
