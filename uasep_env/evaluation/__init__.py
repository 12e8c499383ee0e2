r"""Headless evaluation of policies on the separation-management scenarios (``uasep-eval``).

Every policy is played on the **same seeds** (episode ``k`` uses ``seed + k``), so the
policies meet identical encounters (obstacles, noise), and the paper's section-4 metrics
(:mod:`uasep_env.metrics`) are computed per episode and aggregated per policy.

Command line (also ``python -m uasep_env.evaluation``)::

    uasep-eval --policy apf,motion-state-apf,traditional-apf --scenario paper \\
        --episodes 20 --seed 0 --workers 4 --config noise.accel_std=0 \\
        --json results.json --csv results.csv --plot figures/

Python::

    from uasep_env.evaluation import evaluate
    result = evaluate(["apf", "traditional-apf"], {"scenario": "crossing"}, range(10))
    result.results["apf"].aggregate["episode.min_obstacle_distance"]["mean"]

The modules: :mod:`.overrides` (the config from ``KEY=VALUE`` overrides), :mod:`.runner`
(chunks of seeds, in-process, in a process pool or on Ray; results independent of the worker
count), :mod:`.results` (the typed result and its JSON layout), :mod:`.output` (JSON, CSV),
:mod:`.report` (the side-by-side summary) and :mod:`.cli` (``uasep-eval``).
"""

from uasep_env.evaluation.cli import build_parser, main
from uasep_env.evaluation.output import result_to_json, write_csv, write_json
from uasep_env.evaluation.overrides import build_config, parse_config_overrides
from uasep_env.evaluation.report import format_summary, summary_rows
from uasep_env.evaluation.results import (
    EpisodeResult,
    EvaluationResult,
    EvaluationSettings,
    PolicyResult,
)
from uasep_env.evaluation.runner import (
    DEFAULT_BATCH_SIZE,
    DEFAULT_HOLD_TIME_S,
    MIN_DEFAULT_BATCH_SIZE,
    default_batch_size,
    evaluate,
)

__all__ = [
    "DEFAULT_BATCH_SIZE",
    "DEFAULT_HOLD_TIME_S",
    "MIN_DEFAULT_BATCH_SIZE",
    "EpisodeResult",
    "EvaluationResult",
    "EvaluationSettings",
    "PolicyResult",
    "build_config",
    "build_parser",
    "default_batch_size",
    "evaluate",
    "format_summary",
    "main",
    "parse_config_overrides",
    "result_to_json",
    "summary_rows",
    "write_csv",
    "write_json",
]
