"""Learned policies, importable from one place (the names of the modules that hold them).

The project's checkpoints as policies live in :mod:`~uasep_env.policies.checkpoint_policy`,
stable-baselines3 models in :mod:`~uasep_env.policies.sb3_policy`, the checkpoint format in
:mod:`~uasep_env.policies.checkpoint` and :mod:`~uasep_env.policies.checkpoint_reader`.

Importing this module does not import stable-baselines3 or torch.
"""

from __future__ import annotations

from uasep_env.policies.checkpoint import (
    ALGORITHMS,
    CHECKPOINT_FORMAT,
    META,
    CheckpointError,
    PolicyCheckpoint,
    StoredLayout,
    save_policy,
)
from uasep_env.policies.checkpoint_policy import (
    LearnedPolicy,
    checkpoint_config,
    checkpoint_path,
    dense,
    dense_sums,
    is_policy_checkpoint,
    load_policy,
    observed_config,
)
from uasep_env.policies.checkpoint_reader import LIMITS, CheckpointLimits, read_checkpoint
from uasep_env.policies.sb3_policy import SB3Policy, load_sb3_policy

__all__ = [
    "ALGORITHMS",
    "CHECKPOINT_FORMAT",
    "LIMITS",
    "META",
    "CheckpointError",
    "CheckpointLimits",
    "LearnedPolicy",
    "PolicyCheckpoint",
    "SB3Policy",
    "StoredLayout",
    "checkpoint_config",
    "checkpoint_path",
    "dense",
    "dense_sums",
    "is_policy_checkpoint",
    "load_policy",
    "load_sb3_policy",
    "observed_config",
    "read_checkpoint",
    "save_policy",
]
