"""The ``uasep-train`` command line: ``uasep-train RECIPE [flags]`` (``--help`` per recipe)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from uasep_env.training import RECIPES

__all__ = ["main"]

_TRAIN = 'install torch==2.13.0 first, then pip install "uasep-env[train]"'
#: What a recipe imports when it runs, and how to get it.
_EXTRAS = {
    "torch": _TRAIN,
    "stable_baselines3": _TRAIN,
    "tqdm": _TRAIN,
    "skrl": "pip install skrl, after the train extra",
}

_USAGE = "usage: uasep-train RECIPE [flags]   (uasep-train RECIPE --help: every flag)"


def _overview() -> str:
    width = max(map(len, RECIPES))
    lines = [_USAGE, "", "Train a shared policy for the uasep-env environments.", "", "recipes:"]
    lines += [f"  {name:<{width}}  {text}" for name, (_, text) in RECIPES.items()]
    lines += [
        "",
        "Each recipe needs the train extra (install torch==2.13.0 first; mappo* also skrl).",
        "A run writes progress.csv, curves.png, checkpoints/, policy.zip and validation.json",
        "to --out-dir; uasep-eval --policy OUT_DIR/policy.zip evaluates the result.",
    ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``uasep-train``.

    Args:
        argv: Arguments (without the program name); ``sys.argv[1:]`` when None.

    Returns:
        The exit status: 0 on success, 2 for bad arguments (one line naming the flag), 1 for
        a run that cannot start or a file that cannot be written.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        sys.stdout.write(_overview())
        return 0 if args else 2
    name, rest = args[0], args[1:]
    if name not in RECIPES:
        sys.stderr.write(
            f"uasep-train: error: unknown recipe {name!r}: choose from {', '.join(RECIPES)} "
            "(see uasep-train --help)\n"
        )
        return 2
    from uasep_env.training import ppo_shared

    module = importlib.import_module(RECIPES[name][0])
    ppo_shared._PROG.update(prog=f"uasep-train {name}", doc=module.__doc__ or "")
    try:
        module.run(rest)
    except ModuleNotFoundError as err:
        missing = (err.name or "").split(".")[0]
        if missing not in _EXTRAS:
            raise
        print(f"uasep-train {name}: error: it needs {missing} ({_EXTRAS[missing]})",
              file=sys.stderr)  # fmt: skip
        return 1
    except SystemExit as exc:
        code = exc.code
        if code is None or isinstance(code, int):
            return code or 0
        print(code, file=sys.stderr)
        return 1
    return 0
