r"""Safety and deviation against the number of UAVs and of obstacles: ``uasep-report``.

The report lives in the package, :mod:`uasep_env.reporting.scaling` (its docstring, or
``python baselines/scaling.py --help``, describes it); this script keeps
``python baselines/scaling.py [flags]`` and ``import scaling`` (with ``baselines/`` on the
path) working, and records its command as ``python baselines/scaling.py ...``.
"""

import uasep_env.reporting.scaling as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})


def main(argv: list[str] | None = None) -> dict:
    """:func:`uasep_env.reporting.scaling.main`, recorded as ``python baselines/scaling.py``."""
    return _impl.main(argv, command="python baselines/scaling.py")


if __name__ == "__main__":
    main()
