r"""The leaderboard, ``uasep-bench``: every policy on the standard suite, in one command.

    uasep-bench --policy apf,orca,mypkg.ctrl:make_policy --out runs/bench --workers 4

Every policy (a registered or shipped name, ``+cbf`` for its shielded variant, a checkpoint
path, or a user's ``module:callable``) plays the suite's banks (:mod:`.banks`: the held-out
bank, the two collision courses, 8 and 32 UAVs, real traffic and real traffic slowed x0.2);
each row carries the collision and loss-of-separation rates (Wilson intervals), the max
deviation, conflict time and episode cost (Student-t intervals), and the max deviation at
equal safety along the policy's swept front (:mod:`.front`, :mod:`.summary`).

The modules: :mod:`.methods` (each method's knob and swept values, shared with
``uasep-tradeoff``), :mod:`.tradeoff` and :mod:`.sweep_rows` (that sweep, ``uasep-tradeoff``,
and its CSV), :mod:`.front` (Pareto fronts, the knee, interpolation at equal safety),
:mod:`.banks` (the suite's table of banks), :mod:`.entries` (the policies), :mod:`.runner`
(the cells, written as they finish; resume), :mod:`.summary` (the JSON layout), :mod:`.output`
(JSON, Markdown, figure) and :mod:`.cli`. Heavy parts are imported where used.
"""

from __future__ import annotations

from typing import Any

__all__ = ["main"]


def main(argv: Any = None) -> int:
    """Entry point of ``uasep-bench`` (:func:`uasep_env.benchmark.cli.main`)."""
    from uasep_env.benchmark.cli import main as cli_main

    return cli_main(argv)
