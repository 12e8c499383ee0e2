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
    result["results"]["apf"]["aggregate"]["episode.min_obstacle_distance"]["mean"]

Reproducibility: the seeds are split into chunks (one batched simulator each) whose size
depends only on the number of episodes and ``batch_size`` (:func:`default_batch_size`), never
on ``workers``. Each chunk is played by a fresh policy built from its name (the ``random``
policy's generator is seeded with the chunk's first seed), in-process (``workers=1``) or in a
``spawn`` process pool, or as Ray tasks on a local Ray or a cluster (``--ray [ADDRESS]``),
and the chunks are reassembled in seed order. The results are therefore identical for any
worker count and on Ray, for stochastic policies too.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import json
import math
import multiprocessing
import os
import sys
import textwrap
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from uasep_env.config import SCENARIOS, EnvConfig, make_config
from uasep_env.metrics import aggregate, episode_metrics, flatten_metrics
from uasep_env.policies import POLICIES, Policy, RandomPolicy, make_policy
from uasep_env.rollout import (
    DEFAULT_DEVIATION_THRESHOLD_M,
    DEFAULT_SETTLE_TIME_S,
    Episode,
    run_episodes,
)

__all__ = [
    "DEFAULT_BATCH_SIZE",
    "DEFAULT_HOLD_TIME_S",
    "MIN_DEFAULT_BATCH_SIZE",
    "build_config",
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

#: Largest number of episodes simulated together in one batched simulator (by default).
DEFAULT_BATCH_SIZE = 64
#: Smallest default chunk: batching many episodes is much cheaper per episode.
MIN_DEFAULT_BATCH_SIZE = 16
#: Hold time of the conflict-resolution timeline (s), see :func:`metrics.conflict_timelines`.
DEFAULT_HOLD_TIME_S = 2.0

PolicySpec = str | Policy


# --------------------------------------------------------------------------------------------
# Configuration from KEY=VALUE overrides
# --------------------------------------------------------------------------------------------


def _parse_value(text: str) -> Any:
    """JSON when it parses (numbers, true/false/null, lists, dicts), else the string."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def parse_config_overrides(items: Iterable[str]) -> dict[str, Any]:
    """Turn ``KEY=VALUE`` strings into a nested override dict for :func:`make_config`.

    Dotted keys address nested fields (``noise.accel_std=0`` gives
    ``{"noise": {"accel_std": 0}}``). Values are parsed as JSON when possible (``0.5``,
    ``true``, ``null``, ``[1, 2, 3]``), otherwise kept as strings (``scenario=crossing``).

    Args:
        items: The ``KEY=VALUE`` strings, applied in order (later ones win).

    Returns:
        The nested overrides.

    Raises:
        ValueError: For an item without ``=``, an empty key, or a key that is used both as a
            value and as a section (e.g. ``noise=false`` and ``noise.accel_std=0``).
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"config override {item!r}: expected KEY=VALUE (e.g. dt=0.1)")
        parts = key.split(".")
        if any(not p for p in parts):
            raise ValueError(f"config override {item!r}: malformed key {key!r}")
        node = out
        for depth, part in enumerate(parts[:-1]):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise ValueError(f"config override {item!r}: {where!r} was already set to a value")
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise ValueError(f"config override {item!r}: {key!r} is a section with fields set")
        node[parts[-1]] = _parse_value(raw.strip())
    return out


def build_config(
    scenario: str | None = None,
    overrides: Iterable[str] | Mapping[str, Any] = (),
    base: EnvConfig | Mapping[str, Any] | None = None,
) -> EnvConfig:
    """Build the evaluation config: ``base``, then ``scenario``, then the overrides.

    Args:
        scenario: Scenario family (one of :data:`uasep_env.config.SCENARIOS`), or None to
            keep the base's.
        overrides: ``KEY=VALUE`` strings (see :func:`parse_config_overrides`) or a nested dict.
        base: Base config or dict (defaults when None).

    Returns:
        The validated config.

    Raises:
        TypeError: For unknown keys (named).
        ValueError: For malformed overrides or invalid values (named).
    """
    values: dict[str, Any] = {}
    if scenario is not None:
        values["scenario"] = scenario
    if isinstance(overrides, Mapping):
        values.update(overrides)
    else:
        values.update(parse_config_overrides(overrides))
    cfg = base if isinstance(base, EnvConfig) else make_config(base)
    return make_config(cfg, **values)


# --------------------------------------------------------------------------------------------
# Policies
# --------------------------------------------------------------------------------------------


def _split_policy_args(values: Iterable[str]) -> list[str]:
    """Split repeatable, comma-separated ``--policy`` values; keep order, drop duplicates."""
    names: list[str] = []
    for value in values:
        for part in value.split(","):
            part = part.strip()
            if part and part not in names:
                names.append(part)
    return names


def _policy_label(spec: str, taken: Iterable[str]) -> str:
    """A short, unique display label: the name, or a model file's stem."""
    label = spec if spec in POLICIES else Path(spec).stem or spec
    taken = set(taken)
    base, k = label, 2
    while label in taken:
        label, k = f"{base}-{k}", k + 1
    return label


def _normalise_policies(
    policies: PolicySpec | Sequence[PolicySpec] | Mapping[str, PolicySpec],
) -> dict[str, PolicySpec]:
    if isinstance(policies, (str, Policy)):
        policies = [policies]
    if isinstance(policies, Mapping):
        out = {str(k): v for k, v in policies.items()}
    else:
        out = {}
        for spec in policies:
            if isinstance(spec, str):
                label = _policy_label(spec, out)
            else:
                label = _policy_label(str(getattr(spec, "name", type(spec).__name__)), out)
            out[label] = spec
    if not out:
        raise ValueError("policies: give at least one policy")
    for label, spec in out.items():
        if isinstance(spec, str):
            if spec not in POLICIES and not Path(spec).exists():
                raise ValueError(
                    f"unknown policy {spec!r}: use one of {sorted(POLICIES)} or a model path"
                )
        elif not isinstance(spec, Policy):
            raise ValueError(f"policy {label!r}: expected a name, a path or a Policy, got {spec!r}")
    return out


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------


def default_batch_size(n_episodes: int) -> int:
    """Default chunk size: about 8 chunks, each of 16 to 64 episodes (never above ``n``).

    It depends on the number of episodes only, so that results do not depend on the number
    of workers; 8 chunks per policy keep up to 8 workers busy on long runs.

    Args:
        n_episodes: Episodes per policy.

    Returns:
        Episodes per batched simulator.
    """
    size = min(DEFAULT_BATCH_SIZE, max(MIN_DEFAULT_BATCH_SIZE, math.ceil(n_episodes / 8)))
    return max(1, min(size, n_episodes))


def _chunks(seeds: Sequence[int], size: int) -> list[list[int]]:
    return [list(seeds[i : i + size]) for i in range(0, len(seeds), size)]


def _run_chunk(
    spec: PolicySpec,
    config: EnvConfig,
    seeds: list[int],
    deviation_threshold: float,
    settle_time: float,
    hold_time: float,
    keep: int,
    allow_pickle: bool = False,
) -> tuple[list[dict[str, Any]], list[Episode]]:
    """Play one chunk of seeds with one policy and compute its metrics (pool task).

    Args:
        spec: Policy name or path (a fresh policy is built), or a policy object.
        config: Environment config.
        seeds: The chunk's seeds (one batched simulator).
        deviation_threshold: Off-track threshold (m).
        settle_time: Start of the deviation / fluctuation statistics (s).
        hold_time: Hold time of the conflict timeline (s).
        keep: Number of leading episodes of the chunk to return whole (for plots).
        allow_pickle: Let SB3 model files be unpickled (see :func:`make_policy`).

    Returns:
        Per-episode JSON-able entries, and the first ``keep`` :class:`Episode` objects.
    """
    policy = make_policy(spec, config, allow_pickle) if isinstance(spec, str) else spec
    if isinstance(spec, str) and isinstance(policy, RandomPolicy):
        policy = RandomPolicy(config, seed=seeds[0])  # independent draws per chunk
    episodes = run_episodes(
        policy,
        config,
        seeds,
        batch_size=len(seeds),
        deviation_threshold=deviation_threshold,
        settle_time=settle_time,
    )
    entries = [
        {
            "seed": ep.seed,
            "family": ep.family,
            "steps": ep.steps,
            "terminated": ep.terminated,
            "episode_return": ep.episode_return,
            "metrics": episode_metrics(ep.record, hold_time=hold_time).to_dict(),
        }
        for ep in episodes
    ]
    return entries, episodes[:keep]


def _aggregate_entries(entries: list[dict[str, Any]], confidence: float) -> dict[str, Any]:
    """Aggregate the metrics of a policy's episodes, plus return / steps / termination."""
    extended = [
        {
            "episode": {
                **e["metrics"]["episode"],
                "episode_return": e["episode_return"],
                "steps": e["steps"],
                "terminated": e["terminated"],
            },
            "uavs": e["metrics"]["uavs"],
        }
        for e in entries
    ]
    return aggregate(extended, confidence=confidence)


def evaluate(
    policies: PolicySpec | Sequence[PolicySpec] | Mapping[str, PolicySpec],
    config: EnvConfig | Mapping[str, Any] | None,
    seeds: Iterable[int],
    workers: int = 1,
    batch_size: int | None = None,
    *,
    deviation_threshold: float = DEFAULT_DEVIATION_THRESHOLD_M,
    settle_time: float = DEFAULT_SETTLE_TIME_S,
    hold_time: float = DEFAULT_HOLD_TIME_S,
    confidence: float = 0.95,
    keep_episodes: int = 0,
    progress: Callable[[int], None] | None = None,
    allow_pickle: bool = False,
    ray: str | None = None,
) -> dict[str, Any]:
    """Evaluate policies on the same seeds and aggregate the paper's metrics.

    Args:
        policies: A policy name (``"apf"``, ``"motion-state-apf"``, ``"traditional-apf"``,
            ``"zero"``, ``"random"``) or the path of a saved SB3 model, a sequence of those,
            or a mapping ``label -> name / path / Policy object``. Names are rebuilt fresh for
            every chunk (reproducible for any ``workers``); a policy object is reused as is
            (with ``workers > 1`` it is pickled to the workers).
        config: Environment config (or dict for :func:`make_config`, None for defaults).
        seeds: One seed per episode; every policy plays the same seeds.
        workers: Processes (``1``: in-process; more: a ``spawn`` process pool).
        batch_size: Episodes per batched simulator (a chunk); None:
            :func:`default_batch_size`. Results do not depend on ``workers``; they may depend
            on ``batch_size`` for the ``random`` policy (its draws are shared by a batch).
        deviation_threshold: Off-track threshold of the deviation timeline (m).
        settle_time: Start of the deviation / fluctuation statistics (s).
        hold_time: Hold time of the conflict-resolution timeline (s).
        confidence: Confidence level of the aggregate intervals.
        keep_episodes: Number of leading episodes per policy to keep whole (for plots).
        progress: Called with the number of episodes finished after each chunk.
        allow_pickle: Let stable-baselines3 model files be unpickled (runs code from the
            file; policy checkpoints never need it).
        ray: Run the chunks as Ray tasks instead (``workers`` is then unused): ``"local"``
            starts a local Ray (or uses the one this process already joined), anything else
            is the address of a cluster (``"auto"``, ``"ray://head:10001"``). Every node
            needs this package installed. The results are the same as with ``workers=1``.

    Returns:
        A dict::

            {"version", "config" (EnvConfig.to_dict()), "policies" (labels),
             "policy_specs" (label -> name/path/class), "seeds", "settings" {...},
             "results": {label: {"episodes": [{"seed", "family", "steps", "terminated",
                                               "episode_return", "metrics"}, ...],
                                 "aggregate": {dotted metric: stats}}},
             "elapsed_s",
             "episodes": {label: [Episode, ...]}   # only when keep_episodes > 0}

        Everything except ``"episodes"`` is JSON-serialisable (see :func:`result_to_json`).

    Raises:
        ValueError: For an unknown policy, no seeds, or a non-positive worker / batch count.
    """
    from uasep_env import __version__

    t0 = time.perf_counter()
    specs = _normalise_policies(policies)
    cfg = config if isinstance(config, EnvConfig) else make_config(config)
    seed_list = [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("seeds: need at least one episode")
    if any(s < 0 for s in seed_list):
        raise ValueError(f"seeds: must be >= 0, got {min(seed_list)}")
    if int(workers) < 1:
        raise ValueError(f"workers: must be >= 1, got {workers}")
    if ray is not None and not (isinstance(ray, str) and ray.strip()):
        raise ValueError(f"ray: must be 'local' or a Ray address, got {ray!r}")
    workers = int(workers)
    if batch_size is None:
        batch_size = default_batch_size(len(seed_list))
    if int(batch_size) < 1:
        raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
    chunks = _chunks(seed_list, int(batch_size))
    tasks = [
        (
            label,
            ci,
            (
                spec,
                cfg,
                chunk,
                deviation_threshold,
                settle_time,
                hold_time,
                keep_episodes if ci == 0 else 0,
                allow_pickle,
            ),
        )
        for label, spec in specs.items()
        for ci, chunk in enumerate(chunks)
    ]
    done: dict[tuple[str, int], tuple[list[dict[str, Any]], list[Episode]]] = {}

    if ray is not None:
        for (label, ci), out in _run_on_ray(ray, tasks, progress, [len(c) for c in chunks]):
            done[label, ci] = out
    elif workers == 1 or len(tasks) == 1:
        for label, ci, args in tasks:
            done[label, ci] = _run_chunk(*args)
            if progress is not None:
                progress(len(chunks[ci]))
    else:
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx)
        try:
            futures: dict[Future[Any], tuple[str, int]] = {
                pool.submit(_run_chunk, *args): (label, ci) for label, ci, args in tasks
            }
            for fut in as_completed(futures):
                label, ci = futures[fut]
                done[label, ci] = fut.result()
                if progress is not None:
                    progress(len(chunks[ci]))
        except BaseException:  # a failed chunk or Ctrl-C: do not wait for the rest
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()

    results: dict[str, Any] = {}
    kept: dict[str, list[Episode]] = {}
    for label in specs:
        entries: list[dict[str, Any]] = []
        for ci in range(len(chunks)):
            chunk_entries, chunk_eps = done[label, ci]
            entries.extend(chunk_entries)
            if ci == 0:
                kept[label] = chunk_eps
        results[label] = {
            "episodes": entries,
            "aggregate": _aggregate_entries(entries, confidence),
        }

    out: dict[str, Any] = {
        "version": __version__,
        "config": cfg.to_dict(),
        "policies": list(specs),
        "policy_specs": {
            label: spec if isinstance(spec, str) else type(spec).__name__
            for label, spec in specs.items()
        },
        "seeds": seed_list,
        "settings": {
            "batch_size": int(batch_size),
            "workers": workers,
            "deviation_threshold": float(deviation_threshold),
            "settle_time": float(settle_time),
            "hold_time": float(hold_time),
            "confidence": float(confidence),
            **({"ray": ray} if ray is not None else {}),
        },
        "results": results,
        "elapsed_s": time.perf_counter() - t0,
    }
    if keep_episodes > 0:
        out["episodes"] = kept
    return out


def _run_on_ray(
    address: str,
    tasks: list[tuple[str, int, tuple]],
    progress: Callable[[int], None] | None,
    sizes: list[int],
) -> Iterable[tuple[tuple[str, int], Any]]:
    """Run :func:`_run_chunk` for every task as a Ray task; yield ``((label, chunk), out)``.

    Joins the Ray this process is connected to, or starts one (``"local"``) or connects to
    ``address``, and disconnects at the end if it connected.
    """
    try:
        import ray
    except ImportError as err:
        raise ImportError(
            "ray is not installed; pip install 'uasep-env[clients]' (or 'ray>=2.60')"
        ) from err
    started = not ray.is_initialized()
    if started:
        ray.init(
            address=None if address == "local" else address,
            include_dashboard=False,
            log_to_driver=False,
        )
    refs: dict[Any, tuple[str, int]] = {}
    try:
        remote = ray.remote(_run_chunk)
        refs = {remote.remote(*args): (label, ci) for label, ci, args in tasks}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                label, ci = refs[ref]
                yield (label, ci), ray.get(ref)
                if progress is not None:
                    progress(sizes[ci])
    except BaseException:  # a failed chunk or Ctrl-C: do not wait for the rest
        for ref in refs:
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()


# --------------------------------------------------------------------------------------------
# Output: JSON, CSV
# --------------------------------------------------------------------------------------------


def _json_safe(value: Any) -> Any:
    """Plain-Python, strict-JSON view: NaN / inf -> None, numpy -> Python, tuples -> lists."""
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def result_to_json(result: Mapping[str, Any], **kwargs: Any) -> str:
    """Strict JSON of an :func:`evaluate` result (without the kept ``"episodes"``).

    Args:
        result: The result dict.
        **kwargs: Passed to :func:`json.dumps` (e.g. ``indent``).

    Returns:
        JSON text; non-finite floats are written as ``null``.
    """
    data = {k: v for k, v in result.items() if k != "episodes"}
    return json.dumps(_json_safe(data), allow_nan=False, **kwargs)


def write_json(result: Mapping[str, Any], path: str | Path) -> Path:
    """Write :func:`result_to_json` (indented) to ``path``, creating parent folders.

    A path ending in ``.gz`` is gzip-compressed (with a zero time stamp, so the same result
    gives the same bytes): per-episode results of large banks shrink about tenfold.

    Args:
        result: The result dict.
        path: Output file.

    Returns:
        The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = (result_to_json(result, indent=2) + "\n").encode("utf-8")
    if path.suffix == ".gz":
        with path.open("wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as gz:
            gz.write(data)
    else:
        path.write_bytes(data)
    return path


def _csv_cell(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else ""
    return value


def write_csv(result: Mapping[str, Any], path: str | Path) -> Path:
    """Write one row per (policy, episode) with the flattened scalar metrics.

    Columns: ``policy, seed, family, steps, terminated, episode_return`` and then every key
    of :func:`uasep_env.metrics.flatten_metrics` (e.g. ``episode.min_obstacle_distance``,
    ``uav.uav_2.timeline.t_leave``). Empty cells are NaN / undefined.

    Args:
        result: An :func:`evaluate` result.
        path: Output file.

    Returns:
        The path written.
    """
    rows: list[dict[str, Any]] = []
    keys: dict[str, None] = {}
    for label in result["policies"]:
        for e in result["results"][label]["episodes"]:
            flat = flatten_metrics(e["metrics"])
            keys.update(dict.fromkeys(flat))
            rows.append(
                {
                    "policy": label,
                    "seed": e["seed"],
                    "family": e["family"],
                    "steps": e["steps"],
                    "terminated": e["terminated"],
                    "episode_return": e["episode_return"],
                    **flat,
                }
            )
    header = ["policy", "seed", "family", "steps", "terminated", "episode_return", *keys]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=header, restval="")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    return path


# --------------------------------------------------------------------------------------------
# Summary table
# --------------------------------------------------------------------------------------------

_AXES = ("x", "y", "z")

#: (label, dotted aggregate key, digits) of the episode-level rows of the summary; negative
#: digits mark counts (no decimals for one episode, ``-digits`` decimals for a mean).
_EPISODE_ROWS: tuple[tuple[str, str, int], ...] = (
    ("min UAV-UAV separation (m)", "episode.min_uav_separation", 2),
    ("min UAV-obstacle distance (m)", "episode.min_obstacle_distance", 2),
    ("min distance to reachable region (m)", "episode.min_region_distance", 2),
    ("loss-of-separation events UAV-UAV", "episode.uav_los_events", -2),
    ("loss-of-separation events UAV-obstacle", "episode.obstacle_los_events", -2),
    ("collision events", "episode.collision_events", -2),
    ("max deviation (m)", "episode.max_deviation", 2),
    ("RMS deviation, worst UAV (m)", "episode.max_rms_deviation", 2),
    ("max conflict duration (s)", "episode.max_conflict_duration", 1),
)


def _pm_symbol() -> str:
    enc = getattr(sys.stdout, "encoding", None) or "ascii"
    try:
        "±".encode(enc)
    except (LookupError, UnicodeEncodeError):
        return "+/-"
    return "±"


def _fmt_num(value: Any, digits: int) -> str:
    if value is None:
        return "-"
    v = float(value)
    if not math.isfinite(v):
        return "-"
    return f"{v:.{digits}f}"


def _cell(stats: Mapping[str, Any] | None, digits: int, single: bool, pm: str) -> str:
    """One summary cell: the value (one episode) or mean ± CI half-width / rate."""
    if stats is None:
        return "-"
    if stats.get("kind") == "rate":
        return f"{stats['successes']}/{stats['n_valid']}"
    if digits < 0:
        digits = 0 if single else -digits
    if single or stats.get("n_valid", 0) < 2:
        cell = _fmt_num(stats.get("mean"), digits)
        if not single and stats.get("n_valid", 0) < stats.get("n", 0):
            cell += f" (n={stats['n_valid']})"
        return cell
    mean, low, high = stats.get("mean"), stats.get("ci_low"), stats.get("ci_high")
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return _fmt_num(mean, digits)
    cell = f"{_fmt_num(mean, digits)} {pm} {_fmt_num(0.5 * (high - low), digits)}"
    if stats["n_valid"] < stats["n"]:
        cell += f" (n={stats['n_valid']})"
    return cell


def summary_rows(result: Mapping[str, Any]) -> list[list[str]]:
    """Rows of the side-by-side summary (header first: ``metric``, then one column per policy).

    With one episode the cells are the values; with more, ``mean ± half-width`` of the
    confidence interval of the mean (``n=`` when some episodes had no value, e.g. no UAV
    left its track) and ``k/n`` for rates (episodes with a collision).

    Args:
        result: An :func:`evaluate` result.

    Returns:
        Rows of strings.
    """
    labels = list(result["policies"])
    aggs = {lab: result["results"][lab]["aggregate"] for lab in labels}
    n_eps = len(result["seeds"])
    single = n_eps == 1
    pm = _pm_symbol()
    first = result["results"][labels[0]]["episodes"][0]["metrics"]
    uav_names = [u["name"] for u in first["uavs"]]

    def row(title: str, key: str, digits: int) -> list[str]:
        return [title, *(_cell(aggs[lab].get(key), digits, single, pm) for lab in labels)]

    rows: list[list[str]] = [["metric", *labels]]
    rows.extend(row(t, k, d) for t, k, d in _EPISODE_ROWS)
    if not single:
        rows.append(row("episodes with a collision", "episode.collision", 0))
        rows.append(row("episodes with loss of separation", "episode.loss_of_separation", 0))
    for ax in _AXES:
        rows.append(row(f"acc std {ax}, worst UAV (m/s²)", f"episode.max_acc_std.{ax}", 3))
    rows.append(row("vel std z, worst UAV (m/s)", "episode.max_vel_std.z", 3))
    for name in uav_names:
        pre = f"uav.{name}"
        if single:
            cells = [name + " leave / resolved / back (s)"]
            for lab in labels:
                parts = [
                    _fmt_num(aggs[lab].get(f"{pre}.timeline.{f}", {}).get("mean"), 1)
                    for f in ("t_leave", "t_resolved", "t_back")
                ]
                left = aggs[lab].get(f"{pre}.timeline.left", {}).get("successes", 1)
                cells.append(" / ".join(parts) if left else "never left")
            rows.append(cells)
        rows.append(row(f"{name} conflict duration (s)", f"{pre}.timeline.conflict_duration", 1))
        rows.append(row(f"{name} max deviation (m)", f"{pre}.deviation.max_norm", 2))
        rows.append(row(f"{name} acc std z (m/s²)", f"{pre}.fluctuation.acc_std.z", 3))
    rows.append(row("episode return", "episode.episode_return", 1))
    return rows


def _render_rows(rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(r[j]) for r in rows) for j in range(len(rows[0]))]

    def line(r: Sequence[str]) -> str:
        cells = [r[0].ljust(widths[0])] + [
            c.rjust(w) for c, w in zip(r[1:], widths[1:], strict=True)
        ]
        return "  ".join(cells).rstrip()

    return "\n".join([line(rows[0]), "  ".join("-" * w for w in widths), *map(line, rows[1:])])


def format_summary(result: Mapping[str, Any]) -> str:
    """The readable summary: a heading and the policies side by side.

    Args:
        result: An :func:`evaluate` result.

    Returns:
        Multi-line text.
    """
    seeds = result["seeds"]
    n = len(seeds)
    cfg = result["config"]
    what = (
        f"{n} episode (seed {seeds[0]})"
        if n == 1
        else f"{n} episodes (seeds {seeds[0]}..{seeds[-1]}), mean "
        f"{_pm_symbol()} {100 * result['settings']['confidence']:.0f}% CI half-width"
    )
    head = (
        f"uasep-eval {result['version']}: scenario {cfg['scenario']}, {what}; "
        f"{cfg['n_uavs']} UAVs, {cfg['n_obstacles']} obstacle slot(s), "
        f"{cfg['episode_duration']:g} s episodes"
    )
    uav = cfg["uav"]
    foot = (
        f"collision distance {uav['collision_distance']:g} m, separation UAV-UAV "
        f"{uav['separation_distance']:g} m / UAV-obstacle {uav['obstacle_separation']:g} m; "
        f"deviation and fluctuation after t = {result['settings']['settle_time']:g} s, "
        f"off-track beyond {result['settings']['deviation_threshold']:g} m; "
        f"'-' = undefined (e.g. never left the track)"
        + ("; (n=k): only k episodes had a value." if n > 1 else ".")
    )
    return "\n".join([head, "", _render_rows(summary_rows(result)), "", foot])


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


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


def _output_problem(path: Path, directory: bool) -> str | None:
    """Why ``path`` cannot be written (a file, or a folder when ``directory``), or None.

    Checked before the evaluation runs, so that a bad path fails at once: the path must
    not be a folder (a file for ``directory``), its nearest existing parent must be a
    writable folder, and an existing target must be writable.
    """
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
            f"policies: {', '.join(POLICIES)} or the path of a policy checkpoint (.zip)"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--policy",
        action="append",
        metavar="NAME",
        help="policy to evaluate; repeatable or comma-separated, all on the same seeds "
        "(default: apf)",
    )
    p.add_argument(
        "--scenario",
        default="paper",
        choices=SCENARIOS,
        metavar="NAME",
        help=f"scenario family: {', '.join(SCENARIOS)} (default: paper)",
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
        "--allow-pickle",
        action="store_true",
        help="let a stable-baselines3 model file be unpickled, which runs code from it; "
        "only for files you trust (policy checkpoints never need it)",
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


def _progress_bar(total: int, quiet: bool) -> Any:
    """A tqdm bar on stderr, or None when quiet, not a terminal, or tqdm is missing."""
    if quiet or not sys.stderr.isatty():
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is optional
        return None
    return tqdm(total=total, unit="ep", desc="uasep-eval", file=sys.stderr, leave=False)


def _run(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)

    names = _split_policy_args(args.policy or ["apf"])
    if not names:
        parser.error("argument --policy: no policy given")
    for name in names:
        if name not in POLICIES and not Path(name).exists():
            parser.error(
                f"argument --policy: unknown policy {name!r} (use one of "
                f"{', '.join(POLICIES)} or the path of a policy checkpoint)"
            )
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
    try:
        cfg = build_config(args.scenario, args.config)
    except (TypeError, ValueError) as err:
        parser.error(f"argument --config: {err}")
    for name in names:  # fail early on models that do not load
        try:
            make_policy(name, cfg, args.allow_pickle)
        except Exception as err:
            parser.error(f"argument --policy: cannot load {name!r}: {err}")

    seeds = list(range(args.seed, args.seed + args.episodes))
    bar = _progress_bar(len(names) * len(seeds), args.quiet)
    try:
        result = evaluate(
            names,
            cfg,
            seeds,
            workers=args.workers,
            batch_size=args.batch_size,
            deviation_threshold=args.deviation_threshold,
            settle_time=args.settle_time,
            hold_time=args.hold_time,
            keep_episodes=1 if args.plot is not None else 0,
            progress=bar.update if bar is not None else None,
            allow_pickle=args.allow_pickle,
            ray=args.ray,
        )
    finally:
        if bar is not None:
            bar.close()
    result["command"] = ["uasep-eval", *(sys.argv[1:] if argv is None else argv)]

    if not args.quiet:
        print(format_summary(result))
    written: list[Path] = []
    if args.json is not None:
        written.append(write_json(result, args.json))
    if args.csv is not None:
        written.append(write_csv(result, args.csv))
    if args.plot is not None:
        from uasep_env.plotting import plot_paper_figures

        first = {label: eps[0] for label, eps in result["episodes"].items()}
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
        print(f"({result['elapsed_s']:.1f} s)")
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
    try:
        return _run(argv)
    except SystemExit as exc:  # argparse: --help / --version (0) and usage errors (2)
        code = exc.code
        if code is None:
            return 0
        if isinstance(code, int):
            return code
        print(code, file=sys.stderr)
        return 1
    except OSError as err:
        print(f"uasep-eval: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    # Run through the package module so that pool workers unpickle the same functions.
    from uasep_env import evaluation as _evaluation

    sys.exit(_evaluation.main())
