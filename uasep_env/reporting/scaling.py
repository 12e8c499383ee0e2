r"""Safety and deviation against the number of UAVs and of obstacles, on a held-out bank.

The report a new method is published with (``docs/protocol.md``), as ``uasep-report``:

    uasep-report --policy apf,motion-state-apf,traditional-apf \\
        --episodes 50 --out baselines/results/scaling
    uasep-report --policy apf,ppo_residual_apf --policy mypackage.policies:make_policy \\
        --episodes 100 --held-out-episodes 500 --out runs/scaling

(``python baselines/scaling.py`` in a checkout is the same command.)

Every policy plays the same ``random`` encounters (crossing, head-on, overtaking, climbing,
multi-obstacle) drawn from :data:`SCALING_SEEDS` (7,000,000-7,000,999: disjoint from the
training, validation and held-out seeds of :mod:`uasep_env.scenarios` and from the
trade-off bank), in two sweeps: formations of ``--uavs`` (3, 8, 16, 32) UAVs with
``--base-obstacles`` (1) obstacle, and ``--obstacles`` (1, 2, 4) obstacles around
``--base-uavs`` (3) UAVs (``--full-grid``: every combination). The formation is the
paper's at 3 UAVs and a square ``grid`` (spacing 20 m) above (``--formation`` to choose
one pattern for every size). Each obstacle is aimed at a UAV of the formation.
``--held-out-episodes N`` adds the first N encounters of the held-out bank
(:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`, 3 UAVs and 1 obstacle, 200 s): with it, one
command gives every table a new method is reported with (``docs/protocol.md``).

Policies (``--policy``, comma-separated or repeated; ``LABEL=SPEC`` names one):

* a built-in name (``apf``, ``motion-state-apf``, ``traditional-apf``, ``zero``, ...),
  observing the environment's default layout;
* a policy checkpoint (``.zip`` in the project's format, or a shipped one by name:
  ``ppo_residual_apf``, ``ppo_shared``): it reads the observation layout
  it was trained with (its K nearest UAVs and obstacles:
  :func:`uasep_env.policies.observed_config`), so a checkpoint trained on 3 UAVs flies every
  size zero-shot, in the env version it was trained in (a ``-v2`` checkpoint plays the
  ``-v2`` version of each cell, and its rows' ``env_version`` says so);
* ``module:callable``: a factory called with each cell's :class:`~uasep_env.EnvConfig`
  and returning a policy (``actions = policy(observations)``);
* any of these followed by ``+cbf``: that policy under the CBF shield
  (:class:`~uasep_env.policies.shield.Shielded`; a checkpoint's shield reads the
  checkpoint's layout, its K nearest UAVs and obstacles).

Writes ``<out>.md`` (one table per sweep: rates with 95 % Wilson intervals, means with
95 % Student-t intervals, from :func:`uasep_env.metrics.aggregate`), ``<out>.json`` (every
aggregate of every cell) and ``<out>.png`` (every metric against the number of UAVs and of
obstacles, with the intervals), and prints the targets: at 8 and 32 UAVs, each
non-APF policy's collision rate no worse than the APF's, each "met", "not met" or "not
shown" with the episodes behind it (:func:`uasep_env.metrics.statistics.rate_verdict`: met
only if the policy's rate is no higher and its 95 % Wilson interval rules out a rate more
than 10 percentage points above the APF's; not met if its interval lies wholly above the
APF's; not shown otherwise, e.g. too few episodes). The tables carry each episode's cost
(the cost channel: a UAV's per-step costs summed, the team mean and the worst UAV). An
existing output is refused unless ``--force``.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from uasep_env import make_config
from uasep_env.config import EnvConfig
from uasep_env.evaluation import evaluate
from uasep_env.policies import (
    POLICIES,
    SHIELDS,
    is_policy_checkpoint,
    load_policy,
    observed_config,
    shipped_policy_path,
    split_label,
    split_shield,
)
from uasep_env.policies.env_version import current_version, policy_env_version, version_config
from uasep_env.reporting.scaling_views import APFS, METRICS, figure, markdown
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.jsonio import write_json
from uasep_env.scenarios import HELD_OUT_SEEDS, SCALING_SEEDS

__all__ = [
    "OBSTACLE_COUNTS",
    "UAV_COUNTS",
    "PolicyEntry",
    "build_parser",
    "cell_config",
    "cells",
    "checkpoint_layout",
    "evaluate_cell",
    "load_factory",
    "main",
    "parse_policies",
    "run",
]

#: The cells' formation sizes and obstacle counts (seeds: ``SCALING_SEEDS``).
UAV_COUNTS = (3, 8, 16, 32)
OBSTACLE_COUNTS = (1, 2, 4)


@dataclasses.dataclass(frozen=True, kw_only=True)
class PolicyEntry:
    """One policy of the comparison.

    Attributes:
        label: Its name in the tables.
        kind: ``"builtin"``, ``"checkpoint"`` or ``"factory"``.
        spec: The name, path or ``module:callable``.
        layout: For a checkpoint, its ``(k_uavs, k_obstacles)``; trained sizes in ``trained``.
        trained: For a checkpoint, ``(n_uavs, n_obstacles)`` it was trained with.
        env_version: For a checkpoint, the env version it was trained in: it plays that
            version of every cell (:mod:`uasep_env.policies.env_version`); None: the current.
        sizes: For a checkpoint trained at several formation sizes (``--formation-sizes``),
            those sizes; None: ``trained``'s alone.
    """

    label: str
    kind: str
    spec: str
    layout: tuple[int, int] | None = None
    trained: tuple[int, int] | None = None
    env_version: int | None = None
    sizes: tuple[int, ...] | None = None


def checkpoint_layout(path: str | Path) -> tuple[EnvConfig, tuple[int, int]]:
    """The training config of a checkpoint and its effective ``(k_uavs, k_obstacles)``."""
    meta = load_policy(path).meta
    layout = meta.observation_layout  # stored (format 2) or implied by its training config
    return meta.env_config, (layout.k_uavs, layout.k_obstacles)


def trained_sizes(meta: Any) -> tuple[int, ...] | None:
    """The formation sizes a checkpoint (its ``meta``) was trained at, or None (one size)."""
    args = meta.info.get("args")
    text = args.get("formation_sizes", "") if isinstance(args, dict) else ""
    return tuple(int(n) for n in text.split(",")) if text else None


def _checkpoint_entry(label: str, path: str) -> PolicyEntry:
    """The entry of a policy checkpoint file (its meta read once)."""
    meta = load_policy(path).meta
    layout = meta.observation_layout  # stored (format 2) or implied by its training config
    return PolicyEntry(
        label=label,
        kind="checkpoint",
        spec=path,
        layout=(layout.k_uavs, layout.k_obstacles),
        trained=(meta.env_config.n_uavs, meta.env_config.n_obstacles),
        env_version=policy_env_version(path),
        sizes=trained_sizes(meta),
    )


def _zero_shot(entry: PolicyEntry, n_uavs: int, n_obstacles: int) -> bool:
    """Whether a cell is one a checkpoint was not trained at (never, for a controller)."""
    if entry.trained is None:
        return False
    sizes = entry.sizes or (entry.trained[0],)
    return n_uavs not in sizes or n_obstacles != entry.trained[1]


def cell_config(
    n_uavs: int,
    n_obstacles: int,
    formation: str = "auto",
    entry: PolicyEntry | None = None,
    episode_duration: float | None = None,
) -> EnvConfig:
    """The environment of one cell, as ``entry`` observes it.

    Args:
        n_uavs: Formation size.
        n_obstacles: Obstacles (all aimed at the formation).
        formation: A pattern name, or ``"auto"``: the paper's at 3 UAVs, ``grid`` above.
        entry: A checkpoint's entry fixes the observation to its training layout (the same
            scales and K); anything else observes the default layout.
        episode_duration: Seconds per episode (None: the config's default).

    Returns:
        The validated config.
    """
    pattern = formation if formation != "auto" else ("paper" if n_uavs == 3 else "grid")
    extra: dict[str, Any] = {}
    if episode_duration is not None:
        extra["episode_duration"] = episode_duration
    config = make_config(
        scenario="random", n_uavs=n_uavs, n_obstacles=n_obstacles, formation=pattern, **extra
    )
    if entry is not None and entry.kind == "checkpoint":
        if entry.env_version is not None:  # the env version it was trained in
            config = version_config(config, entry.env_version)
        config = observed_config(split_shield(entry.spec)[0], config)
    return config


def load_factory(spec: str) -> Callable[[EnvConfig], Any]:
    """The callable named by ``module:callable`` (``ValueError`` naming ``spec`` otherwise)."""
    module, _, name = spec.partition(":")
    try:
        obj: Any = importlib.import_module(module)
        for part in name.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError, ValueError) as err:
        raise ValueError(
            f"--policy {spec!r}: cannot import {name!r} from {module!r} ({err})"
        ) from err
    if not callable(obj):
        raise ValueError(f"--policy {spec!r}: {name} is not callable")
    return obj


def parse_policies(specs: Sequence[str]) -> list[PolicyEntry]:
    """Entries for ``--policy`` values; an unknown one is a ``ValueError`` naming it."""
    entries: list[PolicyEntry] = []
    taken: set[str] = set()
    for item in (s.strip() for raw in specs for s in raw.split(",")):
        if not item:
            continue
        try:
            name, spec = split_label(item)  # LABEL=SPEC
        except ValueError as err:
            raise ValueError(f"--policy {err}") from None
        spec, shield = split_shield(spec)  # "<policy>+cbf": the policy, shielded
        if spec in POLICIES:
            entry = PolicyEntry(label=spec, kind="builtin", spec=spec)
        elif not Path(spec).exists() and (shipped := shipped_policy_path(spec)) is not None:
            entry = _checkpoint_entry(spec, str(shipped))  # a shipped checkpoint, by name
        elif Path(spec).is_file():
            if not is_policy_checkpoint(spec):
                raise ValueError(f"--policy {spec!r}: not a policy checkpoint (.zip)")
            entry = _checkpoint_entry(Path(spec).stem, spec)
        elif ":" in spec:
            load_factory(spec)
            entry = PolicyEntry(label=spec.rpartition(":")[2], kind="factory", spec=spec)
        else:
            raise ValueError(
                f"--policy {spec!r}: not a built-in policy {sorted(POLICIES)}, a checkpoint "
                "file or module:callable"
            )
        if shield is not None:
            entry = dataclasses.replace(
                entry, label=f"{entry.label}+{shield}", spec=f"{entry.spec}+{shield}"
            )
        if name is not None:
            entry = dataclasses.replace(entry, label=name.strip())
        if entry.label in taken:
            entry = dataclasses.replace(entry, label=f"{entry.label}-{len(taken) + 1}")
        taken.add(entry.label)
        entries.append(entry)
    if not entries:
        raise ValueError("--policy: give at least one policy")
    return entries


def cells(
    uavs: Sequence[int],
    obstacles: Sequence[int],
    base_uavs: int,
    base_obstacles: int,
    full_grid: bool = False,
) -> list[tuple[int, int]]:
    """The ``(n_uavs, n_obstacles)`` cells: the two sweeps (or every combination), sorted."""
    if full_grid:
        out = {(n, m) for n in uavs for m in obstacles}
    else:
        out = {(n, base_obstacles) for n in uavs} | {(base_uavs, m) for m in obstacles}
    return sorted(out)


def evaluate_cell(
    entries: Sequence[PolicyEntry],
    n: int,
    m: int,
    seeds: Sequence[int],
    formation: str = "auto",
    workers: int = 1,
    episode_duration: float | None = None,
) -> list[dict[str, Any]]:
    """Every entry on ``seeds`` with ``n`` UAVs and ``m`` obstacles: one row per entry.

    Built-in policies and factories share one evaluation (the default layout); each
    checkpoint gets its own, in its training layout. Every one plays the same encounters.
    """
    shared = [e for e in entries if e.kind != "checkpoint"]
    groups: list[tuple[EnvConfig, list[PolicyEntry]]] = []
    if shared:
        groups.append((cell_config(n, m, formation, None, episode_duration), shared))
    for e in entries:
        if e.kind == "checkpoint":
            groups.append((cell_config(n, m, formation, e, episode_duration), [e]))
    rows: dict[str, dict[str, Any]] = {}
    for cfg, group in groups:
        specs: dict[str, Any] = {}
        for e in group:
            specs[e.label] = e.spec
            if e.kind == "factory":
                spec, shield = split_shield(e.spec)
                policy = load_factory(spec)(cfg)
                specs[e.label] = SHIELDS[shield](policy, cfg) if shield else policy
        result = evaluate(specs, cfg, seeds, workers=workers)
        for e in group:
            agg = result.results[e.label].aggregate
            rows[e.label] = {
                "n_uavs": n,
                "n_obstacles": m,
                "policy": e.label,
                "zero_shot": _zero_shot(e, n, m),
                "formation": cfg.formation if isinstance(cfg.formation, str) else "slots",
                "env_version": e.env_version or current_version(),
                "metrics": {k: agg[k] for k, _, _ in METRICS if k in agg},
            }
    return [rows[e.label] for e in entries]


def run(
    entries: Sequence[PolicyEntry],
    grid: Sequence[tuple[int, int]],
    episodes: int,
    formation: str = "auto",
    workers: int = 1,
    episode_duration: float | None = None,
    held_out_episodes: int = 0,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Evaluate every entry in every cell on the same seeds; the JSON-ready result.

    With ``held_out_episodes``, also the first of the held-out bank
    (:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`: 3 UAVs, 1 obstacle, 200 s episodes).
    """
    seeds = list(SCALING_SEEDS)[:episodes]
    rows: list[dict[str, Any]] = []
    for n, m in grid:
        t0 = time.perf_counter()
        rows += evaluate_cell(entries, n, m, seeds, formation, workers, episode_duration)
        log(
            f"{n:>2} UAVs, {m} obstacle(s): {len(seeds)} episodes x {len(entries)} policies "
            f"in {time.perf_counter() - t0:.1f} s"
        )
    held: list[dict[str, Any]] = []
    if held_out_episodes:
        t0 = time.perf_counter()
        bank = list(HELD_OUT_SEEDS)[:held_out_episodes]
        held = evaluate_cell(entries, 3, 1, bank, "auto", workers)
        log(f"held-out bank: {len(bank)} episodes in {time.perf_counter() - t0:.1f} s")
    return {
        "seeds": {"first": seeds[0], "count": len(seeds), "bank": "SCALING_SEEDS"},
        "policies": [dataclasses.asdict(e) for e in entries],
        "cells": [list(c) for c in grid],
        "rows": rows,
        "held_out": held,
    }


def _counts(text: str, flag: str) -> tuple[int, ...]:
    try:
        vals = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"{flag}: comma-separated integers, got {text!r}") from err
    if not vals:
        raise argparse.ArgumentTypeError(f"{flag}: comma-separated integers, got {text!r}")
    return vals


def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    """The report's flags (a bad value is one line naming the flag; ``--help``: defaults)."""
    from uasep_env.training.args import (
        HelpFormatter,
        OneLineParser,
        non_negative_int,
        positive_float,
        positive_int,
    )

    p = OneLineParser(prog=prog, description=__doc__, formatter_class=HelpFormatter)
    p.add_argument(
        "--policy",
        action="append",
        default=None,
        help="name, checkpoint, LABEL=SPEC or module:callable; repeatable, "
        f"comma-separated (None: {','.join(APFS)})",
    )
    p.add_argument("--episodes", type=positive_int, default=50, help="encounters per cell")
    p.add_argument(
        "--uavs",
        type=lambda t: _counts(t, "--uavs"),
        default=UAV_COUNTS,
        help="formation sizes of the UAV sweep",
    )
    p.add_argument(
        "--obstacles",
        type=lambda t: _counts(t, "--obstacles"),
        default=OBSTACLE_COUNTS,
        help="obstacle counts of the obstacle sweep",
    )
    p.add_argument(
        "--base-uavs", type=positive_int, default=3, help="formation size of the obstacle sweep"
    )
    p.add_argument(
        "--base-obstacles", type=non_negative_int, default=1, help="obstacle count of the UAV sweep"
    )
    p.add_argument("--full-grid", action="store_true", help="every (UAVs, obstacles) pair")
    p.add_argument(
        "--formation",
        default="auto",
        help="formation pattern (auto: the paper's at 3 UAVs, grid above)",
    )
    p.add_argument(
        "--episode-duration",
        type=positive_float,
        default=None,
        help="seconds per episode (None: the config's 200)",
    )
    p.add_argument(
        "--held-out-episodes",
        type=non_negative_int,
        default=0,
        help="also the first N held-out encounters (3 UAVs, 1 obstacle; at most 500)",
    )
    p.add_argument("--workers", type=positive_int, default=1, help="evaluation processes")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("runs/scaling/scaling"),
        help="writes OUT.md, OUT.json and OUT.png",
    )
    p.add_argument("--no-figure", action="store_true", help="no OUT.png")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.add_argument(
        "--render",
        type=Path,
        default=None,
        help="rewrite the .md and .png of an existing .json (no episodes played)",
    )
    return p


def main(
    argv: list[str] | None = None, command: str = "uasep-report", prog: str | None = None
) -> dict[str, Any]:
    """Run the sweeps, write the table, JSON and figure, print the targets.

    Args:
        argv: The arguments (default ``sys.argv[1:]``).
        command: How the result records the command that made it.
        prog: The program name in messages (default: the script's).

    Returns:
        The result (what ``OUT.json`` holds).
    """
    import shlex

    p = build_parser(prog)
    args = p.parse_args(argv)
    if args.render is not None:
        return _render(args.render, not args.no_figure)
    if not 1 <= args.episodes <= len(SCALING_SEEDS):
        p.error(f"argument --episodes: must be in [1, {len(SCALING_SEEDS)}], got {args.episodes}")
    if not 0 <= args.held_out_episodes <= len(HELD_OUT_SEEDS):
        p.error(
            f"argument --held-out-episodes: must be in [0, {len(HELD_OUT_SEEDS)}], "
            f"got {args.held_out_episodes}"
        )
    if args.workers < 1:
        p.error(f"argument --workers: must be >= 1, got {args.workers}")
    try:
        entries = parse_policies(args.policy or list(APFS))
        grid = cells(args.uavs, args.obstacles, args.base_uavs, args.base_obstacles, args.full_grid)
        for n, m in grid:  # validate every cell before the first episode
            cell_config(n, m, args.formation, None, args.episode_duration)
    except ValueError as err:
        p.error(str(err))
    outs = [args.out.with_suffix(s) for s in (".md", ".json", ".png")]
    if not args.force and (clash := [str(o) for o in outs if o.exists()]):
        p.error(f"{', '.join(clash)} exist: pass --force to overwrite")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    result = run(
        entries,
        grid,
        args.episodes,
        args.formation,
        args.workers,
        args.episode_duration,
        args.held_out_episodes,
    )
    elapsed = time.perf_counter() - t0
    line = f"{command} " + shlex.join(sys.argv[1:] if argv is None else argv)
    result["command"], result["elapsed_s"] = line, elapsed
    if args.workers == 1:  # the CPU time of the episodes (all played in this process)
        result["cpu_s"] = time.process_time() - c0
    write_json(result, outs[1])
    _write_views(result, args.out, not args.no_figure)
    return result


def _write_views(result: dict[str, Any], out: Path, with_figure: bool) -> None:
    """The markdown (and figure) of a result, written atomically next to its JSON."""
    text = markdown(result, result["command"], result["elapsed_s"])
    atomic_write(out.with_suffix(".md"), text)
    if with_figure:
        figure(result, out.with_suffix(".png"))
    print(text)
    print(
        f"wrote {out.with_suffix('.md')}" + (f", {out.with_suffix('.png')}" if with_figure else "")
    )


def _render(path: Path, with_figure: bool) -> dict[str, Any]:
    """``--render``: the views of a results JSON this script wrote."""
    import json

    if path.suffix != ".json" or not path.is_file():
        raise SystemExit(f"--render: {path} is not a results .json file")
    result = json.loads(path.read_text())
    if not {"rows", "cells", "policies", "command", "elapsed_s"} <= set(result):
        raise SystemExit(f"--render: {path} is not a scaling result (uasep-report's)")
    for p in result["policies"]:  # written before the field: the checkpoint says
        if p["kind"] == "checkpoint" and "sizes" not in p and Path(p["spec"]).is_file():
            p["sizes"] = trained_sizes(load_policy(p["spec"]).meta)
    _write_views(result, path.with_suffix(""), with_figure)
    return result


def cli(argv: list[str] | None = None) -> int:
    """Entry point of ``uasep-report``: :func:`main`, exit status 0 (2: bad arguments)."""
    try:
        main(argv, prog="uasep-report")
    except OSError as err:
        print(f"uasep-report: error: {err}", file=sys.stderr)
        return 1
    return 0
