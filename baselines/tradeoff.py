"""Every controller's trade-off sweep, into the repository: ``uasep-tradeoff`` in a checkout.

The sweep lives in the package, :mod:`uasep_env.benchmark.tradeoff` (its docstring, or
``python baselines/tradeoff.py --help``, describes it); this script keeps
``python baselines/tradeoff.py [flags]`` writing where it always has (``docs/figures/``, the
tables the README quotes) and ``import tradeoff`` (with ``baselines/`` on the path) working.
Patch the package module, not this one, to change what the sweep calls.
"""

from collections.abc import Sequence
from pathlib import Path

import uasep_env.benchmark.tradeoff as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

ROOT = Path(__file__).resolve().parent
#: The repository's figures: the sweep's CSV, tables and figures the docs quote.
FIGURES = ROOT.parent / "docs" / "figures"
CHECKPOINTS = ROOT / "checkpoints"


def main(argv: Sequence[str] | None = None) -> None:
    """:func:`uasep_env.benchmark.tradeoff.main`, writing ``docs/figures/`` by default."""
    _impl.main(argv, default_out=FIGURES, prog="baselines/tradeoff.py")


if __name__ == "__main__":
    main()
