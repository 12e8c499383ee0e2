"""The ``uasep-eval`` command line (also ``python -m uasep_env.evaluation``): parse, run, write."""

from __future__ import annotations

import argparse
import math
import os
import sys
import textwrap
import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from uasep_env._numba import note_slow_kernels
from uasep_env.config import VERSION_DEFAULTS
from uasep_env.evaluation.output import write_csv, write_json
from uasep_env.evaluation.overrides import build_config
from uasep_env.evaluation.progress import progress_bar
from uasep_env.evaluation.report import format_summary
from uasep_env.evaluation.runner import DEFAULT_HOLD_TIME_S, evaluate, policy_config
from uasep_env.policies import (
    POLICIES,
    SHIELDS,
    check_policy_name,
    make_policy,
    shipped_policies,
)
from uasep_env.policies.checkpoint import ALGORITHMS as SB3_ALGORITHMS
from uasep_env.policies.env_version import (
    EnvVersionWarning,
    choose_env_version,
    current_version,
    policy_env_version,
)
from uasep_env.rollout import DEFAULT_DEVIATION_THRESHOLD_M, DEFAULT_SETTLE_TIME_S
from uasep_env.runtime.atomic import output_kind
from uasep_env.scenarios import scenario_names
from uasep_env.viz.requirements import VIZ_HINT, matplotlib_available

__all__ = ["build_parser", "main"]


def _split_policy_args(values: Iterable[str]) -> list[str]:
    """Split repeatable, comma-separated ``--policy`` values; keep order, drop duplicates.

    A value that is the path of an existing file is taken whole, commas and all.
    """
    names: list[str] = []
    for value in values:
        whole = value.strip()
        for part in [whole] if whole and Path(whole).is_file() else value.split(","):
            part = part.strip()
            if part and part not in names:
                names.append(part)
    return names


def _bounded(kind: type, minimum: float) -> Callable[[str], float]:
    """An argparse type: ``kind`` (int or float) parsed from text, finite and >= ``minimum``."""
    noun = "an integer" if kind is int else "a number"

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {noun}, got {text!r}") from None
        if kind is float and not (math.isfinite(value) and value >= minimum):
            raise argparse.ArgumentTypeError(
                f"must be a finite number >= {minimum:g}, got {text!r}"
            )
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum:g}, got {text!r}")
        return value

    return parse


class _OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (not the whole usage)."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` and a pointer to ``--help``; exit with status 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _one_line(err: BaseException, limit: int = 400) -> str:
    """An exception as one non-empty line, cut to about ``limit`` characters."""
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= limit else text[:limit] + f"... ({len(text):,} chars)"


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name the same file (resolved, or the same inode when both exist)."""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _output_problem(path: Path, directory: bool) -> str | None:
    """Why ``path`` cannot be written (a file, or a folder when ``directory``), or None.

    Checked before the evaluation runs, so that a bad path fails at once: the path must
    not be a folder (a file for ``directory``), its nearest existing parent must be a
    writable folder, and an existing target must be writable.
    """
    if not directory:
        try:
            output_kind(path)  # a block device or a socket is never written
        except OSError as err:
            return (err.strerror or str(err)).rpartition(f"{path}: ")[2]
    if path.exists():
        if directory and not path.is_dir():
            return "exists and is not a directory"
        if not directory and path.is_dir():
            return "is a directory"
        if not os.access(path, os.W_OK):
            return "is not writable"
        return None
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"{parent} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{parent} is not writable"
    return None


def _size_problem(args: argparse.Namespace, cfg: Any, n_policies: int) -> str | None:
    """What in the run's sizes and times cannot work, checked before it starts, or None."""
    from uasep_env.config.checks import MAX_TIME
    from uasep_env.evaluation.runner import default_batch_size
    from uasep_env.runtime.capacity import (
        EPISODE_RESULT_BYTES,
        available_memory,
        check_count,
        record_bytes,
    )

    for flag, value in (("--settle-time", args.settle_time), ("--hold-time", args.hold_time)):
        if value > MAX_TIME:  # a time past the episode's end is clipped to it; not 1e308
            return (
                f"argument {flag}: must be <= {MAX_TIME:g} s (the longest episode), got {value:g}"
            )
    results = args.episodes * n_policies * EPISODE_RESULT_BYTES
    if results > (free := available_memory()):
        return (f"argument --episodes: {args.episodes:,} episodes x {n_policies} policies keep "
                f"about {results / 1e9:,.3g} GB of results in memory, more than the "
                f"{free / 1e9:,.3g} GB available")  # fmt: skip
    batch = min(args.batch_size or default_batch_size(args.episodes), args.episodes)
    chunks = math.ceil(args.episodes / batch) * n_policies
    held = 1 if args.ray is not None else min(args.workers, chunks)
    try:
        check_count("batch_size", batch, cfg, extra_bytes=record_bytes(cfg), copies=held)
    except ValueError as err:
        flag = "--batch-size" if args.batch_size else "--episodes"
        return f"argument {flag}: {_one_line(err)}"
    return None


def _versions() -> list[int]:
    """The env versions this package plays (:data:`~uasep_env.config.VERSION_DEFAULTS`)."""
    from uasep_env.config import VERSION_DEFAULTS

    return sorted(VERSION_DEFAULTS)


def _env_version(text: str) -> int:
    """An argparse type: one of :func:`_versions`."""
    try:
        value = int(text)
    except ValueError:
        value = None
    if value not in _versions():
        raise argparse.ArgumentTypeError(
            f"choose from {', '.join(map(str, _versions()))} (the env versions this uasep-env "
            f"plays), got {text!r}"
        )
    return value


_positive_int = _bounded(int, 1)
_non_negative_int = _bounded(int, 0)
_non_negative_float = _bounded(float, 0.0)


def build_parser() -> argparse.ArgumentParser:
    """The ``uasep-eval`` argument parser.

    Returns:
        The parser.
    """
    from uasep_env import __version__

    p = _OneLineParser(
        prog="uasep-eval",
        description=(
            "Evaluate separation-management policies headlessly on the same seeded scenarios "
            "and report the paper's section-4 metrics (separation, collisions, deviation, "
            "conflict-resolution timeline, velocity/acceleration fluctuation)."
        ),
        epilog=(
            "examples:\n"
            "  uasep-eval --policy apf,motion-state-apf,traditional-apf --plot figs/\n"
            "  uasep-eval --policy apf --scenario random --episodes 100 --workers 4 "
            "--json out.json\n"
            "  uasep-eval --config noise=false --config obstacle.speed=6 --csv out.csv\n"
            f"policies: {', '.join([*POLICIES, *shipped_policies()])} or the path of a "
            "policy checkpoint (.zip)"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--policy",
        action="append",
        metavar="NAME",
        help="policy to evaluate; repeatable or comma-separated, all on the same seeds "
        "(default: apf); a value naming an existing file is one path, commas included",
    )
    p.add_argument(
        "--shield",
        choices=sorted(SHIELDS),
        default=None,
        metavar="NAME",
        help="filter every listed policy's actions through a safety shield: "
        f"{', '.join(sorted(SHIELDS))} (the CBF filter); rows are named POLICY+NAME "
        "(list 'apf,apf+cbf' without --shield to compare one policy with and without)",
    )
    p.add_argument(
        "--scenario",
        default="paper",
        choices=scenario_names(),
        metavar="NAME",
        help=f"scenario family: {', '.join(scenario_names())} (default: paper); a family's "
        "own defaults come with it (large_formation: 8 UAVs in a wedge, as its gym id), "
        "--config overrides them",
    )
    p.add_argument(
        "--env-version",
        type=_env_version,
        default=None,
        metavar="N",
        help=f"play the episodes of env -vN: {', '.join(map(str, _versions()))} (default: the "
        "version the policy checkpoints were trained in, else the current one, "
        f"{current_version()}); every policy plays the same episodes",
    )
    p.add_argument(
        "--episodes",
        type=_positive_int,
        default=1,
        metavar="N",
        help="episodes per policy (default: 1)",
    )
    p.add_argument(
        "--seed",
        type=_non_negative_int,
        default=0,
        help="first seed; episode k uses seed+k (default: 0)",
    )
    p.add_argument(
        "--workers",
        type=_positive_int,
        default=1,
        metavar="N",
        help="worker processes (default: 1 = in-process); results do not depend on it",
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="run the episodes as Ray tasks: on a local Ray (no ADDRESS) or on the cluster "
        "at ADDRESS ('auto', 'ray://head:10001'); results are the same as --workers 1",
    )
    p.add_argument(
        "--batch-size",
        type=_positive_int,
        default=None,
        metavar="N",
        help="episodes per batched simulator (default: ceil(episodes / 8) clipped to "
        "[16, 64], at most episodes; independent of --workers)",
    )
    p.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override, repeatable; dotted keys for nested fields "
        "(noise.accel_std=0); values parsed as JSON when possible",
    )
    p.add_argument(
        "--deviation-threshold",
        type=_non_negative_float,
        default=DEFAULT_DEVIATION_THRESHOLD_M,
        metavar="M",
        help="off-track deviation threshold in m (default: %(default)s)",
    )
    p.add_argument(
        "--settle-time",
        type=_non_negative_float,
        default=DEFAULT_SETTLE_TIME_S,
        metavar="S",
        help="deviation/fluctuation statistics start at this time in s (default: %(default)s)",
    )
    p.add_argument(
        "--hold-time",
        type=_non_negative_float,
        default=DEFAULT_HOLD_TIME_S,
        metavar="S",
        help="time back on track before a UAV counts as returned, in s (default: %(default)s)",
    )
    p.add_argument(
        "--json",
        type=Path,
        metavar="PATH",
        help="write everything machine-readable (strict JSON; gzipped if it ends in .gz) to PATH",
    )
    p.add_argument(
        "--csv", type=Path, metavar="PATH", help="write one row per (policy, episode) to PATH"
    )
    p.add_argument(
        "--plot",
        type=Path,
        metavar="DIR",
        help="write the paper's figures (first episode of each policy) to DIR",
    )
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bar and no summary on stdout (errors still go to stderr)",
    )
    p.add_argument(
        "--progress",
        action="store_true",
        help="show progress on stderr even when it is not a terminal (a log); never on stdout",
    )
    p.add_argument(
        "--allow-pickle",
        action="store_true",
        help="let a stable-baselines3 model file be unpickled, which runs code from it; "
        "only for files you trust (policy checkpoints never need it)",
    )
    p.add_argument(
        "--algorithm",
        choices=SB3_ALGORITHMS,
        default=None,
        metavar="NAME",
        help="the stable-baselines3 algorithm that saved a model file given with "
        f"--allow-pickle: {', '.join(SB3_ALGORITHMS)} (default: PPO)",
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


#: The options handed to :func:`~uasep_env.evaluation.evaluate` under their own names.
_EVALUATE_OPTIONS = ("workers", "batch_size", "deviation_threshold", "settle_time", "hold_time",
                     "allow_pickle", "ray", "algorithm")  # fmt: skip


def _run(argv: Sequence[str] | None) -> int:
    from uasep_env.runtime.cores import check_variables

    parser = build_parser()
    args = parser.parse_args(argv)
    try:  # read by the kernels deep in a run: checked here, one line
        check_variables()
    except ValueError as err:
        parser.error(str(err))

    names = _split_policy_args(args.policy or ["apf"])
    if not names:
        parser.error("argument --policy: no policy given")
    if args.shield is not None:
        names = [f"{name}+{args.shield}" for name in names]
    for name in names:
        try:
            name.encode("utf-8")
        except UnicodeEncodeError:  # the results, CSV and JSON, are labelled with it
            parser.error(
                f"argument --policy: {name!r} is not UTF-8 text; link to the file under a "
                "UTF-8 name"
            )
        try:
            check_policy_name(name)
        except ValueError as err:
            parser.error(f"argument --policy: {_one_line(err)}")
    if args.deviation_threshold <= 0:
        parser.error(
            f"argument --deviation-threshold: must be > 0, got {args.deviation_threshold:g}"
        )
    for flag, path, directory in (
        ("--json", args.json, False),
        ("--csv", args.csv, False),
        ("--plot", args.plot, True),
    ):
        problem = None if path is None else _output_problem(path, directory)
        if problem is not None:
            parser.error(f"argument {flag}: cannot write {str(path)!r}: {problem}")
    if args.plot is not None and not matplotlib_available():  # before hours of evaluation
        parser.error(f"argument --plot: the figures need matplotlib: {VIZ_HINT}")
    # An output must not overwrite an input, nor another output.
    if args.json is not None and args.csv is not None and _same_file(args.json, args.csv):
        parser.error(f"arguments --json and --csv: both write {str(args.json)!r}")
    for flag, path in (("--json", args.json), ("--csv", args.csv)):
        for name in names if path is not None else ():
            if name not in POLICIES and _same_file(path, Path(name)):
                parser.error(f"argument {flag}: {str(path)!r} is the policy being evaluated")
    # Checkpoints play the env version they were trained in (and the others beside them).
    trained: dict[str, int] = {}
    for name in names:
        try:
            version = policy_env_version(name)
        except (ValueError, OSError) as err:
            parser.error(f"argument --policy: cannot load {name!r}: {_one_line(err)}")
        if version is not None:
            trained[name] = version
    try:
        version, notes = choose_env_version(trained, args.env_version)
    except ValueError as err:
        parser.error(f"argument --policy: {_one_line(err)}")
    if not args.quiet:
        for note in notes:
            print(f"uasep-eval: {note}", file=sys.stderr)
    try:
        cfg = build_config(args.scenario, args.config, base=VERSION_DEFAULTS[version])
    except (TypeError, ValueError, RecursionError) as err:
        parser.error(f"argument --config: {_one_line(err)}")
    problem = _size_problem(args, cfg, len(names))
    if problem is not None:
        parser.error(problem)
    with warnings.catch_warnings():  # the notes above said it, once
        warnings.simplefilter("ignore", EnvVersionWarning)
        return _evaluate(args, parser, names, cfg, version, argv)


def _evaluate(
    args: argparse.Namespace,
    parser: argparse.ArgumentParser,
    names: list[str],
    cfg: Any,
    version: int,
    argv: Sequence[str] | None,
) -> int:
    """Load the policies (failing early), play them, print and write the results."""
    from uasep_env.config.options import pick

    for name in names:  # fail early on models that do not load
        try:
            observed = policy_config(name, cfg)  # a checkpoint's own layout where it must
            make_policy(name, observed, args.allow_pickle, args.algorithm)
        except Exception as err:
            parser.error(f"argument --policy: cannot load {name!r}: {_one_line(err)}")
        if observed != cfg and not args.quiet:
            o = observed.observation
            note = f"k_uavs={o.k_uavs}, k_obstacles={o.k_obstacles}"
            print(f"uasep-eval: {name} observes with its training observation ({note}); "
                  "same episodes", file=sys.stderr)  # fmt: skip

    seeds = list(range(args.seed, args.seed + args.episodes))
    if not args.quiet:
        note_slow_kernels()
    bar = progress_bar(len(names) * len(seeds), args.quiet, args.progress)
    try:
        result = evaluate(
            names,
            cfg,
            seeds,
            keep_episodes=1 if args.plot is not None else 0,
            progress=bar.update if bar is not None else None,
            **pick(args, *_EVALUATE_OPTIONS),
        )
    finally:
        if bar is not None:
            bar.close()
    result.command = ["uasep-eval", *(sys.argv[1:] if argv is None else argv)]
    result.env_version = version

    if not args.quiet:
        print(format_summary(result))
    written: list[Path] = []
    if args.json is not None:
        written.append(write_json(result, args.json))
    if args.csv is not None:
        written.append(write_csv(result, args.csv))
    if args.plot is not None:
        from uasep_env.plotting import plot_paper_figures

        first = {label: eps[0] for label, eps in result.episodes.items()}
        figs = plot_paper_figures(first, args.plot, accel_limit=cfg.uav.max_accel)
        if not args.quiet:
            names = textwrap.fill(
                ", ".join(f.name for f in figs),
                width=100,
                initial_indent="  ",
                subsequent_indent="  ",
                break_on_hyphens=False,
                break_long_words=False,
            )
            print(f"\n{len(figs)} figures (seed {seeds[0]}) in {args.plot}:\n{names}")
    if not args.quiet:
        for path in written:
            print(f"wrote {path}")
        print(f"({result.elapsed_s:.1f} s)")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``uasep-eval`` and ``python -m uasep_env.evaluation``.

    Args:
        argv: Arguments (without the program name); ``sys.argv[1:]`` when None.

    Returns:
        The exit status: 0 on success, 2 for bad arguments (one line on stderr that names
        the bad value; output paths are checked before the evaluation runs), 1 for an output
        file that still cannot be written.
    """
    return exit_status("uasep-eval", _run, argv)


def exit_status(
    prog: str, run: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None
) -> int:
    """``run(argv)``'s exit status, as every command of the package gives it.

    argparse's exits keep their status (``--help`` 0, a usage error 2); a message raised as
    ``SystemExit`` is printed and gives 1; an output that cannot be written (``OSError``) is
    one line naming it, status 1.
    """
    try:
        return run(argv)
    except SystemExit as exc:  # argparse: --help / --version (0) and usage errors (2)
        code = exc.code
        if code is None:
            return 0
        if isinstance(code, int):
            return code
        print(code, file=sys.stderr)
        return 1
    except OSError as err:
        print(f"{prog}: error: {_one_line(err)}", file=sys.stderr)
        return 1
