"""Train MAPPO-Lagrangian (a cost critic, a PID multiplier): ``uasep-train mappo_lagrangian``.

The recipe lives in the package, :mod:`uasep_env.training.mappo_lagrangian` (its docstring,
or ``python train/mappo_lagrangian.py --help``, describes it); this script keeps
``python train/mappo_lagrangian.py [flags]`` and ``import mappo_lagrangian`` (with
``train/`` on the path) working.
"""

import uasep_env.training.mappo_lagrangian as _impl

# Every name of the package module, private helpers included, as train/mappo.py does.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

if __name__ == "__main__":
    _impl.cli()
