"""Train PPO under the safety constraint: ``uasep-train ppo_lagrangian`` in a checkout.

The recipe lives in the package, :mod:`uasep_env.training.ppo_lagrangian` (its docstring,
or ``python train/ppo_lagrangian.py --help``, describes it); this script keeps
``python train/ppo_lagrangian.py [flags]`` and ``import ppo_lagrangian`` working.
"""

import uasep_env.training.ppo_lagrangian as _impl

globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

if __name__ == "__main__":
    _impl.run()
