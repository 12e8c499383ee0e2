"""The Lagrange multiplier of constrained training, and the cost budget it enforces.

Constrained RL maximises the return ``J_r`` subject to ``J_c <= d``, with ``J_c`` the
expected episode cost (:mod:`uasep_env.interface.costs`, per agent) and ``d`` the cost limit. The
Lagrangian relaxation ``max_pi min_{lambda >= 0} J_r - lambda (J_c - d)`` trains the policy
on ``r - lambda c`` and moves ``lambda`` up while the measured episode cost is above ``d``
and down (to 0 at least) while it is below.

:class:`PIDLagrangian` is the multiplier update of Stooke, Achiam and Abbeel (2020),
"Responsive Safety in Reinforcement Learning by PID Lagrangian Methods" (ICML), Algorithm 2:
after each batch of episodes with mean cost ``J``,

* ``delta = J - d``; ``I <- max(0, I + K_I delta)`` (the integral, kept in units of the
  multiplier, as OmniSafe's ``PIDLagrangian`` does: ``K_I`` may then change without a jump);
* ``P = EMA_p(delta)``; ``D = max(0, EMA_d(J) - EMA_d(J)`` ``delay`` updates earlier``)``
  (the derivative only ever raises the multiplier: it reacts to a cost that is rising);
* ``lambda = min(lambda_max, max(0, K_P P + I + K_D D))``.

With ``K_P = K_D = 0`` it is the plain projected gradient ascent of the Lagrangian
(``lambda <- max(0, lambda + K_I (J - d))``, ``K_I`` the multiplier's learning rate), the
update of OmniSafe's and SafePO's PPO-Lag up to their use of Adam on ``lambda``.

:func:`apf_cost_budget` measures the limit ``d`` from the reference APF on validation
encounters with the project's evaluation code (:func:`uasep_env.evaluation.evaluate`).
The SB3 side (the callback that applies the multiplier to PPO's rollouts) is
:mod:`uasep_env.training.sb3_lagrangian`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from uasep_env.config.checks import check, check_finite, check_int_in, check_positive

__all__ = ["CostBudget", "PIDLagrangian", "apf_cost_budget", "check_cost_limit"]

#: Largest cost limit and gain accepted (an episode has at most 10^6 steps).
_MAX = 1.0e9


def check_cost_limit(value: Any, name: str = "cost_limit") -> float:
    """``value`` as a cost limit: a finite number >= 0.

    Raises:
        ValueError: Naming ``name`` and the value (a negative or non-finite limit).
    """
    check_positive(name, value, allow_zero=True, hi=_MAX)
    return float(value)


class PIDLagrangian:
    """A PID-controlled Lagrange multiplier (Stooke et al. 2020; see the module docstring).

    Args:
        cost_limit: ``d``, the episode cost the constraint allows (>= 0).
        kp: ``K_P``, the proportional gain (>= 0; 0: no proportional term).
        ki: ``K_I``, the integral gain (>= 0): the learning rate of plain gradient ascent.
        kd: ``K_D``, the derivative gain (>= 0).
        ema_p: Smoothing of the proportional term, in ``[0, 1)`` (0: the latest ``delta``).
        ema_d: Smoothing of the cost the derivative reads, in ``[0, 1)``.
        delay: The derivative compares the smoothed cost with its value ``delay`` updates
            earlier (>= 1).
        init: The multiplier before any update (>= 0; the integral starts there).
        max_multiplier: Upper bound of the multiplier (> 0; ``inf``: none).

    Raises:
        ValueError: A bad value, named (``cost_limit=-1.0: must be >= 0``).

    Examples:
        >>> pid = PIDLagrangian(cost_limit=1.0, ki=0.5)
        >>> pid.update(3.0), pid.update(3.0), pid.update(0.0)
        (1.0, 2.0, 1.5)
    """

    def __init__(
        self,
        cost_limit: float,
        *,
        kp: float = 0.0,
        ki: float = 0.01,
        kd: float = 0.0,
        ema_p: float = 0.0,
        ema_d: float = 0.0,
        delay: int = 1,
        init: float = 0.0,
        max_multiplier: float = math.inf,
    ) -> None:
        self.cost_limit = check_cost_limit(cost_limit)
        for name, value in (("kp", kp), ("ki", ki), ("kd", kd), ("init", init)):
            check_positive(name, value, allow_zero=True, hi=_MAX)
        for name, value in (("ema_p", ema_p), ("ema_d", ema_d)):
            check_finite(name, value)
            check(0.0 <= value < 1.0, name, value, "must be in [0, 1)")
        check_int_in("delay", delay, 1, 10_000)
        check(
            isinstance(max_multiplier, (int, float)) and max_multiplier > 0,
            "max_multiplier",
            max_multiplier,
            "must be > 0 (inf: no bound)",
        )
        self.kp, self.ki, self.kd = float(kp), float(ki), float(kd)
        self.ema_p, self.ema_d = float(ema_p), float(ema_d)
        self.delay, self.max_multiplier = int(delay), float(max_multiplier)
        self.integral = min(float(init), self.max_multiplier)
        self.multiplier = self.integral
        self._delta_p = 0.0
        self._cost_d = 0.0
        self._costs_d: deque[float] = deque([0.0], maxlen=self.delay)
        self.updates = 0

    def update(self, episode_cost: float) -> float:
        """Move the multiplier with one measurement of the mean episode cost.

        Args:
            episode_cost: ``J``, the mean cost of the episodes since the last update (>= 0).

        Returns:
            The new multiplier.

        Raises:
            ValueError: A negative or non-finite cost, named.
        """
        check_positive("episode_cost", episode_cost, allow_zero=True, hi=_MAX)
        cost = float(episode_cost)
        delta = cost - self.cost_limit
        self.integral = min(self.max_multiplier, max(0.0, self.integral + self.ki * delta))
        self._delta_p = self.ema_p * self._delta_p + (1.0 - self.ema_p) * delta
        self._cost_d = self.ema_d * self._cost_d + (1.0 - self.ema_d) * cost
        d_term = max(0.0, self._cost_d - self._costs_d[0]) if self.updates else 0.0
        self._costs_d.append(self._cost_d)
        out = self.kp * self._delta_p + self.integral + self.kd * d_term
        self.multiplier = min(self.max_multiplier, max(0.0, out))
        self.updates += 1
        return self.multiplier

    def penalise(self, rewards: Any, costs: Any) -> Any:
        """The rewards PPO learns from: ``(r - lambda c) / (1 + lambda)``, in ``rewards``' dtype.

        ``rewards`` itself (the same array) while the multiplier is 0. The one formula of the
        SB3 callback and the lean loop's :class:`~uasep_env.training.constraint.LeanCost`.
        """
        lam = self.multiplier
        if not lam:
            return rewards
        return ((rewards - lam * costs) / (1.0 + lam)).astype(rewards.dtype)

    def state_dict(self) -> dict[str, Any]:
        """The controller's state (JSON-friendly), for checkpoints."""
        return {
            "integral": self.integral,
            "multiplier": self.multiplier,
            "delta_p": self._delta_p,
            "cost_d": self._cost_d,
            "costs_d": list(self._costs_d),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (the gains and the limit are the constructor's).

        A state from a file is checked first: the multiplier and the integral in
        ``[0, max_multiplier]``, the smoothed terms finite (costs >= 0), ``updates`` a
        count.

        Raises:
            ValueError: A value out of range, named (``multiplier=nan: must be ...``).
            KeyError: A missing field.
        """
        bound = self.max_multiplier
        for name in ("integral", "multiplier"):
            value = state[name]
            check_finite(name, value)
            check(0.0 <= value <= bound, name, value, f"must be in [0, {bound:g}]")
        check_finite("delta_p", state["delta_p"])
        check_positive("cost_d", state["cost_d"], allow_zero=True, hi=_MAX)
        costs_d = state["costs_d"]
        check(isinstance(costs_d, list) and 0 < len(costs_d) <= self.delay, "costs_d",
              costs_d, f"must be a list of 1 to {self.delay} costs")  # fmt: skip
        for c in costs_d:
            check_positive("costs_d[]", c, allow_zero=True, hi=_MAX)
        check_int_in("updates", state["updates"], 0, 2**62)
        self.integral = float(state["integral"])
        self.multiplier = float(state["multiplier"])
        self._delta_p = float(state["delta_p"])
        self._cost_d = float(state["cost_d"])
        self._costs_d = deque((float(c) for c in costs_d), maxlen=self.delay)
        self.updates = int(state["updates"])


@dataclass(frozen=True, kw_only=True)
class CostBudget:
    """The APF's safety on validation encounters, as cost limits (:func:`apf_cost_budget`).

    Attributes:
        episodes: Encounters played.
        n_uavs: UAVs per encounter.
        loss_rate: ``r``, the fraction of encounters with a loss of separation (any UAV,
            ``episode.loss_of_separation`` of the metrics).
        mean_cost: The APF's mean episode cost per agent: steps in loss of separation per
            UAV and episode (the metrics' ``uav_los_time + obstacle_los_time`` over the step
            duration, each weighted as the cost is).
        cost_of_a_loss: Mean episode cost per agent over the encounters with a loss
            (``mean_cost = loss_rate * cost_of_a_loss``).
    """

    episodes: int
    n_uavs: int
    loss_rate: float
    mean_cost: float
    cost_of_a_loss: float

    @property
    def parity_limit(self) -> float:
        """``d = mean_cost``: as many steps in loss of separation as the APF, on average."""
        return self.mean_cost

    @property
    def rate_limit(self) -> float:
        """``d = loss_rate / n_uavs``: meeting it bounds the loss rate by the APF's.

        An encounter with a loss costs at least 1 to at least one of its ``N`` agents, so
        ``P(loss) <= N E[mean agent cost]``: a policy whose mean agent cost is at most
        ``r / N`` loses separation in at most a fraction ``r`` of the encounters (Markov's
        inequality; a sufficient condition, much stricter than the APF's own
        ``mean_cost``).
        """
        return self.loss_rate / self.n_uavs


def apf_cost_budget(config: Any, seeds: Iterable[int], workers: int = 1) -> CostBudget:
    """The APF's loss-of-separation rate and mean episode cost on ``seeds`` (validation).

    Plays the paper's APF with :func:`uasep_env.evaluation.evaluate` and reads the metrics
    (:mod:`uasep_env.metrics`), which use the cost's thresholds.

    Args:
        config: The environment config (its ``cost`` weights are applied; the ``region``
            weight must be 0: the metrics do not time region intrusions).
        seeds: The encounters (:data:`uasep_env.scenarios.VALIDATION_SEEDS`, not the held-out
            bank).
        workers: Evaluation processes.

    Raises:
        ValueError: A ``cost.region`` weight > 0, or no seed.
    """
    from uasep_env.config import make_config
    from uasep_env.evaluation import evaluate

    cfg = make_config(config).replace(action={"mode": "direct"})
    reason = "must be 0 for a budget from the metrics (they do not time region intrusions)"
    check(cfg.cost.region == 0.0, "cost.region", cfg.cost.region, reason)
    seeds = [int(s) for s in seeds]
    check(len(seeds) > 0, "seeds", seeds, "must name at least one encounter")
    result = evaluate({"apf": "apf"}, cfg, seeds, workers=workers)
    episodes = result.results["apf"].episodes
    w_u, w_o, dt = cfg.cost.separation_uav, cfg.cost.separation_obstacle, cfg.step_duration
    costs, losses = [], []
    for ep in episodes:
        m = ep.metrics
        per_uav = [(w_u * u.uav_los_time + w_o * u.obstacle_los_time) / dt for u in m.uavs]
        costs.append(sum(per_uav) / len(per_uav))
        losses.append(bool(m.episode.loss_of_separation))
    lossy = [c for c, lost in zip(costs, losses, strict=True) if lost]
    return CostBudget(
        episodes=len(episodes),
        n_uavs=cfg.n_uavs,
        loss_rate=sum(losses) / len(losses),
        mean_cost=sum(costs) / len(costs),
        cost_of_a_loss=sum(lossy) / len(lossy) if lossy else 0.0,
    )
