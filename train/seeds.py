"""Train a recipe over several seeds, select on validation, report: ``uasep-seeds`` in a checkout.

The driver lives in the package, :mod:`uasep_env.training.seeds` (its docstring, or
``python train/seeds.py --help``, describes it); this script keeps
``python train/seeds.py [flags] [-- recipe flags]`` (recorded as such in its reports) and
``import seeds`` (with ``train/`` on the path) working. Patch the package module, not this
one, to change what the driver calls.
"""

from pathlib import Path
from typing import Any

import uasep_env.training.seeds as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

HERE = Path(__file__).resolve().parent
#: The recipes' scripts in this folder (``train/reproduce.py`` runs them by file).
RECIPES = {name: f"{recipe}.py" for name, recipe in _impl.RECIPES.items()}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """:func:`uasep_env.training.seeds.main`, recorded as ``python train/seeds.py``."""
    return _impl.main(argv, script="train/seeds.py")


if __name__ == "__main__":
    main()
