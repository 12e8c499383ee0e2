"""Pick a run's best checkpoint on the validation encounters: the package's rule, here too.

The code lives in the package, :mod:`uasep_env.training.selection` (its docstring, or
``python train/select_checkpoint.py --help``, describes it); this script keeps
``python train/select_checkpoint.py RUN [flags]`` and ``import select_checkpoint`` (with
``train/`` on the path) working.
"""

import uasep_env.training.selection as _impl

# Every name of the package module, private helpers included, so that ``import`` users and
# tests of this script see what they saw before the code moved.
globals().update({k: v for k, v in vars(_impl).items() if not k.startswith("__")})

if __name__ == "__main__":
    _impl.main()
