"""Running the evaluation: every policy on the same seeds, in chunks, here, in a pool or on Ray.

Reproducibility: the seeds are split into chunks (one batched simulator each) whose size
depends only on the number of episodes and ``batch_size`` (:func:`default_batch_size`), never
on ``workers``. Each chunk is played by a fresh policy built from its name (the ``random``
policy's generator is seeded with the chunk's first seed), in-process (``workers=1``) or in a
``spawn`` process pool, or as Ray tasks on a local Ray or a cluster (``ray=``), and the chunks
are reassembled in seed order. The results are therefore identical for any worker count and
on Ray, for stochastic policies too.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from uasep_env.config import EnvConfig, make_config
from uasep_env.evaluation.results import (
    EpisodeResult,
    EvaluationResult,
    EvaluationSettings,
    PolicyResult,
)
from uasep_env.metrics import aggregate, episode_metrics
from uasep_env.policies import (
    POLICIES,
    CheckpointError,
    Policy,
    RandomPolicy,
    check_policy_name,
    checkpoint_path,
    load_policy,
    make_policy,
    observed_config,
    split_shield,
)
from uasep_env.policies.env_version import EnvVersionWarning, policy_env_version
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
    "PolicySpec",
    "default_batch_size",
    "evaluate",
    "policy_config",
]

#: Largest number of episodes simulated together in one batched simulator (by default).
DEFAULT_BATCH_SIZE = 64
#: Smallest default chunk: batching many episodes is much cheaper per episode.
MIN_DEFAULT_BATCH_SIZE = 16
#: Hold time of the conflict-resolution timeline (s), see :func:`metrics.conflict_timelines`.
DEFAULT_HOLD_TIME_S = 2.0

PolicySpec = str | Policy


def _policy_label(spec: str, taken: Iterable[str]) -> str:
    """A short, unique display label: the name, or a model file's stem."""
    base, shield = split_shield(spec)
    label = base if base in POLICIES else Path(base).stem or base
    label += f"+{shield}" if shield is not None else ""
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
            check_policy_name(spec)
        elif not isinstance(spec, Policy):
            raise ValueError(f"policy {label!r}: expected a name, a path or a Policy, got {spec!r}")
    return out


def policy_config(spec: PolicySpec, config: EnvConfig) -> EnvConfig:
    """The config a policy observes the comparison's episodes with.

    ``config`` itself, except for a policy checkpoint (a file or a shipped name, shielded or
    not) that does not fit it as given (another formation size, obstacle count or K
    nearest): it observes with its training observation
    (:func:`~uasep_env.policies.observed_config`), as the scaling report does. The
    observation does not move the world, so the episodes are the ones every other policy
    plays.

    Args:
        spec: A policy name, path or object.
        config: The comparison's environment.

    Returns:
        The config to build and run the policy with.
    """
    base = split_shield(spec)[0] if isinstance(spec, str) else spec  # a shield reads as it
    path = checkpoint_path(base) if isinstance(base, str) and base not in POLICIES else None
    if path is None:
        return config
    try:
        load_policy(path, config)
    except CheckpointError:
        return observed_config(path, config)
    return config


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
    algorithm: str | None = None,
) -> tuple[list[EpisodeResult], list[Episode]]:
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
        algorithm: The SB3 algorithm of such files (default PPO).

    Returns:
        Per-episode results, and the first ``keep`` :class:`Episode` objects.
    """
    policy = spec
    if isinstance(spec, str):
        with warnings.catch_warnings():  # said once, by evaluate's policy_config
            warnings.simplefilter("ignore", EnvVersionWarning)
            policy = make_policy(spec, config, allow_pickle, algorithm)
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
        EpisodeResult(
            seed=ep.seed,
            family=ep.family,
            steps=ep.steps,
            terminated=ep.terminated,
            episode_return=ep.episode_return,
            metrics=episode_metrics(ep.record, hold_time=hold_time),
        )
        for ep in episodes
    ]
    return entries, episodes[:keep]


def _aggregate_entries(entries: list[EpisodeResult], confidence: float) -> dict[str, Any]:
    """Aggregate the metrics of a policy's episodes, plus return / steps / termination."""
    extended = [
        {
            "episode": {
                **e.metrics.episode.to_dict(),
                "episode_return": e.episode_return,
                "steps": e.steps,
                "terminated": e.terminated,
            },
            "uavs": [u.to_dict() for u in e.metrics.uavs],
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
    algorithm: str | None = None,
) -> EvaluationResult:
    """Evaluate policies on the same seeds and aggregate the paper's metrics.

    Args:
        policies: A policy name (``"apf"``, ``"motion-state-apf"``, ``"traditional-apf"``,
            ``"zero"``, ``"random"``, or a shipped policy such as ``"ppo_shared"``) or the
            path of a checkpoint or saved SB3 model, a sequence of those,
            or a mapping ``label -> name / path / Policy object``. Names are rebuilt fresh for
            every chunk (reproducible for any ``workers``); a policy object is reused as is
            (with ``workers > 1`` it is pickled to the workers).
        config: Environment config (or dict for :func:`make_config`, None for defaults). A
            policy checkpoint that does not fit it (another size or K nearest) observes it
            with its training observation (:func:`policy_config`; the same episodes).
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
        algorithm: The stable-baselines3 algorithm of model files (``"SAC"``, ...;
            default PPO).

    Returns:
        The typed result (:class:`EvaluationResult`: per policy the episodes and their
        aggregate); its ``to_json()`` / :func:`uasep_env.runtime.jsonio.write_json` give the JSON
        layout, without the episodes kept whole for plots.

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
    observed = {label: policy_config(spec, cfg) for label, spec in specs.items()}
    trained = {label: v for label, s in specs.items() if (v := policy_env_version(s)) is not None}
    tasks = [
        (
            label,
            ci,
            (
                spec,
                observed[label],
                chunk,
                deviation_threshold,
                settle_time,
                hold_time,
                keep_episodes if ci == 0 else 0,
                allow_pickle,
                algorithm,
            ),
        )
        for label, spec in specs.items()
        for ci, chunk in enumerate(chunks)
    ]
    done = _run_tasks(tasks, [len(c) for c in chunks], workers, ray, progress)

    results: dict[str, PolicyResult] = {}
    kept: dict[str, list[Episode]] = {}
    for label in specs:
        entries: list[EpisodeResult] = []
        for ci in range(len(chunks)):
            chunk_entries, chunk_eps = done[label, ci]
            entries.extend(chunk_entries)
            if ci == 0:
                kept[label] = chunk_eps
        results[label] = PolicyResult(
            episodes=entries, aggregate=_aggregate_entries(entries, confidence)
        )

    return EvaluationResult(
        version=__version__,
        config=cfg,
        policies=list(specs),
        policy_specs={
            label: spec if isinstance(spec, str) else type(spec).__name__
            for label, spec in specs.items()
        },
        seeds=seed_list,
        settings=EvaluationSettings(
            batch_size=int(batch_size),
            workers=workers,
            deviation_threshold=float(deviation_threshold),
            settle_time=float(settle_time),
            hold_time=float(hold_time),
            confidence=float(confidence),
            ray=ray,
        ),
        results=results,
        elapsed_s=time.perf_counter() - t0,
        trained_env_versions=trained or None,
        observations={
            label: c.to_dict()["observation"] for label, c in observed.items() if c != cfg
        }
        or None,
        episodes=kept if keep_episodes > 0 else {},
    )


_ChunkOutput = tuple[list[EpisodeResult], list[Episode]]


def _run_tasks(
    tasks: list[tuple[str, int, tuple]],
    sizes: list[int],
    workers: int,
    ray: str | None,
    progress: Callable[[int], None] | None,
) -> dict[tuple[str, int], _ChunkOutput]:
    """Run :func:`_run_chunk` for every task: here, in a ``spawn`` pool, or on Ray.

    Returns:
        ``(label, chunk index) -> (episode results, kept episodes)``.
    """
    if ray is not None:
        return dict(_run_on_ray(ray, tasks, progress, sizes))
    done: dict[tuple[str, int], _ChunkOutput] = {}
    if workers == 1 or len(tasks) == 1:
        for label, ci, args in tasks:
            done[label, ci] = _run_chunk(*args)
            if progress is not None:
                progress(sizes[ci])
        return done
    ctx = multiprocessing.get_context("spawn")
    n = min(workers, len(tasks))
    pool = ProcessPoolExecutor(
        max_workers=n, mp_context=ctx, initializer=_share_cores, initargs=(n,)
    )
    try:
        futures: dict[Future[Any], tuple[str, int]] = {
            pool.submit(_run_chunk, *args): (label, ci) for label, ci, args in tasks
        }
        for fut in as_completed(futures):
            label, ci = futures[fut]
            done[label, ci] = fut.result()
            if progress is not None:
                progress(sizes[ci])
    except BaseException:  # a failed chunk or Ctrl-C: do not wait for the rest
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return done


def _share_cores(workers: int) -> None:
    """In a worker: its compiled kernels take its share of the cores (``UASEP_WORKERS``)."""
    os.environ.setdefault("UASEP_WORKERS", str(workers))


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
