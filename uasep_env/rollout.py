"""Batched, headless rollouts of any policy, recorded for the metrics.

:func:`run_episodes` plays one episode per seed, many at once in one batched
:class:`~uasep_env.envs.core.EnvCore` (no Python loop over environments inside a step),
and returns an :class:`~uasep_env.metrics.EpisodeRecord` of true states per episode, with
each UAV's per-step cost as the core computed it (``EpisodeRecord.step_cost``). The
same seeds give the same scenarios (obstacles, noise) for every policy, so policies are
compared on identical encounters.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from uasep_env.config import EnvConfig, make_config
from uasep_env.envs.core import EnvCore
from uasep_env.metrics import EpisodeRecord
from uasep_env.policies.base import Policy
from uasep_env.runtime.capacity import check_count, record_bytes

__all__ = ["DEFAULT_DEVIATION_THRESHOLD_M", "DEFAULT_SETTLE_TIME_S", "Episode", "run_episodes"]

#: A UAV is "off its planned trajectory" beyond this deviation (m).
DEFAULT_DEVIATION_THRESHOLD_M = 2.0
#: Metrics of deviation and fluctuation start once the formation has formed up (s).
DEFAULT_SETTLE_TIME_S = 40.0


@dataclass
class Episode:
    """One played episode.

    Attributes:
        seed: Its seed.
        family: Scenario family that generated it.
        record: True-state record for :func:`uasep_env.metrics.episode_metrics`.
        episode_return: Sum of the mean-over-agents reward.
        steps: Environment steps played.
        terminated: Ended by a collision.
        obstacle_axes: ``(M, 3)`` semi-axes of the predicted reachable ellipsoids (m).
        pred_center: ``(T, M, 3)`` centres of the predicted ellipsoids (m).
        pred_heading: ``(T, M)`` their headings (rad).
        waypoints: ``(W, 3)`` planned trajectory of the formation centre (m).
    """

    seed: int
    family: str
    record: EpisodeRecord
    episode_return: float
    steps: int
    terminated: bool
    obstacle_axes: np.ndarray
    pred_center: np.ndarray
    pred_heading: np.ndarray
    waypoints: np.ndarray


def run_episodes(
    policy: Policy,
    config: EnvConfig | dict | None,
    seeds: Sequence[int],
    batch_size: int = 256,
    deviation_threshold: float = DEFAULT_DEVIATION_THRESHOLD_M,
    settle_time: float = DEFAULT_SETTLE_TIME_S,
    on_batch: Callable[[int], None] | None = None,
) -> list[Episode]:
    """Play one episode per seed with ``policy``, batched.

    Args:
        policy: Maps observations ``(E, N, D)`` to actions ``(E, N, 3)``.
        config: Environment config.
        seeds: One seed per episode.
        batch_size: Episodes simulated together.
        deviation_threshold: Off-track threshold for the timeline (m).
        settle_time: Start of the deviation/fluctuation statistics (s); clipped to the
            episode.
        on_batch: Called with the number of episodes finished after each batch.

    Returns:
        The episodes, in the order of ``seeds``.
    """
    cfg = config if isinstance(config, EnvConfig) else make_config(config)
    seeds = [int(s) for s in seeds]
    out: list[Episode] = []
    for start in range(0, len(seeds), batch_size):
        chunk = seeds[start : start + batch_size]
        out.extend(_run_batch(policy, cfg, chunk, deviation_threshold, settle_time))
        if on_batch is not None:
            on_batch(len(chunk))
    return out


def _run_batch(
    policy: Policy,
    cfg: EnvConfig,
    seeds: list[int],
    deviation_threshold: float,
    settle_time: float,
) -> list[Episode]:
    e = len(seeds)
    check_count("batch_size", e, cfg, extra_bytes=record_bytes(cfg))  # with the records
    core = EnvCore(cfg, n_envs=e)
    w = core.world
    obs = core.reset(seed=list(seeds))
    policy.reset()
    t_max = cfg.max_steps + 1
    n, m = cfg.n_uavs, cfg.n_obstacles
    rec = {
        "time": np.zeros((t_max, e)),
        "uav_pos": np.zeros((t_max, e, n, 3)),
        "uav_vel": np.zeros((t_max, e, n, 3)),
        "uav_acc": np.zeros((t_max, e, n, 3)),
        "planned_pos": np.zeros((t_max, e, n, 3)),
        "obstacle_pos": np.zeros((t_max, e, m, 3)),
        "obstacle_active": np.zeros((t_max, e, m), dtype=bool),
        "region_distance": np.zeros((t_max, e, n, m)),
        "pred_center": np.zeros((t_max, e, m, 3)),
        "pred_heading": np.zeros((t_max, e, m)),
        "cost": np.zeros((t_max, e, n)),  # row k: the step ending at sample k (row 0 unused)
    }

    def record(k: int) -> None:
        rec["time"][k] = w.time
        rec["uav_pos"][k] = w.uav_pos
        rec["uav_vel"][k] = w.uav_vel
        rec["uav_acc"][k] = w.uav_acc
        rec["planned_pos"][k] = w.planned()[0]
        rec["obstacle_pos"][k] = w.obstacles.pos
        rec["obstacle_active"][k] = w.obstacles.active
        rec["region_distance"][k] = np.where(np.isfinite(reg := w.region_distances()), reg, 1e9)
        rec["pred_center"][k] = w.pred_center
        rec["pred_heading"][k] = w.pred_heading

    record(0)
    length = np.ones(e, dtype=np.int64)  # samples recorded per env
    done = np.zeros(e, dtype=bool)
    terminated = np.zeros(e, dtype=bool)
    returns = np.zeros(e)
    k = 0
    while not done.all():
        k += 1
        actions = policy(obs)
        res = core.step(actions, active=~done)
        obs = res.obs
        live = ~done
        returns[live] += res.rewards[live].mean(axis=1)
        record(k)
        rec["cost"][k] = res.cost
        length[live] = k + 1
        terminated |= live & res.terminated
        done |= res.terminated | res.truncated

    episodes = []
    for i, seed in enumerate(seeds):
        t = length[i]
        time = rec["time"][:t, i]
        settle = min(settle_time, float(time[-1]))
        record_i = EpisodeRecord(
            time=time,
            dt=cfg.step_duration,
            uav_pos=rec["uav_pos"][:t, i],
            uav_vel=rec["uav_vel"][:t, i],
            uav_acc=rec["uav_acc"][:t, i],
            planned_pos=rec["planned_pos"][:t, i],
            obstacle_pos=rec["obstacle_pos"][:t, i],
            obstacle_active=rec["obstacle_active"][:t, i],
            region_distance=rec["region_distance"][:t, i],
            collision_distance=cfg.uav.collision_distance,
            uav_separation=cfg.uav.separation_distance,
            obstacle_separation=cfg.uav.obstacle_separation,
            deviation_threshold=deviation_threshold,
            settle_time=settle,
            step_cost=rec["cost"][1:t, i],
        )
        episodes.append(
            Episode(
                seed=seed,
                family=w.families[i],
                record=record_i,
                episode_return=float(returns[i]),
                steps=int(t - 1),
                terminated=bool(terminated[i]),
                obstacle_axes=w.pred_axes[i].copy(),
                pred_center=rec["pred_center"][:t, i],
                pred_heading=rec["pred_heading"][:t, i],
                waypoints=w.plan.waypoints[i].copy(),
            )
        )
    return episodes
