"""The views of a scaling result: :mod:`uasep_env.reporting.scaling_views` (kept importable)."""

import uasep_env.reporting.scaling_views as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})
