"""The trade-off sweep's CSV: :mod:`uasep_env.benchmark.sweep_rows` (importable from here)."""

from uasep_env.benchmark.sweep_rows import *  # noqa: F403
from uasep_env.benchmark.sweep_rows import __all__  # noqa: F401
