"""Train MAPPO under a safety constraint: a cost critic and a PID Lagrange multiplier.

The recipe of ``uasep-train mappo`` (:mod:`uasep_env.training.mappo`: every flag applies)
with the task reward (``--config reward=task``: deviation, control, smoothness and the
alive bonus, no separation or collision term) and the separation kept as a constraint on
the cost channel instead: the expected episode cost per agent (:mod:`uasep_env.interface.costs`:
steps in loss of separation) must stay at most ``--cost-limit``.

    uasep-train mappo_lagrangian                            # limit: the APF's mean cost
    uasep-train mappo_lagrangian --cost-limit 0.5           # a limit of your own
    uasep-train mappo_lagrangian --resume runs/mappo_lagrangian/checkpoints/latest

(``python train/mappo_lagrangian.py`` in a checkout is the same command.)

The algorithm is MAPPO-Lagrangian as in SafePO and OmniSafe, on skrl's MAPPO (a subclass,
:func:`agent_class`; no second PPO):

* a **cost critic** ``V_c``, of the value critic's shape on the same agent-specific global
  state and shared by the agents as it is, predicts the discounted cost return; its targets
  are normalised by a running scaler of their own, and it is trained after skrl's update,
  with its own Adam optimiser (one per agent over the shared network, as skrl's critic),
  the same epochs, mini-batches, loss scale and gradient clip;
* cost advantages ``A_c`` by GAE with the reward's ``gamma`` and ``lambda``; the actor is
  updated on ``(A_r - lambda A_c) / (1 + lambda)`` (OmniSafe's PPOLag), ``A_r`` being skrl's
  reward advantage (standardised: mean 0, std 1) and ``A_c`` centred but not scaled
  (OmniSafe's rule: a rollout without cost has a near-zero ``A_c``, which standardising
  would blow up to unit noise; SafePO's MAPPO-L standardises both);
* the multiplier ``lambda`` (:class:`uasep_env.training.lagrangian.PIDLagrangian`; ``--pid-kp 0
  --pid-kd 0`` is plain gradient ascent) moves once per rollout, before the rollout's
  update, with the mean episode cost per agent of the episodes that ended in it.

With ``lambda = 0`` the actor and the reward critic get exactly plain MAPPO's update (the
cost critic's initialisation and mini-batches come from random streams of their own, so a
run that never moves the multiplier is plain MAPPO's, weight for weight).

``--cost-limit``: a number >= 0, ``apf`` (the APF's mean episode cost on
``--budget-episodes`` validation encounters) or ``apf-rate`` (the APF's loss-of-separation
rate over the formation size); see :mod:`uasep_env.training.constraint`. The limit is
written to ``budget.json``.

Beside ``mappo``'s outputs a run writes ``cost_progress.csv`` (one row per rollout: the mean
episode cost of the rollout's episodes and of the last 200, the limit and the multiplier),
``cost_curves.png`` drawn from it, and the constraint's state (``lagrangian``: cost, limit,
multiplier and its controller's state) in the checkpoints' ``state.json`` and in
``validation.json``. ``--resume`` restores the cost critic, its optimiser and scaler, and the
multiplier, and rewinds ``cost_progress.csv`` to the checkpoint as ``progress.csv``; from a
checkpoint between two rollouts (with ``env_state.npz``, :func:`mappo.continue_episodes`) the
episodes and their running costs continue too, and the resumed run is the uninterrupted
one, bit for bit.
``policy.zip`` is the actor only, as ``mappo``'s. ``--norm-reward`` is refused (it would
rescale the reward but not the cost). Requires the ``train`` extra and skrl.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.training import constraint, mappo, ppo_shared
from uasep_env.training.args import parse_args as _parse_args

if TYPE_CHECKING:
    from uasep_env.training.rundir import RunFolder

__all__ = ["Args", "LagrangianHooks", "agent_class", "combine_advantages", "main",
           "parse_args", "run", "train"]  # fmt: skip


@dataclass
class Args(constraint.LagrangianArgs, mappo.Args):
    """``mappo.Args`` with the constraint's options (:class:`~constraint.LagrangianArgs`)."""

    out_dir: str = "runs/mappo_lagrangian"


def _check(args: Args) -> str | None:
    return constraint.check(args) or mappo._check(args)


def parse_args(argv: list[str] | None = None, defaults: Args | None = None) -> Args:
    """MAPPO-Lagrangian's :class:`Args` from the command line, or exit 2 naming the flag."""
    return _parse_args(
        argv, defaults or Args(), prog=ppo_shared._prog(), description=__doc__, check=_check
    )


def combine_advantages(reward_adv: Any, cost_adv: Any, multiplier: float) -> Any:
    """The actor's advantage ``(A_r - lambda A_c) / (1 + lambda)`` (arrays or tensors).

    ``multiplier = 0`` gives ``A_r`` exactly; a larger one favours the actions of lower cost
    advantage, and the ``1 + lambda`` keeps the scale within ``A_r``'s and ``A_c``'s.
    """
    return (reward_adv - multiplier * cost_adv) / (1.0 + multiplier)


@functools.cache
def agent_class() -> type:
    """The skrl MAPPO with a cost critic (module docstring); built on first use (lazy skrl)."""
    import torch
    import torch.nn.functional as F
    from skrl.multi_agents.torch.mappo import MAPPO
    from skrl.multi_agents.torch.mappo.mappo import compute_gae
    from skrl.resources.preprocessors.torch import RunningStandardScaler

    class Sampler:
        """The cost critic's mini-batch permutations: a torch generator of its own."""

        def __init__(self, seed: int) -> None:
            self.generator = torch.Generator().manual_seed(seed)

        def state_dict(self) -> dict:
            return {"state": self.generator.get_state()}

        def load_state_dict(self, state: dict) -> None:
            self.generator.set_state(state["state"])

    class MAPPOLagrangian(MAPPO):
        """skrl's MAPPO whose actor learns ``(A_r - lambda A_c) / (1 + lambda)``.

        The models of each agent hold ``"cost_value"`` beside ``"policy"`` and ``"value"``
        (:func:`uasep_env.training.mappo.build` makes it, from :attr:`extra_critics`); the
        step's costs come in ``record_transition``'s ``infos["cost"]`` (per agent,
        ``(num_envs, 1)``); :attr:`multiplier` is set by the training loop.
        """

        extra_critics = ("cost_value",)

        def __init__(self, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            self.multiplier = 0.0
            self.cost_values = {u: self.models[u]["cost_value"] for u in self.possible_agents}
            self.cost_optimizers: dict = {}
            self._cost_value_preprocessor: dict = {}
            self._cost_sampler = Sampler(torch.initial_seed() + 1)
            for uid in self.possible_agents:
                critic = self.cost_values[uid]
                self.cost_optimizers[uid] = torch.optim.Adam(
                    critic.parameters(), lr=self.cfg.learning_rate[uid][0]
                )
                # Unclipped (skrl's value scaler clips at 5 std): a rare large cost return
                # is the cost's signal, not an outlier.
                self._cost_value_preprocessor[uid] = RunningStandardScaler(
                    size=1, clip_threshold=float("inf"), device=self.device
                )
                # Saved and restored with the rest (mappo.save_checkpoint / load_checkpoint).
                mods = self.checkpoint_modules[uid]
                mods["cost_value"] = critic
                mods["cost_optimizer"] = self.cost_optimizers[uid]
                mods["cost_value_preprocessor"] = self._cost_value_preprocessor[uid]
            self.checkpoint_modules[self.possible_agents[0]]["cost_sampler"] = self._cost_sampler

        def init(self, *, trainer_cfg: dict | None = None) -> None:
            super().init(trainer_cfg=trainer_cfg)
            # skrl's mini-batch loop takes the advantage from the last of these names: the
            # combined one is read in its place (the only change to skrl's update).
            if self._tensors_names[-1] != "advantages":
                raise RuntimeError(f"unexpected skrl MAPPO sample names {self._tensors_names}")
            self._tensors_names = [*self._tensors_names[:-1], "lagrangian_advantages"]
            for uid in self.possible_agents:
                for name in ("costs", "cost_values", "cost_returns", "lagrangian_advantages"):
                    self.memories[uid].create_tensor(name=name, size=1, dtype=torch.float32)
            self._current_cost_values: dict = {}

        def act(self, observations: dict, states: dict, *, timestep: int, timesteps: int) -> Any:
            out = super().act(observations, states, timestep=timestep, timesteps=timesteps)
            if self.training:
                for uid in self.possible_agents:
                    inputs = {"states": self._state_preprocessor[uid](states[uid])}
                    c, _ = self.cost_values[uid].act(inputs, role="value")
                    self._current_cost_values[uid] = self._cost_value_preprocessor[uid](
                        c, inverse=True
                    )
            return out

        def record_transition(self, *, infos: dict, **kwargs: Any) -> None:
            index = {uid: self.memories[uid].memory_index for uid in self.possible_agents}
            super().record_transition(infos=infos, **kwargs)
            if not self.training:
                return
            if "cost" not in infos:
                raise ValueError("MAPPO-Lagrangian needs each step's costs: infos['cost'][agent]")
            for uid in self.possible_agents:  # the row skrl has just written
                tensors = self.memories[uid].tensors
                tensors["costs"][index[uid]].copy_(infos["cost"][uid])
                tensors["cost_values"][index[uid]].copy_(self._current_cost_values[uid])

        def _gae(self, uid: str, rewards: Any, values: Any, critic: Any, scaler: Any) -> Any:
            """The GAE of skrl's ``update`` runs it: (returns, standardised advantages)."""
            memory = self.memories[uid]
            with torch.no_grad():
                inputs = {"states": self._state_preprocessor[uid](self._current_next_states[uid])}
                last, _ = critic.act(inputs, role="value")
                last = scaler(last, inverse=True)
            return compute_gae(
                rewards=rewards,
                terminated=memory.get_tensor_by_name("terminated"),
                truncated=memory.get_tensor_by_name("truncated"),
                values=values,
                last_values=last,
                discount_factor=self.cfg.discount_factor[uid],
                lambda_coefficient=self.cfg.gae_lambda[uid],
                time_limit_bootstrap=self.cfg.time_limit_bootstrap[uid],
            )

        def update(self, *, timestep: int, timesteps: int, uid: str) -> None:
            memory = self.memories[uid]
            # The reward's advantage, computed as skrl's update is about to (checked below).
            _, reward_adv = self._gae(
                uid,
                memory.get_tensor_by_name("rewards"),
                memory.get_tensor_by_name("values"),
                self.values[uid],
                self._value_preprocessor[uid],
            )
            cost_values = memory.get_tensor_by_name("cost_values")
            scaler = self._cost_value_preprocessor[uid]
            cost_returns, _ = self._gae(
                uid, memory.get_tensor_by_name("costs"), cost_values, self.cost_values[uid], scaler
            )
            cost_adv = cost_returns - cost_values
            cost_adv = cost_adv - cost_adv.mean()
            memory.set_tensor_by_name("cost_returns", scaler(cost_returns, train=True))
            combined = combine_advantages(reward_adv, cost_adv, self.multiplier)
            memory.set_tensor_by_name("lagrangian_advantages", combined)
            super().update(timestep=timestep, timesteps=timesteps, uid=uid)
            if not torch.equal(memory.get_tensor_by_name("advantages"), reward_adv):
                raise RuntimeError(
                    "skrl's MAPPO computed another reward advantage than this recipe's copy of "
                    "its GAE (a different skrl version?); the actor's update was wrong"
                )
            self._update_cost_critic(uid)

        def _update_cost_critic(self, uid: str) -> None:
            memory, critic = self.memories[uid], self.cost_values[uid]
            optimizer, clip = self.cost_optimizers[uid], self.cfg.grad_norm_clip[uid]
            states = memory.tensors_view["states"]
            returns = memory.tensors_view["cost_returns"]
            total = 0.0
            for _ in range(self.cfg.learning_epochs[uid]):
                order = torch.randperm(len(memory), generator=self._cost_sampler.generator)
                for batch in order.tensor_split(self.cfg.mini_batches[uid]):
                    inputs = {"states": self._state_preprocessor[uid](states[batch])}
                    predicted, _ = critic.act(inputs, role="value")
                    loss = self.cfg.value_loss_scale[uid] * F.mse_loss(returns[batch], predicted)
                    optimizer.zero_grad()
                    loss.backward()
                    if clip > 0:
                        torch.nn.utils.clip_grad_norm_(critic.parameters(), clip)
                    optimizer.step()
                    total += loss.item()
            n = self.cfg.learning_epochs[uid] * self.cfg.mini_batches[uid]
            self.track_data(f"Loss / Cost value loss ({uid})", total / n)

    return MAPPOLagrangian


class LagrangianHooks(mappo.Hooks):
    """The constraint in :func:`uasep_env.training.mappo.train`'s loop.

    Reads each step's costs from the environments' infos, hands them to the agent, moves
    the multiplier at the end of each rollout (``cost_progress.csv``), and keeps the
    constraint's state in the checkpoints.

    Args:
        args: The options (``cost``, the PID gains...).
        limit: The cost limit per agent and episode.
    """

    def __init__(self, args: Args, limit: float) -> None:
        from uasep_env.training.sb3_lagrangian import cost_reader

        self.agent_class = agent_class()
        self.args = args
        self.read = cost_reader(args.cost)
        self.lagrangian = constraint.make_lagrangian(args, limit)
        self.tracker: constraint.CostTracker | None = None
        self.agent: Any = None
        self.log: Any = None

    def start(self, agent: Any, env: mappo.SkrlView, out: Path, resumed: dict) -> None:
        """Restore the constraint from ``resumed`` (rewinding ``cost_progress.csv``)."""
        from uasep_env.training.rundir import ProgressLog, restore_json, rewind_csv
        from uasep_env.training.sb3_lagrangian import COST_FIELDS

        self.agent = agent
        self.tracker = constraint.CostTracker(self.lagrangian, self.args.cost, env.num_envs * env.n)
        path = out / "cost_progress.csv"
        if resumed:
            folder = Path(self.args.resume)

            def load(saved: Any) -> None:
                # The episodes' running costs go on where the episodes do.
                self.tracker.load_state_dict(saved, running=env.continued)

            restore_json(folder, "lagrangian", load, resumed["lagrangian"])
            rewind_csv(path, COST_FIELDS, int(resumed["agent_steps"]))
        self.tracker.start(env.num_envs * env.n)
        agent.multiplier = self.lagrangian.multiplier
        self.log = ProgressLog(path, COST_FIELDS)

    def step(self, env: mappo.SkrlView) -> dict:
        """The step's costs: counted into the episodes, and per agent for the agent."""
        import torch

        assert self.tracker is not None
        costs = np.array([self.read(info) for info in env.infos], dtype=np.float64)
        self.tracker.step(costs, env.dones)
        per = costs.astype(np.float32).reshape(env.num_envs, env.n)
        return {
            "cost": {
                uid: torch.from_numpy(per[:, i : i + 1].copy())
                for i, uid in enumerate(env.possible_agents)
            }
        }

    def rollout_end(self, agent_steps: int) -> None:
        """Move the multiplier (before the rollout's update) and log it."""
        assert self.tracker is not None
        self.log.write(self.tracker.end_rollout(agent_steps))
        self.agent.multiplier = self.lagrangian.multiplier

    def info(self) -> dict:
        """``lagrangian``: cost, limit, the multiplier's state."""
        return {"lagrangian": self.tracker.info()} if self.tracker is not None else {}

    def state(self) -> dict:
        """``lagrangian`` with the episode window: what ``--resume`` restores."""
        return {"lagrangian": self.tracker.state_dict()} if self.tracker is not None else {}

    def close(self) -> None:
        """Close ``cost_progress.csv``."""
        if self.log is not None:
            self.log.close()


def train(
    args: Args, config: Any, out: Path | RunFolder, limit: float
) -> tuple[Any, Any, dict, Any]:
    """:func:`uasep_env.training.mappo.train` under the constraint; also returns the hooks."""
    hooks = LagrangianHooks(args, limit)
    agent, venv, info = mappo.train(args, config, out, hooks)
    return agent, venv, info, hooks


def _limit(args: Args, config: Any, out: Path, resumed: dict) -> float:
    """The cost limit: the checkpoint's when resuming with the same option, else measured."""
    lag = resumed.get("lagrangian")
    if lag is not None and resumed.get("args", {}).get("cost_limit") == args.cost_limit:
        from uasep_env.training.lagrangian import check_cost_limit
        from uasep_env.training.rundir import restore_json

        limit = lag.get("cost_limit")
        restore_json(Path(args.resume), "lagrangian.cost_limit", check_cost_limit, limit)
        print(f"cost limit {limit:.4g} per agent and episode (the checkpoint's)")
        return float(limit)
    return constraint.measure_budget(args, config, out)


def _check_resume(directory: Path, info: dict, args: Args) -> None:
    """Refuse a checkpoint of plain MAPPO, or of the other ``--value-norm`` (one line)."""
    from uasep_env.training.rundir import RunError, check_switch

    if "lagrangian" not in info:  # plain MAPPO's has no cost critic, no multiplier
        raise RunError(f"--resume {args.resume}: not a MAPPO-Lagrangian checkpoint")
    check_switch(directory, info, args, "value_norm", default=True)


def main(argv: list[str] | None = None, defaults: Args | None = None) -> dict:
    """Train (or resume) under the constraint, export the actor, validate; the summary."""
    args = parse_args(argv, defaults)
    import torch  # lazy: the training extra

    from uasep_env.training.rundir import RunFolder
    from uasep_env.training.sb3_lagrangian import plot_cost_curves

    torch.set_num_threads(args.torch_threads)
    config = ppo_shared.make_env_config(args)
    task = config.reward == config.reward.task()
    print(f"reward: {'the task reward' if task else config.reward} (--config {args.config!r})")
    run = RunFolder.start(
        args,
        lambda ck, info: _check_resume(ck, info, args),
        same_trainer=False,  # as it always was: the Lagrangian check says it first
        own_files=constraint.COST_FILES,  # --overwrite deletes the constraint's files too
    )
    limit = _limit(args, config, run.out, run.resumed)
    agent, venv, info, _ = train(args, config, run, limit)
    title = "MAPPO-Lagrangian (skrl)"
    return run.publish(
        lambda path: mappo.export_policy(agent, venv, config, args, path, info),
        config, info, title,
        more=lambda out: plot_cost_curves(
            out / "cost_progress.csv", out / "cost_curves.png", title
        ),
    )  # fmt: skip


def cli(argv: list[str] | None = None) -> None:
    """Run :func:`main` (:func:`uasep_env.training.ppo_shared.cli`'s error handling)."""
    ppo_shared.cli(None, argv, main)


run = cli  # ``uasep-train mappo_lagrangian``
