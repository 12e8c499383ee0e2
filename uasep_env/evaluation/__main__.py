"""``python -m uasep_env.evaluation``: the ``uasep-eval`` command line."""

import sys

from uasep_env.evaluation.cli import main

if __name__ == "__main__":  # spawn pool workers import this module too: run only as main
    sys.exit(main())
