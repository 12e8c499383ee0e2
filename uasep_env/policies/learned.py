"""Learned policies, importable from one place (the names of the modules that hold them).

The project's checkpoints as policies live in :mod:`~uasep_env.policies.checkpoint_policy`,
stable-baselines3 models in :mod:`~uasep_env.policies.sb3_policy`, the checkpoint format in
:mod:`~uasep_env.policies.checkpoint` and :mod:`~uasep_env.policies.checkpoint_reader`.

Importing this module does not import stable-baselines3 or torch.
"""

from __future__ import annotations

# Each module's public names are listed once, in its own ``__all__``.
from uasep_env.policies import checkpoint, checkpoint_policy, checkpoint_reader, sb3_policy
from uasep_env.policies.checkpoint import *  # noqa: F403
from uasep_env.policies.checkpoint_policy import *  # noqa: F403
from uasep_env.policies.checkpoint_reader import *  # noqa: F403
from uasep_env.policies.sb3_policy import *  # noqa: F403

__all__ = [
    *checkpoint.__all__,
    *checkpoint_policy.__all__,
    *checkpoint_reader.__all__,
    *sb3_policy.__all__,
]
