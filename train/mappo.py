"""Train MAPPO (skrl; a centralised critic): ``uasep-train mappo`` in a checkout.

The recipe lives in the package, :mod:`uasep_env.training.mappo` (its docstring, or
``python train/mappo.py --help``, describes it); this script keeps
``python train/mappo.py [flags]`` and ``import mappo`` (with ``train/`` on the path) working.
"""

import uasep_env.training.mappo as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

if __name__ == "__main__":
    _impl.cli()
