"""What :func:`~uasep_env.evaluation.evaluate` returns: typed results, and their JSON layout.

The JSON files (``uasep-eval --json``, ``baselines/results/*.json[.gz]``) are these dataclasses
through :func:`uasep_env.runtime.jsonio.to_plain`, field by field, in declaration order::

    {"version", "config" (EnvConfig.to_dict()), "policies" (labels),
     "policy_specs" (label -> name/path/class), "seeds", "settings" {...},
     "results": {label: {"episodes": [{"seed", "family", "steps", "terminated",
                                       "episode_return", "metrics"}, ...],
                         "aggregate": {dotted metric: stats}}},
     "elapsed_s", "env_version" (only when set), "trained_env_versions" (only when some
     policy is a checkpoint), "command" (only when set)}

The episodes kept whole for plots (:attr:`EvaluationResult.episodes`) are not written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from uasep_env.config import EnvConfig
from uasep_env.metrics import EpisodeMetrics
from uasep_env.runtime.jsonio import OMIT, PLAIN, dumps, to_plain

if TYPE_CHECKING:
    from uasep_env.rollout import Episode

__all__ = ["EpisodeResult", "EvaluationResult", "EvaluationSettings", "PolicyResult"]


@dataclass(frozen=True, kw_only=True)
class EpisodeResult:
    """One episode of one policy.

    Attributes:
        seed: The episode's seed.
        family: Scenario family that generated it.
        steps: Environment steps played.
        terminated: Ended by a collision (or a lost UAV).
        episode_return: Sum of the mean-over-agents reward.
        metrics: Every metric of the episode.
    """

    seed: int
    family: str
    steps: int
    terminated: bool
    episode_return: float
    metrics: EpisodeMetrics


@dataclass(frozen=True, kw_only=True)
class PolicyResult:
    """The episodes of one policy and their aggregate.

    Attributes:
        episodes: Per-episode results, in seed order.
        aggregate: :func:`uasep_env.metrics.aggregate` of the episodes' metrics, with
            ``episode.episode_return``, ``episode.steps`` and ``episode.terminated`` added;
            keyed by dotted metric name.
    """

    episodes: list[EpisodeResult]
    aggregate: dict[str, dict[str, Any]]


@dataclass(frozen=True, kw_only=True)
class EvaluationSettings:
    """How the evaluation ran and measured (thresholds in m, times in s).

    Attributes:
        batch_size: Episodes per batched simulator.
        workers: Worker processes.
        deviation_threshold: Off-track threshold of the deviation timeline (m).
        settle_time: Start of the deviation / fluctuation statistics (s).
        hold_time: Hold time of the conflict-resolution timeline (s).
        confidence: Confidence level of the aggregate intervals.
        ray: The Ray address the chunks ran on, or None (not written then).
    """

    batch_size: int
    workers: int
    deviation_threshold: float
    settle_time: float
    hold_time: float
    confidence: float
    ray: str | None = field(default=None, metadata={OMIT: None})


@dataclass
class EvaluationResult:
    """Policies evaluated on the same seeds.

    Attributes:
        version: Package version.
        config: The environment config (written as :meth:`EnvConfig.to_dict`).
        policies: Policy labels, in order.
        policy_specs: Label -> policy name, model path, or class name of a policy object.
        seeds: One seed per episode, shared by every policy.
        settings: How it ran.
        results: Label -> the policy's episodes and aggregate.
        elapsed_s: Wall time of the evaluation (s).
        env_version: The env version whose episodes were played (set by ``uasep-eval``,
            which plays the checkpoints' own; not written when None).
        trained_env_versions: Label -> the env version a checkpoint was trained in, for
            the policies that are checkpoints (not written when None).
        command: The command line (set by ``uasep-eval``; not written when None).
        observations: Label -> the observation group a policy observed when it is not
            ``config``'s: a checkpoint that does not fit ``config`` as given observes with
            its training observation (same episodes; not written when None).
        episodes: Label -> the leading episodes kept whole (``keep_episodes``); not written.
    """

    version: str
    config: EnvConfig = field(metadata={PLAIN: EnvConfig.to_dict})
    policies: list[str]
    policy_specs: dict[str, str]
    seeds: list[int]
    settings: EvaluationSettings
    results: dict[str, PolicyResult]
    elapsed_s: float
    env_version: int | None = field(default=None, metadata={OMIT: None})
    trained_env_versions: dict[str, int] | None = field(default=None, metadata={OMIT: None})
    command: list[str] | None = field(default=None, metadata={OMIT: None})
    observations: dict[str, dict[str, Any]] | None = field(default=None, metadata={OMIT: None})
    episodes: dict[str, list[Episode]] = field(default_factory=dict, metadata={OMIT: True})

    def to_dict(self) -> dict[str, Any]:
        """The JSON layout as plain Python (NaN / inf kept as floats; see the module docstring).

        Returns:
            Nested dict.
        """
        return to_plain(self)

    def to_json(self, **kwargs: Any) -> str:
        """Strict JSON of the result (non-finite floats as ``null``, kept episodes left out).

        Args:
            **kwargs: Passed on to :func:`json.dumps` (e.g. ``indent``).

        Returns:
            JSON text.
        """
        return dumps(self, **kwargs)
