"""A job compiles only the kernels it runs, each once (what ``make eval`` waits for).

numba compiles a kernel on its first call, once per argument type; a compiled kernel
(or one loaded from the disk cache) lists its argument types in ``dispatcher.signatures``.
A process that only evaluates the APF must not compile the policy network's kernel nor
the parallel loops it does not run, nor any kernel twice (``benchmarks/bench_compile.py``
times it).
"""

from __future__ import annotations

import json

import pytest
from conftest import run_python

from uasep_env import _numba

pytestmark = pytest.mark.skipif(
    not _numba.available(), reason="numba not installed or UASEP_NUMBA=0"
)

#: The loops one APF evaluation runs (serial: one thread), by ``module.function``.
APF_LOOPS = {
    "apf._apf_rows",  # the APF's decision
    "ellipsoids._pairs_serial",  # every UAV against every obstacle region
    "separations._separations_serial",
    "plan._plan_rows",
    "observations._observe_serial",
    "rewards._outcome_serial",  # rewards, episode ends, costs
    "physics._advance",  # the physics step
    "physics._move",
    "physics._sense",
}
#: The enclosing fit's kernels (the reachable ellipses, at reset): the -v3 default, the
#: calibrated region, is closed-form and does not run them.
ENCLOSING_FIT = {
    "ellipse_fit._start_rows",
    "ellipse_fit._arguments_rows",
    "ellipse_fit._nodes_rows",
    "ellipse_fit._fit_rows",
}

# In a fresh process: the APF evaluated, then every kernel module's dispatchers and the
# number of argument types each holds compiled.
_PROBE = """
    import importlib
    import json

    import numba
    from uasep_env import _numba
    from uasep_env.evaluation import evaluate

    evaluate(["apf"], {"scenario": "paper"}, [0])  # what make eval runs (whole episode)
    _numba.kernels()  # loaded, as every kernel call does
    counts = {}
    for name in ("apf", "common", "draws", "ellipse_fit", "ellipsoids", "network",
                 "observations", "physics", "plan", "rewards", "scenario", "separations"):
        module = importlib.import_module(f"uasep_env._kernels.{name}")
        for attr, obj in vars(module).items():
            if isinstance(obj, numba.core.registry.CPUDispatcher):
                parallel = bool(obj.targetoptions.get("parallel"))
                counts[f"{name}.{attr}"] = [len(obj.signatures), parallel]
    print(json.dumps(counts))
"""


@pytest.fixture(scope="module")
def compiled_by_apf_eval():
    """``{"module.function": [signatures compiled, parallel loop]}`` after an APF eval."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("UASEP_THREADS", "1")  # the serial loops, whatever this machine's cores
        done = run_python(_PROBE)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_apf_evaluation_compiles_only_the_kernels_it_runs(compiled_by_apf_eval):
    counts = compiled_by_apf_eval
    assert counts.keys() >= APF_LOOPS | ENCLOSING_FIT  # the names exist (no vacuous pass)
    compiled = {name for name, (n, _) in counts.items() if n}
    assert compiled >= APF_LOOPS
    assert not compiled & ENCLOSING_FIT, "the calibrated default ran the enclosing fit"
    assert counts["network._dense_into"][0] == 0  # a learned policy's kernel: not the APF's
    parallel = {name for name, (n, is_parallel) in counts.items() if n and is_parallel}
    assert not parallel, f"parallel loops compiled by a one-thread process: {parallel}"


def test_each_kernel_compiles_one_signature(compiled_by_apf_eval):
    """Callers pass views, copies and broadcasts: the kernels still compile once each."""
    twice = {name: n for name, (n, _) in compiled_by_apf_eval.items() if n > 1}
    assert not twice, f"kernels compiled for several argument types: {twice}"
