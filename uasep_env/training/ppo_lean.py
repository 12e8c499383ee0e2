"""PPO in one loop on the batched core: the SB3 recipes' algorithm without SB3's per-step layers.

A leaner PPO loop on the native vector env: CleanRL's layout (the whole
loop in plain sight, arrays batch-first) over :class:`~uasep_env.envs.core.EnvCore`, with
the settings of :mod:`~uasep_env.training.ppo_shared` (its :class:`~.args.Args`, so the
residual recipe's defaults apply as they are). What SB3 pays for every step and this loop
does not: an info dict per agent (built by the SB3 view, read by ``VecMonitor`` and PPO's
info buffer), ``VecNormalize``'s and ``VecMonitor``'s wrappers, the policy's distribution
objects and the rollout buffer's per-step copies. The algorithm is SB3's PPO as the recipes
configure it, step for step:

* observations normalised by running statistics updated with every step's batch
  (SB3's :class:`~stable_baselines3.common.running_mean_std.RunningMeanStd`, ``VecNormalize``'s
  clip and epsilon); returns normalised too under ``--norm-reward``;
* a Gaussian actor MLP (state-independent log-std) and a critic MLP of the same widths,
  orthogonal initialisation (gains sqrt(2), 0.01 for the mean, 1 for the value), Adam with
  ``eps=1e-5``; actions clipped to the box for the environment, stored unclipped;
* a time limit bootstraps the reward with the value of the terminal observation; GAE;
  ``n_epochs`` epochs of shuffled minibatches of ``batch_size``, advantages normalised per
  minibatch, clipped ratio, value loss weight 0.5, entropy weight ``ent_coef``, gradient
  norm clipped at 0.5, the epochs stopped when the approximate KL passes
  ``1.5 * target_kl``; the actor frozen for the first ``critic_warmup - 1`` updates (the
  SB3 recipes' count).

It is not SB3 bit for bit (torch draws its numbers in another order), so a run is another
training of the same recipe. The exported policy is the recipes' checkpoint
(:func:`~uasep_env.training.rundir.export_actor`): ``uasep-eval --policy`` and the
selection scripts run it as any other. ``uasep-train ppo_residual_apf --trainer lean`` (any
PPO recipe but the Lagrangian ones) trains a recipe's run with it, checkpoints and
``--resume`` included (:mod:`~uasep_env.training.lean_recipe`);
``benchmarks/time_to_policy.py --trainer lean`` measures it against SB3 (``docs/speed.md``
says what it measured). ``--device cuda`` runs the
update on a GPU, on a copy of the networks whose weights the rollout's CPU copy takes after
each update; the rollout acts on the CPU (its draws are the CPU's in either case).

**MAPPO** (``uasep-train mappo --trainer lean``; ``central=True`` here): the same loop with
the critic of MAPPO (Yu et al. 2022) in place of the local one, as the skrl recipe
(:mod:`~uasep_env.training.mappo`) builds it: the critic reads the agent-specific global
state, the environment's global true state (:meth:`~uasep_env.envs.core.EnvCore.state`)
beside the agent's own normalised observation, normalised by running statistics of its
own, and predicts values normalised by the running statistics of the returns (skrl's value
preprocessor; Yu et al.'s value normalisation): the returns update them before each update,
the critic's outputs are mapped back for GAE (``--no-value-norm``: raw returns, as PPO's
critic). A time limit ends an episode as a termination (no bootstrap), as the skrl recipe
has it: the global state holds the episode's progress. The value loss weight and the
gradient clip are MAPPO's flags (``--value-loss-scale``, ``--grad-norm-clip``; 0: no clip).
Unlike skrl's MAPPO, which updates the shared actor once per agent in turn (each with its
own Adam state), the shared actor is updated once per minibatch on every agent's steps
together, as Yu et al.'s parameter sharing does.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from uasep_env.training.args import Args
from uasep_env.training.lean_networks import _ActorCritic, _update, export_policy

__all__ = ["CLIP_OBS", "Hooks", "Normaliser", "State", "export_policy", "gae", "train"]

#: ``VecNormalize``'s defaults: the clip of normalised observations (and returns), and the
#: epsilon under the square root.
CLIP_OBS, EPSILON = 10.0, 1e-8


class Normaliser:
    """``VecNormalize``'s arithmetic on arrays: running observation (and return) statistics.

    Args:
        obs_dim: Observation width.
        n_rows: Rows per step (every agent of every environment).
        norm_obs: Normalise observations.
        norm_reward: Scale rewards by the running standard deviation of the discounted return.
        gamma: The return's discount.
        tied: A set network's layout
            (:class:`~uasep_env.policies.set_network.SetLayout`): the statistics are shared by
            the slots of a neighbour type, taken over the present ones, and leave the masks
            as they are (:func:`~uasep_env.policies.set_network.tied_moments`), so that they
            fit any K. None: per column, as ``VecNormalize``.
    """

    def __init__(
        self,
        obs_dim: int,
        n_rows: int,
        *,
        norm_obs: bool,
        norm_reward: bool,
        gamma: float,
        tied: Any = None,
    ) -> None:
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        self.obs_rms = RunningMeanStd(shape=(obs_dim,))
        self.ret_rms = RunningMeanStd(shape=())
        self.norm_obs, self.norm_reward, self.gamma = norm_obs, norm_reward, gamma
        self.tied = tied
        self.returns = np.zeros(n_rows)
        # What export_actor reads of a VecNormalize.
        self.clip_obs, self.epsilon = CLIP_OBS, EPSILON
        self.observation_space = SimpleNamespace(shape=(obs_dim,))

    def observe(self, obs: np.ndarray, *, update: bool) -> np.ndarray:
        """``obs`` ``(rows, obs_dim)`` normalised (float32); the statistics first updated."""
        if update and self.norm_obs:
            if self.tied is None:
                self.obs_rms.update(obs)
            else:
                from uasep_env.policies.set_network import tied_moments

                rms = self.obs_rms
                mean, var = tied_moments(self.tied, obs, rms.mean, rms.var)
                rms.update_from_moments(mean, var, obs.shape[0])
        return self.normalise(obs)

    def normalise(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` with the current statistics, as ``VecNormalize.normalize_obs``."""
        if not self.norm_obs:
            return obs.astype(np.float32)
        rms = self.obs_rms
        z = (obs - rms.mean) / np.sqrt(rms.var + self.epsilon)
        return np.clip(z, -self.clip_obs, self.clip_obs).astype(np.float32)

    def reward(self, rewards: np.ndarray, dones: np.ndarray) -> np.ndarray:
        """``rewards`` ``(rows,)`` scaled as ``VecNormalize`` does (unchanged when off)."""
        if not self.norm_reward:
            return rewards
        self.returns = self.returns * self.gamma + rewards
        self.ret_rms.update(self.returns)
        scaled = np.clip(rewards / np.sqrt(self.ret_rms.var + self.epsilon), -CLIP_OBS, CLIP_OBS)
        self.returns[dones] = 0.0
        return scaled


class ValueScale:
    """Running statistics of the returns: the centralised critic's value normalisation.

    skrl's ``RunningStandardScaler`` as the MAPPO recipe's value preprocessor uses it
    (mean and variance over every return seen, updated with each rollout's before its
    update), without its clip: the critic predicts ``(value - mean) / std``.
    """

    def __init__(self) -> None:
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        self.rms = RunningMeanStd(shape=())

    @property
    def std(self) -> float:
        return float(np.sqrt(self.rms.var + EPSILON))

    def to_value(self, scaled: np.ndarray) -> np.ndarray:
        """The critic's output in return units."""
        return (scaled * self.std + self.rms.mean).astype(np.float32)

    def scale(self, returns: np.ndarray) -> np.ndarray:
        """``returns`` in the critic's units (statistics updated with them first)."""
        self.rms.update(returns.reshape(-1))
        return ((returns - self.rms.mean) / self.std).astype(np.float32)


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    starts: np.ndarray,
    last_value: np.ndarray,
    last_done: np.ndarray,
    gamma: float,
    lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and returns of one rollout, as SB3's ``compute_returns_and_advantage``.

    Args:
        rewards: ``(T, rows)`` rewards (a time limit's bootstrap included).
        values: ``(T, rows)`` the critic's values of the observations acted on.
        starts: ``(T, rows)`` 1 where the observation began an episode.
        last_value: ``(rows,)`` the value of the observation after the rollout.
        last_done: ``(rows,)`` 1 where that observation began an episode.
        gamma: Discount.
        lam: GAE's lambda.

    Returns:
        ``(advantages, returns)``, each ``(T, rows)``.
    """
    adv = np.zeros_like(rewards)
    running = np.zeros(rewards.shape[1], dtype=rewards.dtype)
    for t in reversed(range(len(rewards))):
        if t == len(rewards) - 1:
            alive, nxt = 1.0 - last_done, last_value
        else:
            alive, nxt = 1.0 - starts[t + 1], values[t + 1]
        delta = rewards[t] + gamma * nxt * alive - values[t]
        running = delta + gamma * lam * alive * running
        adv[t] = running
    return adv, adv + values


class Hooks:
    """What a caller may do around the loop; no-ops here.

    ``benchmarks/time_to_policy.py`` checks the policy as it trains; the recipe's run
    (:mod:`uasep_env.training.lean_recipe`) writes its learning curve and checkpoints.
    """

    def start(self, nets: _ActorCritic, norm: Normaliser) -> None:
        """Before the first rollout."""

    def rollout_end(self, agent_steps: int) -> None:
        """After each rollout, before its update."""

    def act(self, actions: np.ndarray, observations: np.ndarray) -> np.ndarray:
        """The actions ``(E, N, 3)`` the core steps with (the sampled ones, clipped, here).

        ``observations``: the raw ``(E, N, obs_dim)`` observations they were sampled for.
        Training under the shield filters them here
        (:class:`~uasep_env.training.shield_loop.ShieldInLoop`); PPO learns from the
        sampled actions.
        """
        return actions

    def shape(self, res: Any, reward: np.ndarray, dones: np.ndarray) -> np.ndarray:
        """The rewards ``(E * N,)`` PPO learns from for the core's step ``res`` (unchanged here).

        Called at every step before a time limit's bootstrap: the Lagrangian recipes apply
        their multiplier here (:class:`uasep_env.training.constraint.LeanCost`).
        """
        return reward

    def update_end(self, state: State) -> None:
        """After each update; ``state.finished`` holds the episodes ended since the last one."""

    def stop(self) -> bool:
        """Whether to stop before the next rollout."""
        return False


@dataclass(kw_only=True)
class State:
    """What a run has learnt and counted: what a checkpoint saves and a resume restores.

    Attributes:
        nets: The networks the rollout acts with (on the CPU).
        learner: The networks the update trains (``nets`` themselves on the CPU, else a
            copy on ``args.device`` whose weights ``nets`` take after each update).
        opt: The learner's Adam optimiser.
        norm: The observation (and return) normalisation.
        agent_steps: Agent-steps trained so far.
        updates: PPO updates so far (the critic warm-up counts them).
        episodes: Episodes finished so far.
        wall_s: Training seconds so far (a resumed run's earlier ones included; hooks'
            time excluded).
        critic_norm: MAPPO's: the running statistics of the critic's input (None for PPO).
        value_scale: MAPPO's: the value normalisation (None for PPO, and for MAPPO under
            ``--no-value-norm``).
        finished: ``(return, collision, loss_of_separation, max_deviation, length)`` of
            each episode ended since the last update (emptied after
            :meth:`Hooks.update_end`): the return and length
            of its first UAV (as SB3's ``VecMonitor`` counts each agent), the safety
            figures of :class:`~uasep_env.envs.episode_safety.EpisodeSafety`.
    """

    nets: _ActorCritic
    learner: _ActorCritic
    opt: Any
    norm: Normaliser
    agent_steps: int = 0
    updates: int = 0
    episodes: int = 0
    wall_s: float = 0.0
    critic_norm: Normaliser | None = None
    value_scale: ValueScale | None = None
    finished: list[tuple[float, bool, bool, float, int]] = field(default_factory=list)


@dataclass(kw_only=True)
class _Timing:
    """Seconds in each part of a run: the core's steps, the rest of the rollouts, the updates."""

    env_s: float = 0.0
    rollout_s: float = 0.0
    learner_s: float = 0.0


class _Rollout:
    """The rollout's state and buffers: ``n_steps`` steps of every agent of the core."""

    def __init__(
        self,
        core: Any,
        state: State,
        n_steps: int,
        hooks: Hooks | None = None,
        pad: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        import torch

        from uasep_env.envs.episode_safety import EpisodeSafety

        self.core, self.nets, self.norm, self.state = core, state.nets, state.norm, state
        self.hooks = hooks or Hooks()
        self.n_envs, self.n = core.n_envs, core.n_uavs
        # A smaller formation's observations padded to the network's slots (--formation-sizes).
        self.pad = pad or (lambda obs: obs)
        rows, dim = self.n_envs * self.n, state.norm.observation_space.shape[0]
        self.obs_t = torch.zeros((n_steps, rows, dim))
        # MAPPO: the critic's inputs, stored apart (the PPO critic reads obs_t).
        self.central = state.critic_norm is not None
        self.crit_t = (
            torch.zeros((n_steps, rows, state.critic_norm.observation_space.shape[0]))
            if self.central else self.obs_t
        )  # fmt: skip
        self.act = torch.zeros((n_steps, rows, 3))
        self.logp = torch.zeros((n_steps, rows))
        self.rewards = np.zeros((n_steps, rows), dtype=np.float32)
        self.values = np.zeros((n_steps, rows), dtype=np.float32)
        self.starts = np.zeros((n_steps, rows), dtype=np.float32)
        self.last_value = np.zeros(rows, dtype=np.float32)
        self.obs = np.zeros((rows, dim), dtype=np.float32)  # the next observation, normalised
        self.raw = np.zeros((rows, dim), dtype=np.float32)  # the same, as observed
        self.start = np.ones(rows, dtype=np.float32)  # 1 where it begins an episode
        # The running episodes: safety, and the first UAV's return and length (raw rewards).
        self.safety = EpisodeSafety(self.n_envs)
        self.ep_return = np.zeros(self.n_envs)
        self.ep_length = np.zeros(self.n_envs, dtype=np.int64)

    def reset(self, seed: int) -> None:
        """Reset every environment (environment ``e`` gets ``seed + e``)."""
        raw = self.pad(self.core.reset(seed=seed).reshape(len(self.obs), -1))
        self.raw = raw
        self.obs = self.norm.observe(raw, update=True)
        self.start[:] = 1.0
        self.safety.clear()
        self.ep_return[:] = 0.0
        self.ep_length[:] = 0

    def critic_input(self, *, update: bool) -> Any:
        """The critic's input for the current observations (a tensor ``(rows, width)``).

        PPO's critic reads the observation; MAPPO's the agent-specific global state: the
        environment's global state beside the agent's normalised observation, normalised by
        the critic's own running statistics (updated with it under ``update``).
        """
        import torch

        if not self.central:
            return torch.from_numpy(self.obs)
        g = np.repeat(self.core.state(), self.n, axis=0)
        return torch.from_numpy(
            self.state.critic_norm.observe(np.concatenate([g, self.obs], axis=1), update=update)
        )

    def value(self, x: Any) -> np.ndarray:
        """The critic's values of inputs ``x`` in return units (MAPPO's mapped back)."""
        v = self.nets.value(x).numpy()
        scale = self.state.value_scale
        return v if scale is None else scale.to_value(v)

    def collect(self, gamma: float) -> float:
        """Fill the buffers (SB3's ``collect_rollouts``); returns the seconds in the core."""
        import torch

        nets, norm, core, n = self.nets, self.norm, self.core, self.n
        env_s = 0.0
        with torch.no_grad():
            for t in range(len(self.rewards)):
                x = torch.from_numpy(self.obs)
                mean = nets.mu(nets.pi(x))
                act = mean + nets.log_std.exp() * torch.randn_like(mean)
                self.obs_t[t] = x
                self.act[t] = act
                self.logp[t] = nets.log_prob(mean, act)
                c = self.critic_input(update=True)
                if self.central:
                    self.crit_t[t] = c
                self.values[t] = self.value(c)
                self.starts[t] = self.start
                flown = self.hooks.act(
                    np.clip(act.numpy(), -1.0, 1.0).reshape(self.n_envs, n, 3),
                    self.raw.reshape(self.n_envs, n, -1),
                )
                e0 = time.perf_counter()
                res = core.step(flown)
                env_s += time.perf_counter() - e0
                done_env = res.terminated | res.truncated
                self._track(res, done_env)
                dones = np.repeat(done_env, n)
                reward = norm.reward(res.rewards.reshape(-1).astype(np.float32), dones)
                reward = self.hooks.shape(res, reward, dones)
                raw = self.pad(res.obs.reshape(len(self.obs), -1))
                if not done_env.any():
                    self.obs = norm.observe(raw, update=True)
                else:
                    final = raw[dones]  # a copy: the resets below write into raw
                    e0 = time.perf_counter()
                    raw[dones] = self.pad(core.reset_some(done_env).reshape(-1, core.obs_dim))
                    env_s += time.perf_counter() - e0
                    # VecNormalize's order: the statistics take the new observations
                    # first, then the finished episodes' last ones are normalised.
                    self.obs = norm.observe(raw, update=True)
                    timeout = np.repeat(res.truncated & ~res.terminated, n)[dones]
                    # A time limit: bootstrap from the terminal state (MAPPO's critic sees
                    # the episode's progress in the global state: a time limit is an end).
                    if timeout.any() and not self.central:
                        last = torch.from_numpy(norm.normalise(final[timeout]))
                        rows_out = np.flatnonzero(dones)[timeout]
                        reward[rows_out] += gamma * self.value(last)
                self.raw = raw
                self.rewards[t] = reward
                self.start = dones.astype(np.float32)
            # Not counted in the statistics: the next rollout's first step counts it.
            self.last_value = self.value(self.critic_input(update=False))
        return env_s

    def _track(self, res: Any, done_env: np.ndarray) -> None:
        """Fold a step into the running episodes; record and clear those that ended."""
        self.safety.track(self.core.world, res.safety)
        self.ep_return += res.rewards[:, 0]
        self.ep_length += 1
        if not done_env.any():
            return
        for e in np.flatnonzero(done_env).tolist():
            s = self.safety.summary(e)
            self.state.finished.append((
                float(self.ep_return[e]), s["collision"], s["loss_of_separation"],
                s["max_deviation"], int(self.ep_length[e]),
            ))  # fmt: skip
        self.state.episodes += int(done_env.sum())
        self.safety.clear(done_env)
        self.ep_return[done_env] = 0.0
        self.ep_length[done_env] = 0


def train(
    args: Args,
    config: Any,
    hooks: Hooks | None = None,
    prepare: Callable[[State], None] | None = None,
    *,
    central: bool = False,
) -> tuple[_ActorCritic, Normaliser, dict[str, Any]]:
    """Train until ``args.total_timesteps`` agent-steps, ``args.max_minutes`` or ``hooks.stop()``.

    Args:
        args: The recipe's settings (:class:`~uasep_env.training.args.Args`).
        config: Its :class:`~uasep_env.config.EnvConfig`
            (:func:`~uasep_env.training.args.make_env_config`).
        hooks: Called at the start, at each rollout's end, after each update and before
            each rollout.
        prepare: Called with the fresh :class:`State` before the environments are reset:
            a resume restores a checkpoint into it (weights, optimiser, normalisation,
            counters, random state); the wall budget counts ``state.wall_s`` as spent.
        central: MAPPO: the centralised critic (the module's docstring), with value
            normalisation unless ``args.value_norm`` is off, the value loss weight and
            gradient clip of ``args`` (``value_loss_scale``, ``grad_norm_clip``).

    Returns:
        ``(networks, normaliser, facts)``: facts hold ``agent_steps``, ``updates``,
        ``wall_s``, ``episodes`` and the time split (``env_s``, ``rollout_s``,
        ``learner_s``; the hooks' time is in none of them, nor a resumed run's earlier
        time).
    """
    import torch

    from uasep_env.envs.core import EnvCore
    from uasep_env.interface.observation import state_dim
    from uasep_env.scenarios import check_training_seeds
    from uasep_env.training.args import formation_sizes, sizes_problem

    hooks = hooks or Hooks()
    # --formation-sizes: a core a size, its rollouts in turn; the first is the config's own.
    problem = sizes_problem(args)  # the recipes' own check, for callers that skip parsing
    if problem:
        raise ValueError(problem)
    sizes = formation_sizes(args)
    configs = [config] + [config.replace(n_uavs=n) for n in sizes if n != config.n_uavs]
    check_training_seeds(args.seed, args.n_envs * len(configs))
    torch.manual_seed(args.seed)
    core = EnvCore(config, n_envs=args.n_envs)
    rows = args.n_envs * config.n_uavs
    critic_dim = state_dim(config) + core.obs_dim if central else None
    layout = tied = None
    if getattr(args, "arch", "mlp") == "set":
        from uasep_env.policies.checkpoint import StoredLayout
        from uasep_env.policies.set_network import split_layout

        layout = StoredLayout.from_config(config)
        tied = split_layout(layout)
    nets = _ActorCritic(core.obs_dim, args, critic_dim, layout)
    # The rollout acts on the CPU (a few hundred rows a step: a GPU's launches and copies
    # would cost more than they save); the update runs on args.device, on its own copy.
    learner = _learner(nets, torch.device(args.device))
    opt = torch.optim.Adam(learner.params, lr=args.learning_rate, eps=1e-5)
    norm = Normaliser(
        core.obs_dim, rows, norm_obs=args.norm_obs, norm_reward=args.norm_reward,
        gamma=args.gamma, tied=tied,
    )  # fmt: skip
    state = State(nets=nets, learner=learner, opt=opt, norm=norm)
    if central:
        state.critic_norm = Normaliser(
            critic_dim, rows, norm_obs=True, norm_reward=False, gamma=args.gamma
        )
        if getattr(args, "value_norm", True):
            state.value_scale = ValueScale()
    if prepare is not None:
        prepare(state)
        if learner is not nets:
            nets.load_from(learner)
    cores = [core] + [EnvCore(c, n_envs=args.n_envs) for c in configs[1:]]
    rolls = [_Rollout(c, state, args.n_steps, hooks, _padding(c.config, config)) for c in cores]
    if state.agent_steps < args.total_timesteps and state.wall_s < args.max_minutes * 60.0:
        # Not when nothing is left to train: the reset's observations would move the
        # normalisation a resumed run exports unchanged. Each size's environments get
        # their own seeds (the first's those of a run of one size).
        for k, roll in enumerate(rolls):
            roll.reset(args.seed + k * args.n_envs)
    timing = _Timing()
    hooks.start(nets, norm)
    t0 = time.perf_counter()
    spent = state.wall_s
    hook_s = 0.0

    def clock() -> float:
        return spent + time.perf_counter() - t0 - hook_s

    while state.agent_steps < args.total_timesteps and clock() < args.max_minutes * 60.0:
        h0 = time.perf_counter()
        stop = hooks.stop()
        hook_s += time.perf_counter() - h0
        if stop:
            break
        r0 = time.perf_counter()
        # The formation sizes in turn, by update: a resumed run goes on with the next one.
        roll = rolls[state.updates % len(rolls)]
        env_s = roll.collect(args.gamma)
        state.agent_steps += args.n_steps * roll.n_envs * roll.n
        timing.env_s += env_s
        timing.rollout_s += time.perf_counter() - r0 - env_s
        h0 = time.perf_counter()
        hooks.rollout_end(state.agent_steps)
        hook_s += time.perf_counter() - h0
        u0 = time.perf_counter()
        adv, ret = gae(roll.rewards, roll.values, roll.starts, roll.last_value, roll.start,
                       args.gamma, args.gae_lambda)  # fmt: skip
        if state.value_scale is not None:  # MAPPO: the critic learns normalised returns
            ret = state.value_scale.scale(ret)
        _update(learner, opt, args, state.updates, roll.obs_t, roll.act, roll.logp, adv, ret,
                roll.crit_t)  # fmt: skip
        if learner is not nets:
            nets.load_from(learner)
        state.updates += 1
        timing.learner_s += time.perf_counter() - u0
        state.wall_s = clock()
        h0 = time.perf_counter()
        hooks.update_end(state)
        state.finished.clear()  # the hook has had them
        hook_s += time.perf_counter() - h0
    state.wall_s = clock()
    facts = {
        "agent_steps": state.agent_steps,
        "updates": state.updates,
        "wall_s": state.wall_s,
        "episodes": state.episodes,
        "env_s": timing.env_s,
        "rollout_s": timing.rollout_s,
        "learner_s": timing.learner_s,
    }
    return nets, norm, facts


def _padding(small: Any, full: Any) -> Callable[[np.ndarray], np.ndarray] | None:
    """Pads the observations of config ``small`` to those of ``full`` (None: the same width).

    A formation of fewer UAVs than ``k_uavs + 1`` observes fewer UAV slots: its rows get
    the missing slots as zeros, masks 0, which the set network leaves out
    (:func:`~uasep_env.policies.set_network.slot_padding`).
    """
    if small is full:
        return None
    from uasep_env.policies.checkpoint import StoredLayout
    from uasep_env.policies.set_network import slot_padding, split_layout

    mine, theirs = (split_layout(StoredLayout.from_config(c)) for c in (small, full))
    if mine.dim == theirs.dim:
        return None
    src = slot_padding(mine, theirs)
    keep = src >= 0
    cols = src[keep]

    def pad(obs: np.ndarray) -> np.ndarray:
        out = np.zeros((len(obs), theirs.dim), dtype=obs.dtype)
        out[:, keep] = obs[:, cols]
        return out

    return pad


def _learner(nets: _ActorCritic, device: Any) -> _ActorCritic:
    """The networks the update trains: ``nets`` themselves on the CPU, else a copy there."""
    return nets if device.type == "cpu" else nets.copy_to(device)
