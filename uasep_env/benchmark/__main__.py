"""``python -m uasep_env.benchmark``: the ``uasep-bench`` command."""

import sys

from uasep_env.benchmark import main

sys.exit(main())
