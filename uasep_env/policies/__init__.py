"""Policies behind one interface: ``actions = policy(observations)``.

The paper's APF (the reference), its two comparison methods, simple baselines, and learned
SB3 models.
"""

from __future__ import annotations

import os
from pathlib import Path

from uasep_env.config import EnvConfig
from uasep_env.policies.apf import APF, APFGains, MotionStateAPF, TraditionalAPF
from uasep_env.policies.base import Policy, RandomPolicy, ZeroPolicy
from uasep_env.policies.cbf import CBFQP, CBFFilter, CBFParams
from uasep_env.policies.checkpoint import CheckpointError
from uasep_env.policies.checkpoint_policy import (
    LearnedPolicy,
    checkpoint_config,
    checkpoint_path,
    is_policy_checkpoint,
    load_policy,
    observed_config,
)

# Every controller registers itself (uasep_env.policies.registry) when its module is
# imported: a new controller is its module plus its import here (docs/extending.md).
from uasep_env.policies.mvp import MVP, MVPParams
from uasep_env.policies.orca import ORCA, ORCAParams
from uasep_env.policies.registry import (
    POLICIES,
    REGISTRY,
    RegisteredPolicy,
    reference_controllers,
    register_policy,
)
from uasep_env.policies.sb3_policy import SB3Policy, load_sb3_policy
from uasep_env.policies.shield import SHIELDS, Shielded, split_shield
from uasep_env.policies.shipped import shipped_policies, shipped_policy_path

__all__ = [
    "APF",
    "CBFQP",
    "MVP",
    "ORCA",
    "POLICIES",
    "REGISTRY",
    "SHIELDS",
    "APFGains",
    "CBFFilter",
    "CBFParams",
    "CheckpointError",
    "LearnedPolicy",
    "MVPParams",
    "MotionStateAPF",
    "ORCAParams",
    "Policy",
    "RandomPolicy",
    "RegisteredPolicy",
    "SB3Policy",
    "Shielded",
    "TraditionalAPF",
    "ZeroPolicy",
    "check_policy_name",
    "checkpoint_config",
    "checkpoint_path",
    "is_policy_checkpoint",
    "load_policy",
    "load_sb3_policy",
    "make_policy",
    "observed_config",
    "reference_controllers",
    "register_policy",
    "shipped_policies",
    "shipped_policy_path",
    "split_label",
    "split_shield",
]


def _looks_like_path(name: str) -> bool:
    return name.endswith(".zip") or "/" in name or os.sep in name


def _unknown_policy(name: str) -> ValueError:
    names = sorted(POLICIES) + sorted(shipped_policies())
    if _looks_like_path(name) and not Path(name).exists():
        return ValueError(f"no such file {name!r} (a policy is one of {names} or a path)")
    return ValueError(f"unknown policy {name!r}: use one of {names} or a model path")


def split_label(item: str) -> tuple[str | None, str]:
    """Split a ``LABEL=SPEC`` policy value into its row's label and the policy (``"a=apf"``).

    A value without ``=``, or naming an existing file, gives ``(None, item)``.

    Raises:
        ValueError: An empty label or policy, naming the value.
    """
    if "=" not in item or Path(item).exists():
        return None, item
    label, _, spec = (part.strip() for part in item.partition("="))
    if not label or not spec:
        raise ValueError(f"{item!r}: empty label or policy in LABEL=SPEC")
    return label, spec


def check_policy_name(name: str) -> str:
    """Return ``name`` if it names a policy or an existing path.

    A name is a built-in policy (:data:`POLICIES`) or a shipped one
    (:func:`~uasep_env.policies.shipped.shipped_policies`).

    Args:
        name: A policy name or the path of a saved model.

    Returns:
        ``name``.

    Raises:
        ValueError: For an unknown name that is not an existing path (a path-like name,
            ending in ``.zip`` or holding a ``/``, is reported as a missing file).

    Examples:
        >>> check_policy_name("apf")
        'apf'
        >>> check_policy_name("apff")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: unknown policy 'apff': use one of ['apf', ...] or a model path
    """
    if name in POLICIES or Path(name).exists() or shipped_policy_path(name) is not None:
        return name
    base, shield = split_shield(name)
    if shield is not None:
        check_policy_name(base)
        return name
    raise _unknown_policy(name)


def make_policy(
    name: str, config: EnvConfig, allow_pickle: bool = False, algorithm: str | None = None
) -> Policy:
    """A policy by name (built-in or shipped) or from the path of a saved model.

    A path is loaded as a policy checkpoint (:func:`load_policy`, no unpickling); any other
    file as a stable-baselines3 model, only with ``allow_pickle`` (it runs code from the file).
    An existing file takes precedence over a shipped policy of the same name.

    Args:
        name: Built-in policy (:data:`POLICIES`), shipped policy, or path.
        config: The environment config the policy acts in.
        allow_pickle: Let a stable-baselines3 model file be unpickled.
        algorithm: The SB3 algorithm of such a file (``"PPO"``, ``"SAC"``, ...; default PPO).

    Raises:
        ValueError: For an unknown name that is not an existing file
            (:class:`CheckpointError`, a ``ValueError``, for a file that cannot be used).
    """
    if name in POLICIES:
        return POLICIES[name](config)
    check_policy_name(name)
    base, shield = split_shield(name)
    if shield is not None and not Path(name).exists():  # "<policy>+cbf": shielded
        return SHIELDS[shield](make_policy(base, config, allow_pickle, algorithm), config)
    if Path(name).is_file():
        if is_policy_checkpoint(name):
            return load_policy(name, config)
        return load_sb3_policy(name, config, algorithm=algorithm, allow_pickle=allow_pickle)
    shipped = shipped_policy_path(name)
    if shipped is not None and not Path(name).exists():
        return load_policy(shipped, config, name=name)
    raise _unknown_policy(name)  # an existing folder
