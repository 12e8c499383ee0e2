"""Train one PPO policy shared by every UAV: ``uasep-train ppo_shared`` in a checkout.

The recipe lives in the package, :mod:`uasep_env.training.ppo_shared` (its docstring, or
``python train/ppo_shared.py --help``, describes it); this script keeps
``python train/ppo_shared.py [flags]`` and ``import ppo_shared`` (with ``train/`` on the
path) working.
"""

import uasep_env.training.ppo_shared as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

if __name__ == "__main__":
    _impl.cli()
