"""A training run's folder: :mod:`uasep_env.training.rundir` (``import rundir`` still works)."""

import uasep_env.training.rundir as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})
