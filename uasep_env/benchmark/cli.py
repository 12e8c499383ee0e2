"""The ``uasep-bench`` command line: parse, check, play the suite (resuming), write."""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["build_parser", "main"]

PROG = "uasep-bench"


def _budget(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a rate in [0, 1], got {text!r}") from None
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise argparse.ArgumentTypeError(f"must be a rate in [0, 1], got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The ``uasep-bench`` argument parser (a usage error is one line, exit status 2)."""
    from uasep_env import __version__
    from uasep_env.benchmark.banks import BANKS
    from uasep_env.evaluation.cli import _OneLineParser, _positive_int

    p = _OneLineParser(
        prog=PROG,
        description=(
            "The leaderboard: every policy on the standard suite of banks, with collision and "
            "loss-of-separation rates, deviation, conflict time and episode cost (95 % "
            "intervals), and each policy's max deviation at equal safety along its swept front."
        ),
        epilog=(
            "examples:\n"
            "  uasep-bench --out runs/bench\n"
            "  uasep-bench --policy apf,mypkg.ctrl:make_policy --out runs/mine --workers 4\n"
            "  uasep-bench --policy apf,orca --banks held_out --episodes 20 --no-front\n"
            f"banks: {', '.join(BANKS)}"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--policy",
        action="append",
        metavar="SPEC",
        help="registered or shipped name, a checkpoint path, or module:callable (a factory "
        "called with each bank's EnvConfig); +cbf for the shielded policy; LABEL=SPEC names "
        "its row; repeatable, comma-separated (default: the reference controllers)",
    )
    p.add_argument(
        "--banks",
        default=",".join(BANKS),
        metavar="NAMES",
        help="comma-separated banks (default: all)",
    )
    p.add_argument(
        "--episodes",
        type=_positive_int,
        default=None,
        metavar="N",
        help="play only each bank's first N seeds (quick runs; recorded in the JSON)",
    )
    p.add_argument(
        "--budget",
        type=_budget,
        default=None,
        metavar="R",
        help="loss-of-separation budget of the equal-safety column, in [0, 1] (default: "
        "the APF's rate at its default setting, per bank)",
    )
    p.add_argument(
        "--no-front", action="store_true", help="skip the knob sweeps (the default points only)"
    )
    p.add_argument(
        "--front-banks",
        default=None,
        metavar="NAMES",
        help="sweep the knobs on these banks only (default: every bank of --banks); the "
        "others get each policy's default point",
    )
    p.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override applied to every bank, repeatable (e.g. episode_duration=20)",
    )
    p.add_argument("--workers", type=_positive_int, default=1, metavar="N", help="processes")
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="play on Ray (local, or the cluster at ADDRESS); same numbers as --workers 1",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("runs/bench"),
        metavar="DIR",
        help="writes DIR/bench.{json,md,png} and the finished cells, DIR/cells/ "
        "(default: runs/bench)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="keep the finished cells in DIR (the default: a run into DIR always resumes)",
    )
    p.add_argument("--fresh", action="store_true", help="delete DIR/cells first and play all")
    p.add_argument("--no-figure", action="store_true", help="no DIR/bench.png")
    p.add_argument("--quiet", action="store_true", help="no progress and no table on stdout")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def _run(argv: Sequence[str] | None) -> int:
    from uasep_env.benchmark.banks import bank_config, check_banks
    from uasep_env.benchmark.entries import parse_entries
    from uasep_env.benchmark.output import markdown, write_outputs
    from uasep_env.benchmark.runner import REFERENCE, BenchError, plan_cells, run_cells
    from uasep_env.benchmark.summary import leaderboard
    from uasep_env.evaluation.cli import _one_line, _output_problem, _split_policy_args
    from uasep_env.evaluation.overrides import parse_config_overrides
    from uasep_env.policies import reference_controllers
    from uasep_env.viz.requirements import VIZ_HINT, matplotlib_available

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.fresh and args.resume:
        parser.error("arguments --fresh and --resume: choose one")
    try:
        banks = check_banks([b.strip() for b in args.banks.split(",") if b.strip()])
    except ValueError as err:
        parser.error(f"argument --banks: {err}")
    try:
        entries = parse_entries(_split_policy_args(args.policy or reference_controllers()))
    except ValueError as err:
        parser.error(f"argument --policy: {_one_line(err)}")
    try:
        overrides = parse_config_overrides(args.config)
        for bank in banks:  # every bank's config is checked before the first episode
            bank_config(bank, overrides)
    except (TypeError, ValueError) as err:
        parser.error(f"argument --config: {_one_line(err)}")
    problem = _output_problem(args.out, directory=True)
    if problem is not None:
        parser.error(f"argument --out: cannot write {str(args.out)!r}: {problem}")
    if not args.no_figure and not matplotlib_available():
        parser.error(f"the figure needs matplotlib ({VIZ_HINT}); or pass --no-figure")

    labels = {e.label for e in entries}
    reference = None
    if args.budget is None and REFERENCE not in labels:
        reference = parse_entries([REFERENCE])[0]  # the budget's reference, not a row
    front: bool | list[str] = not args.no_front
    if args.front_banks is not None:
        if args.no_front:
            parser.error("arguments --front-banks and --no-front: choose one")
        try:
            front = check_banks([b.strip() for b in args.front_banks.split(",") if b.strip()])
        except ValueError as err:
            parser.error(f"argument --front-banks: {err}")
        outside = [b for b in front if b not in banks]
        if outside:
            parser.error(f"argument --front-banks: {', '.join(outside)} not in --banks")
    cells = plan_cells(entries, banks, front, reference)
    if args.fresh:
        shutil.rmtree(args.out / "cells", ignore_errors=True)
    log = (lambda m: None) if args.quiet else (lambda m: print(f"{PROG}: {m}", file=sys.stderr))
    command = [PROG, *(sys.argv[1:] if argv is None else argv)]
    ray_started = False
    if args.ray is not None:  # one Ray for the whole suite (each evaluation joins it)
        try:
            import ray
        except ImportError:
            parser.error("argument --ray: ray is not installed (pip install 'uasep-env[clients]')")
        if not ray.is_initialized():
            ray.init(
                address=None if args.ray == "local" else args.ray,
                include_dashboard=False,
                log_to_driver=False,
            )
            ray_started = True
    try:
        stats = run_cells(
            cells,
            args.out,
            episodes=args.episodes,
            overrides=overrides,
            workers=args.workers,
            ray=args.ray,
            log=log,
        )
    except BenchError as err:
        parser.error(_one_line(err))
    finally:
        if ray_started:
            import ray

            ray.shutdown()
    board = leaderboard(
        entries,
        banks,
        stats,
        budget=args.budget,
        front=front,
        episodes=args.episodes,
        overrides=overrides,
        command=command,
    )
    written = write_outputs(board, args.out, not args.no_figure)
    if not args.quiet:
        print(markdown(board))
        for path in written:
            print(f"wrote {path}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``uasep-bench`` (also ``python -m uasep_env.benchmark``).

    Args:
        argv: Arguments (without the program name); ``sys.argv[1:]`` when None.

    Returns:
        0 on success, 2 for bad input (one line on stderr naming it: an unknown policy or
        bank, a budget outside [0, 1], a policy that fails or returns non-finite actions),
        1 for an output that cannot be written.
    """
    from uasep_env.evaluation.cli import exit_status

    return exit_status(PROG, _run, argv)
