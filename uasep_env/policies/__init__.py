"""Policies behind one interface: ``actions = policy(observations)``.

The paper's APF (the reference), its two comparison methods, simple baselines, and learned
SB3 models.
"""

from __future__ import annotations

from pathlib import Path

from uasep_env.config import EnvConfig
from uasep_env.policies.apf import APF, APFGains, MotionStateAPF, TraditionalAPF
from uasep_env.policies.base import Policy, RandomPolicy, ZeroPolicy
from uasep_env.policies.learned import SB3Policy, load_sb3_policy

__all__ = [
    "APF",
    "POLICIES",
    "APFGains",
    "MotionStateAPF",
    "Policy",
    "RandomPolicy",
    "SB3Policy",
    "TraditionalAPF",
    "ZeroPolicy",
    "load_sb3_policy",
    "make_policy",
]

#: Built-in policies by name.
POLICIES = {
    "apf": APF,
    "motion-state-apf": MotionStateAPF,
    "traditional-apf": TraditionalAPF,
    "zero": ZeroPolicy,
    "random": RandomPolicy,
}


def make_policy(name: str, config: EnvConfig) -> Policy:
    """A policy by name (:data:`POLICIES`) or from the path of a saved SB3 model.

    Raises:
        ValueError: For an unknown name that is not an existing file.
    """
    if name in POLICIES:
        return POLICIES[name](config)
    if Path(name).exists():
        return load_sb3_policy(name, config)
    raise ValueError(f"unknown policy {name!r}: use one of {sorted(POLICIES)} or a model path")
