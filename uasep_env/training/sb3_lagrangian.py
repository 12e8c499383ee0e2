"""Lagrangian PPO on stable-baselines3: the multiplier applied to the rollouts' cost.

:class:`LagrangianCallback` turns any SB3 on-policy recipe (PPO over
:class:`~uasep_env.envs.sb3.UAVSharedVecEnv`, ``train/ppo_shared.py``) into a Lagrangian one
without a new PPO: at every step it reads each agent's cost from the infos
(:mod:`uasep_env.interface.costs`), replaces the reward PPO stores by
``(r - lambda c) / (1 + lambda)``, adds the cost to the running episode's, and at the end of
every rollout moves ``lambda`` (:class:`~uasep_env.training.lagrangian.PIDLagrangian`) with the mean
cost of the episodes that ended during it.

Why this and not a cost critic. OmniSafe's PPOLag / CPPOPID and SafePO's PPO-Lag learn a
second critic for the cost and combine the advantages as
``(A_r - lambda A_c) / (1 + lambda)``. SB3's PPO has one critic and one reward stream;
a cost critic means another rollout buffer, value head and loss, i.e. another PPO. GAE is
linear in the rewards and the values, so ``(A_r - lambda A_c) / (1 + lambda)`` is the
advantage of the reward ``(r - lambda c) / (1 + lambda)`` under the matching critic: the
two differ only in what the single critic must relearn when ``lambda`` moves (the
``1 + lambda`` keeps its targets' scale within the reward's and the cost's). The cost the
multiplier reads is the measured episode cost, as in those libraries. Neither library fits
here without its own PPO and environment API (OmniSafe's CMDP wrappers, SafePO's
single-file trainers), so they are the reference, not a dependency.

The multiplier of a rollout is the one before its end (the update at its end applies from
the next rollout on: SB3 computes the advantages before the callback sees the rollout's
end). With reward normalisation (``VecNormalize(norm_reward=True)``) the reward PPO sees is
rescaled and the cost is not, so the callback refuses it.

This module imports stable-baselines3; the rest of the package does not.
"""

from __future__ import annotations

import collections
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize

from uasep_env.interface.costs import COST_TERMS
from uasep_env.training.constraint import COST_FIELDS, CostTracker
from uasep_env.training.lagrangian import PIDLagrangian

__all__ = ["COST_FIELDS", "LagrangianCallback", "cost_reader", "plot_cost_curves"]


def cost_reader(cost: str) -> Any:
    """A function ``info -> float`` reading ``cost`` from an agent's step info.

    Args:
        cost: ``"cost"`` (the weighted total) or one of the named terms
            (:data:`~uasep_env.interface.costs.COST_TERMS`, read from ``info["cost_terms"]``).

    Raises:
        ValueError: A cost the environments do not report, named with the ones they do.
    """
    if cost == "cost":
        return lambda info: info["cost"]
    if cost in COST_TERMS:
        return lambda info: info["cost_terms"][cost]
    raise ValueError(
        f"cost {cost!r} is not reported by the environment; choose 'cost' or one of its "
        f"terms {COST_TERMS}"
    )


class LagrangianCallback(BaseCallback):
    """Apply a Lagrange multiplier to an SB3 on-policy algorithm's rewards (module docstring).

    Args:
        lagrangian: The multiplier's controller (its ``cost_limit`` is the constraint's).
        cost: Which cost to constrain: ``"cost"`` or a term name (:func:`cost_reader`).
        csv_path: Append one row per rollout (:data:`COST_FIELDS`) to this CSV; ``None``:
            none. A new file gets a header.
        window: Episodes in the running mean ``episode_cost_window``.
        verbose: SB3's verbosity.

    Attributes:
        episodes: Episodes ended so far (one per agent).
        window: The last ``window`` episode costs.
    """

    def __init__(
        self,
        lagrangian: PIDLagrangian,
        cost: str = "cost",
        csv_path: str | Path | None = None,
        window: int = 200,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if not isinstance(lagrangian, PIDLagrangian):
            raise TypeError(f"lagrangian must be a PIDLagrangian, got {lagrangian!r}")
        self.lagrangian = lagrangian
        self.cost = cost
        self._read = cost_reader(cost)
        self.csv_path = None if csv_path is None else Path(csv_path)
        self.tracker = CostTracker(lagrangian, cost, 1, window)
        self._fh: Any = None

    @property
    def multiplier(self) -> float:
        """The current multiplier ``lambda``."""
        return self.lagrangian.multiplier

    @property
    def episodes(self) -> int:
        """Episodes ended so far (one per agent)."""
        return self.tracker.episodes

    @property
    def window(self) -> collections.deque[float]:
        """The last ``window`` episode costs."""
        return self.tracker.window

    def state_dict(self) -> dict[str, Any]:
        """What a resumed run needs (JSON-friendly): the tracker's state.

        The multiplier's state, the episodes counted, the cost window and the running
        episodes' costs (:meth:`uasep_env.training.constraint.CostTracker.state_dict`).
        Saved between rollouts (the recipes checkpoint when a rollout starts), so there is
        no rollout in progress to keep.
        """
        return self.tracker.state_dict()

    def load_state_dict(self, state: dict[str, Any], running: bool = False) -> None:
        """Restore :meth:`state_dict` (the limit and gains are the constructor's).

        ``running``: the environments continue their episodes (their state restored from
        the checkpoint), so the running episodes' costs continue too.
        """
        self.tracker.load_state_dict(state, running)

    def _on_training_start(self) -> None:
        env = self.training_env
        while env is not None:  # VecNormalize anywhere in the stack rescales the reward
            if isinstance(env, VecNormalize) and env.norm_reward:
                raise ValueError(
                    "reward normalisation (VecNormalize norm_reward=True) rescales the reward "
                    "but not the cost; train the Lagrangian recipe with norm_reward=False"
                )
            env = getattr(env, "venv", None)
        self.tracker.start(self.training_env.num_envs)
        if self.csv_path is not None:  # appended durably; a link there is replaced
            from uasep_env.training.curves import ProgressLog

            self.csv_path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = ProgressLog(self.csv_path, COST_FIELDS)

    def _costs(self, infos: list[dict]) -> np.ndarray:
        try:
            return np.array([self._read(info) for info in infos], dtype=np.float64)
        except (KeyError, TypeError) as err:
            keys = sorted(infos[0]) if infos else []
            raise ValueError(
                f"the environment does not report the cost {self.cost!r} in its step infos "
                f"(keys: {keys}); use uasep_env's SB3 adapter (UAVSharedVecEnv), whose infos "
                "carry 'cost' and 'cost_terms'"
            ) from err

    def _on_step(self) -> bool:
        costs = self._costs(self.locals["infos"])
        rewards = self.locals["rewards"]  # the array PPO stores next: shaped in place
        rewards[...] = self.lagrangian.penalise(rewards, costs)
        self.tracker.step(costs, np.asarray(self.locals["dones"]))
        return True

    def _on_rollout_end(self) -> None:
        row = self.tracker.end_rollout(self.num_timesteps)
        for key in ("episode_cost_mean", "episode_cost_window", "multiplier"):
            self.logger.record(f"lagrangian/{key}", row[key])
        if self._fh is not None:
            self._fh.write(row)

    def _on_training_end(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def plot_cost_curves(csv_path: Path, png_path: Path, title: str = "") -> Path:
    """The episode cost against its limit, and the multiplier, over agent-steps (a PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from uasep_env.runtime.atomic import atomic_output
    from uasep_env.training.curves import read_progress

    rows = [r for r in read_progress(Path(csv_path)) if r.get("agent_steps", "").isdigit()]
    x = np.array([int(r["agent_steps"]) for r in rows]) * 1e-6
    col = {k: np.array([float(r[k]) for r in rows]) for k in COST_FIELDS[2:]}
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    a.plot(x, col["episode_cost_mean"], lw=0.8, alpha=0.5, label="episodes of the rollout")
    a.plot(x, col["episode_cost_window"], lw=1.4, label="last 200 episodes")
    a.plot(x, col["cost_limit"], "k--", lw=1.0, label="cost limit")
    a.set_title("episode cost per agent (steps in loss of separation)", fontsize=10)
    a.legend(fontsize=8)
    b.plot(x, col["multiplier"], lw=1.4)
    b.set_title("Lagrange multiplier", fontsize=10)
    for ax in (a, b):
        ax.set_xlabel("agent-steps (millions)")
        ax.grid(alpha=0.3)
    fig.suptitle(title or Path(csv_path).parent.name)
    fig.tight_layout()
    with atomic_output(Path(png_path), replace_links=True) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
    return Path(png_path)
