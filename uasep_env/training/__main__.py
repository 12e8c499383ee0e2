"""``python -m uasep_env.training RECIPE [flags]``: the same as ``uasep-train``."""

import sys

from uasep_env.training.cli import main

sys.exit(main())
