"""Which branches of the compiled kernels the twin cases of ``test_kernels.py`` never take.

Run as a script with ``NUMBA_DISABLE_JIT=1`` (``numba.njit`` then returns the Python
functions): every case of :data:`test_kernels.TWIN_CASES` goes through the kernels' Python
source under an opcode tracer, serially, then once more through the parallel loops, and
every conditional jump (``if``, ``and``/``or``, conditional expressions, ``for`` loops run
or skipped) of every function in ``uasep_env/_kernels`` is checked for both its outcomes.
Prints JSON: the branches the first case of each twin leaves untaken (the random states
alone), and those all the cases leave untaken (should be none). Read from CPython 3.11's
bytecode (``tests/test_kernels.py`` runs it there only).
"""

from __future__ import annotations

import dis
import importlib
import json
import os
import sys
import types
from pathlib import Path

KERNEL_MODULES = ("apf", "common", "draws", "ellipse_fit", "ellipsoids", "network", "noise",
                  "observations", "physics", "plan", "rewards", "scenario",
                  "separations")  # fmt: skip


def _functions(modules: list[types.ModuleType]) -> list[types.CodeType]:
    """The code of every function the kernel modules define (nested ones included)."""
    out = []
    for m in modules:
        for obj in vars(m).values():
            f = getattr(obj, "py_func", obj)
            if isinstance(f, types.FunctionType) and f.__module__ == m.__name__:
                stack = [f.__code__]
                while stack:
                    c = stack.pop()
                    out.append(c)
                    stack += [k for k in c.co_consts if isinstance(k, types.CodeType)]
    return out


def _untaken(codes: list[types.CodeType], seen: set) -> list[str]:
    """``function:line opname outcome`` of each branch outcome not in ``seen``."""
    missing = []
    for c in codes:
        ins = list(dis.get_instructions(c))
        for k, i in enumerate(ins):
            if not (("JUMP" in i.opname and "IF" in i.opname) or i.opname == "FOR_ITER"):
                continue
            start = k  # a long jump's EXTENDED_ARG prefix is where the tracer sees it
            while start and ins[start - 1].opname == "EXTENDED_ARG":
                start -= 1
            for to, outcome in ((i.argval, "jump"), (ins[k + 1].offset, "fall through")):
                if (c, ins[start].offset, to) not in seen:
                    missing.append(f"{c.co_name}:{i.positions.lineno} {i.opname} {outcome}")
    return missing


def main() -> None:
    if os.environ.get("NUMBA_DISABLE_JIT") != "1":
        raise SystemExit("run with NUMBA_DISABLE_JIT=1")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import test_kernels as tk

    from uasep_env import _numba
    from uasep_env._kernels import common

    modules = [importlib.import_module(f"uasep_env._kernels.{m}") for m in KERNEL_MODULES]
    files = {m.__file__ for m in modules}
    seen: set = set()

    def tracer(frame: types.FrameType, event: str, arg: object):
        if frame.f_code.co_filename not in files:
            return None
        frame.f_trace_opcodes = True
        frame.f_trace_lines = False
        last = [None]

        def step(frame: types.FrameType, event: str, arg: object):
            if event == "opcode":
                if last[0] is not None:
                    seen.add((frame.f_code, last[0], frame.f_lasti))
                last[0] = frame.f_lasti
            return step

        return step

    def run(name: str, args: tuple) -> None:
        fn = _numba.TWINS[name].compiled()
        sys.settrace(tracer)
        try:
            fn(*tk._copy(args))
        finally:
            sys.settrace(None)

    cases = {name: tk.TWIN_CASES[name]() for name in sorted(tk.TWIN_CASES)}
    for name, args in cases.items():
        run(name, args[0])
    codes = _functions(modules)
    first = _untaken(codes, seen)
    for name, args in cases.items():
        for a in args[1:]:
            run(name, a)
    common.PARALLEL_MIN = 0  # the parallel loops (and the wrappers' choice of them)
    common.THREADS[0] = 2  # whatever this machine's share of its cores
    for name, args in cases.items():
        run(name, args[0])
    sys.settrace(tracer)
    common.THREADS[0] = 1  # one thread: serial loops whatever the size
    common._parallel(common.PARALLEL_MIN + 1)
    common._forked[0] = True  # a forked child: serial loops whatever the size
    common._parallel(common.PARALLEL_MIN + 1)
    common._SIN_COS.clear()  # the check, made before the tracer ran: again
    common.sin_cos_agree()
    svml, common.numba.config.USING_SVML = common.numba.config.USING_SVML, True
    common._sin_cos_agree()  # numba on Intel's SVML: its sines may be vectorised
    common.numba.config.USING_SVML = svml
    sys.settrace(None)
    common._SIN_COS[:] = [False]  # numpy's sines not the C library's: the fit's kernels decline
    for name in ("ellipse_start", "node_arguments", "ellipse_nodes"):
        run(name, cases[name][0])
    print(json.dumps({"first_cases": first, "all_cases": _untaken(codes, seen)}))


if __name__ == "__main__":
    main()
