"""Train MAPPO: decentralised actors (one shared MLP), a centralised critic on ``state()``.

The algorithm is skrl's :class:`skrl.multi_agents.torch.mappo.MAPPO` (Yu et al. 2022); this
recipe only supplies the environment, the two networks and the run's bookkeeping, with the
conventions of ``uasep-train ppo_shared`` (every flag of it applies where it means something):

    uasep-train mappo                                       # 55 min budget, runs/mappo
    uasep-train mappo --max-minutes 1 --out-dir /tmp/mappo
    uasep-train mappo --resume runs/mappo/checkpoints/latest

(``python train/mappo.py`` in a checkout is the same command.)

* Environment: ``n_envs`` batched environments (:class:`uasep_env.envs.sb3.UAVSharedVecEnv`
  under SB3's ``VecMonitor`` and ``VecNormalize``: the same observation normalisation as the
  PPO recipes), seen by skrl as one multi-agent environment with ``num_envs = n_envs``:
  agent ``uav_i`` observes its own K-nearest observation; its critic reads the
  agent-specific global state: the global true state
  (:func:`uasep_env.interface.observation.global_state`) and the agent's own observation, normalised
  by skrl's ``RunningStandardScaler``.
* Networks: the actor is an MLP (``--hidden``, ``--activation``) giving the Gaussian's mean,
  with a state-independent log-std, **shared by every UAV** (parameter sharing; skrl updates
  it once per agent and iteration, each agent with its own Adam state). The critic is an MLP
  of the same widths on the state. The actor exports to the project's policy checkpoint
  (``policy.zip``: numpy MLP, observation normalisation stored), so ``uasep-eval --policy
  policy.zip`` and ``train/select_checkpoint.py`` run it like the PPO policies.
* Budget and outputs as ``ppo_shared.py``: ``--max-minutes`` (55) or ``--total-timesteps``
  agent-steps; ``progress.csv`` and ``curves.png``; ``checkpoints/step_N/`` (``state.pt``
  loaded weights-only, ``normalization.npz``, ``state.json``, ``policy.zip``) and
  ``checkpoints/latest`` for ``--resume``; ``validation.json``. A checkpoint between two
  rollouts also holds ``env_state.npz`` (:meth:`SkrlView.rollout_state`): a run resumed from
  it continues the episodes in progress and is the uninterrupted run, bit for bit. The run
  folder follows :mod:`uasep_env.training.rundir`: a used ``--out-dir`` is refused unless
  ``--resume`` or ``--overwrite``, files are written atomically, and ``--resume`` rewinds
  ``progress.csv`` to the checkpoint and continues its episode window.

Options of ``ppo_shared.py`` MAPPO does not have (``--critic-warmup``, ``--norm-reward``,
``--tensorboard``) are refused. ``--batch-size`` sets skrl's mini-batches per agent
(``n_envs * n_steps / batch_size``). Requires the ``train`` extra and skrl.

``--trainer lean`` trains the same algorithm (the same actor, the same critic on the same
agent-specific global state, value normalisation, the time limit as an end) in the lean
loop of :mod:`uasep_env.training.ppo_lean` on the batched core, without skrl or SB3's
wrappers (more agent-steps a minute at the same flags, ``docs/speed.md``). There the shared
actor is updated once per minibatch on every agent's steps (Yu et al.'s parameter
sharing; skrl updates it once per agent in turn), ``--batch-size`` counts agent-steps as
in the PPO recipes, ``--device`` runs the update, and its checkpoints resume with
``--trainer lean`` only.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from uasep_env.training import ppo_shared
from uasep_env.training.args import budget_notice, rounded_budget, shield_problem, sizes_problem
from uasep_env.training.args import parse_args as _parse_args

if TYPE_CHECKING:
    from uasep_env.training.rundir import RunFolder

__all__ = ["Args", "Hooks", "SkrlView", "build", "continue_episodes", "export_policy",
           "load_checkpoint", "main", "parse_args", "ppo_shared", "run", "save_checkpoint",
           "train"]  # fmt: skip


@dataclass
class Args(ppo_shared.Args):
    """``ppo_shared.Args`` with MAPPO's own options and defaults."""

    out_dir: str = "runs/mappo"
    value_loss_scale: float = 1.0
    grad_norm_clip: float = 0.5
    value_norm: bool = True  # skrl's value preprocessor (Yu et al.'s value normalisation)


def _hidden(args: Args) -> list[int]:
    return ppo_shared._hidden(args)


def _check(args: Args) -> str | None:
    """What MAPPO refuses of the shared flags (one message naming the flag), or None."""
    refused = [("critic_warmup", 0), ("norm_reward", False), ("tensorboard", False)]
    if args.trainer != "lean":  # the lean loop runs its update on --device
        refused.append(("device", "cpu"))
    for name, default in refused:
        if getattr(args, name) != default:
            return f"argument --{name.replace('_', '-')}: not supported by the MAPPO recipe"
    # skrl's mini-batches per agent; the lean loop's --batch-size is agent-steps, as PPO's.
    if args.trainer != "lean" and (args.n_envs * args.n_steps) % args.batch_size:
        return (
            f"argument --batch-size: {args.batch_size} must divide n_envs * n_steps = "
            f"{args.n_envs * args.n_steps}"
        )
    # The centralised critic's global state has one formation's width.
    problem = sizes_problem(args, "the MAPPO recipes")
    return ppo_shared.arch_problem(args) or shield_problem(args) or problem


def parse_args(argv: list[str] | None = None, defaults: Args | None = None) -> Args:
    """MAPPO's :class:`Args` from the command line, or exit with one line naming the flag."""
    return _parse_args(
        argv, defaults or Args(), prog=ppo_shared._prog(), description=__doc__, check=_check
    )


def build(args: Args, config: Any, agent_class: type | None = None) -> tuple[Any, Any, Any]:
    """The normalised SB3 vector env, its skrl multi-agent view, and the MAPPO agent.

    Args:
        args: The options.
        config: The environment config.
        agent_class: skrl's ``MAPPO`` (None) or a subclass; the names in its
            ``extra_critics`` attribute (MAPPO-Lagrangian's ``"cost_value"``) get one more
            critic each, of the value critic's shape, shared by the agents.
    """
    import gymnasium
    import torch
    from skrl.memories.torch import RandomMemory
    from skrl.models.torch import DeterministicMixin, GaussianMixin, Model
    from skrl.multi_agents.torch.base import ExperimentCfg
    from skrl.multi_agents.torch.mappo import MAPPO
    from skrl.resources.preprocessors.torch import RunningStandardScaler
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.scenarios import check_training_seeds

    check_training_seeds(args.seed, args.n_envs)
    torch.manual_seed(args.seed)
    base = UAVSharedVecEnv(n_envs=args.n_envs, config=config, seed=args.seed)
    venv = VecNormalize(
        VecMonitor(base), norm_obs=args.norm_obs, norm_reward=False, gamma=args.gamma
    )
    env = SkrlView(venv, base)
    act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[args.activation]

    def mlp(n_in: int, n_out: int) -> torch.nn.Sequential:
        layers: list[torch.nn.Module] = []
        for width in _hidden(args):
            layers += [torch.nn.Linear(n_in, width), act()]
            n_in = width
        return torch.nn.Sequential(*layers, torch.nn.Linear(n_in, n_out))

    class Actor(GaussianMixin, Model):
        def __init__(self, obs_space: Any, act_space: Any) -> None:
            Model.__init__(self, observation_space=obs_space, action_space=act_space, device="cpu")
            # Unclipped samples: skrl would take the log-probability of the clipped action
            # (a biased gradient); the environment clips to its box itself, as for SB3's PPO.
            GaussianMixin.__init__(self, clip_actions=False, role="policy")
            self.net = mlp(self.num_observations, self.num_actions)
            self.log_std = torch.nn.Parameter(torch.full((self.num_actions,), args.log_std_init))

        def compute(self, inputs: dict, role: str = "") -> tuple:
            return self.net(inputs["observations"]), {"log_std": self.log_std}

    class Critic(DeterministicMixin, Model):
        def __init__(self, state_space: Any) -> None:
            Model.__init__(self, state_space=state_space, device="cpu")
            DeterministicMixin.__init__(self, role="value")
            self.net = mlp(self.num_states, 1)

        def compute(self, inputs: dict, role: str = "") -> tuple:
            return self.net(inputs["states"]), {}

    uid0 = env.possible_agents[0]
    actor = Actor(env.observation_spaces[uid0], env.action_spaces[uid0])
    critic = Critic(env.state_spaces[uid0])
    models = {uid: {"policy": actor, "value": critic} for uid in env.possible_agents}
    for k, role in enumerate(getattr(agent_class, "extra_critics", ())):
        # From a stream of its own: the actor, the critic and every later sample stay plain
        # MAPPO's for the same seed.
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(args.seed + 7919 * (k + 1))
            extra = Critic(env.state_spaces[uid0])
        for uid in env.possible_agents:
            models[uid][role] = extra
    memories = {
        uid: RandomMemory(memory_size=args.n_steps, num_envs=args.n_envs, device="cpu")
        for uid in env.possible_agents
    }
    cfg = {
        "rollouts": args.n_steps,
        "learning_epochs": args.n_epochs,
        "mini_batches": args.n_envs * args.n_steps // args.batch_size,
        "discount_factor": args.gamma,
        "gae_lambda": args.gae_lambda,
        "learning_rate": args.learning_rate,
        "ratio_clip": args.clip_range,
        # No value clipping, as the PPO recipes (SB3's clip_range_vf=None): skrl's clipped
        # value loss gives no gradient to a prediction that moved more than the clip.
        "value_clip": 0.0,
        "entropy_loss_scale": args.ent_coef,
        "value_loss_scale": args.value_loss_scale,
        "grad_norm_clip": args.grad_norm_clip,
        "kl_threshold": args.target_kl,
        "state_preprocessor": RunningStandardScaler,
        # Per-agent dicts: skrl 2.1 reads any dict here as one entry per agent (even its own
        # empty defaults, which it then refuses), so every kwargs field is given per agent.
        "learning_rate_scheduler_kwargs": {uid: {} for uid in env.possible_agents},
        "observation_preprocessor_kwargs": {uid: {} for uid in env.possible_agents},
        "state_preprocessor_kwargs": {
            uid: {"size": env.state_spaces[uid], "device": "cpu"} for uid in env.possible_agents
        },
        "value_preprocessor": RunningStandardScaler if args.value_norm else None,
        "value_preprocessor_kwargs": {
            uid: {"size": 1, "device": "cpu"} for uid in env.possible_agents
        },
        # No TensorBoard files or skrl checkpoints: this script keeps its own.
        "experiment": ExperimentCfg(
            directory=args.out_dir, write_interval=0, checkpoint_interval=0
        ),
    }
    agent = (agent_class or MAPPO)(
        possible_agents=env.possible_agents,
        models=models,
        memories=memories,
        observation_spaces=env.observation_spaces,
        state_spaces=env.state_spaces,
        action_spaces=env.action_spaces,
        device="cpu",
        cfg=cfg,
    )
    agent.init()
    # skrl's own trainers switch training on; this loop is ours, so it must: without it skrl
    # stores no transition and never updates (the agent starts in evaluation mode).
    agent.enable_training_mode(True)
    assert isinstance(env.state_spaces[uid0], gymnasium.spaces.Box)
    return venv, env, agent


class SkrlView:
    """``n_envs`` batched environments as skrl sees a vectorised multi-agent environment.

    Steps the normalised SB3 vector env (whose agents are ``(env, uav)`` pairs, auto-reset)
    and regroups its arrays per agent, as torch tensors ``(n_envs, ...)``.
    """

    def __init__(self, venv: Any, base: Any) -> None:
        import gymnasium

        self.venv, self.base = venv, base
        self.num_envs, self.n = base.n_envs, base.n_uavs
        self.possible_agents = [f"uav_{i}" for i in range(self.n)]
        self.agents = list(self.possible_agents)
        self.num_agents = self.max_num_agents = self.n
        self.observation_spaces = {a: venv.observation_space for a in self.possible_agents}
        self.action_spaces = {a: venv.action_space for a in self.possible_agents}
        clip = base.config.observation.clip
        # The agent-specific global state of MAPPO (Yu et al. 2022): the global state and the
        # agent's own (normalised) observation, so the shared critic knows whose return it
        # predicts. (A one-hot agent id would not do: each agent's state normaliser would
        # centre its constant column to zero.)
        width = base.core.state().shape[-1] + int(np.prod(venv.observation_space.shape))
        space = gymnasium.spaces.Box(-np.inf, np.inf, (width,), np.float32)
        self.clip = clip
        self.state_spaces = {a: space for a in self.possible_agents}
        self.infos: list[dict] = []
        self.dones = np.zeros(self.num_envs * self.n, dtype=bool)
        self._obs: dict = {}
        self.continued = False  # the episodes go on from a checkpoint's (continue_episodes)

    def _split(self, flat: np.ndarray) -> dict:
        import torch

        per = np.asarray(flat, dtype=np.float32).reshape(self.num_envs, self.n, -1)
        return {a: torch.from_numpy(per[:, i].copy()) for i, a in enumerate(self.possible_agents)}

    def reset(self) -> tuple[dict, dict]:
        """Reset every environment; per-agent observations."""
        self._obs = self._split(self.venv.reset())
        return self._obs, {}

    def state(self) -> dict:
        """Every agent's critic input: its environment's global state and its observation."""
        import torch

        s = torch.from_numpy(np.asarray(self.base.core.state(), dtype=np.float32))
        return {a: torch.cat([s, self._obs[a]], dim=-1) for a in self.possible_agents}

    def rollout_state(self, timestep: int) -> dict[str, np.ndarray]:
        """Where the environments and this view stand between two rollouts, as arrays.

        The environment stack's state (:func:`uasep_env.training.sb3_state.venv_state`: the
        episodes in progress, ``VecMonitor``'s and ``VecNormalize``'s running figures,
        numpy's random state), the agents' last observations (``skrl.obs``: what the next
        rollout starts from, instead of a reset) and the loop's ``timestep``.
        """
        from uasep_env.training.sb3_state import venv_state

        obs = np.stack([self._obs[a].numpy() for a in self.possible_agents], axis=1)
        return venv_state(
            self.venv, {"skrl.obs": obs, "skrl.timestep": np.array(timestep, dtype=np.int64)}
        )

    def load_rollout_state(self, state: dict[str, np.ndarray]) -> int:
        """Continue from a :meth:`rollout_state` (checked before anything is written).

        Returns:
            The loop's timestep.

        Raises:
            ValueError: One line naming the array.
        """
        import torch

        from uasep_env.training.sb3_state import load_venv_state

        width = int(np.prod(self.venv.observation_space.shape))
        like = {
            "skrl.obs": np.zeros((self.num_envs, self.n, width), np.float32),
            "skrl.timestep": np.zeros((), dtype=np.int64),
        }
        own = load_venv_state(self.venv, state, like, counters=("skrl.timestep",))
        obs = own["skrl.obs"]
        self._obs = {a: torch.from_numpy(obs[:, i].copy()) for i, a in enumerate(self.agents)}
        return int(own["skrl.timestep"])

    def step(self, actions: dict) -> tuple:
        """Step with per-agent actions ``(n_envs, 3)``; finished environments auto-reset."""
        import torch

        stacked = np.stack([actions[a].numpy() for a in self.possible_agents], axis=1)
        obs, rew, dones, infos = self.venv.step(stacked.reshape(-1, 3))
        self.infos, self.dones = infos, dones
        done = dones.reshape(self.num_envs, self.n)[:, :1]
        # The time limit counts as an end: the global state holds the episode's progress, so
        # a state at the limit is terminal, and skrl's GAE (time_limit_bootstrap off) would
        # otherwise run on into the next episode, which the auto-reset has already begun.
        term = torch.from_numpy(done.copy())
        trunc = torch.zeros_like(term)
        r = rew.reshape(self.num_envs, self.n)
        rewards = {
            a: torch.from_numpy(r[:, i : i + 1].copy()) for i, a in enumerate(self.possible_agents)
        }
        self._obs = self._split(obs)
        return (
            self._obs,
            rewards,
            {a: term for a in self.possible_agents},
            {a: trunc for a in self.possible_agents},
            {},
        )


def export_policy(agent: Any, venv: Any, config: Any, args: Args, path: Path, info: dict) -> Path:
    """Write the shared actor and the observation normalisation as a policy checkpoint."""
    import torch

    actor = agent.policies[agent.possible_agents[0]]
    linears = [m for m in actor.net if isinstance(m, torch.nn.Linear)]
    info = {**info, "implementation": "skrl MAPPO"}
    return ppo_shared.export_actor(linears, venv, config, args, path, "MAPPO", info)


def _modules(agent: Any) -> dict:
    return {
        uid: {k: v.state_dict() for k, v in mods.items() if v is not None}
        for uid, mods in agent.checkpoint_modules.items()
    }


def save_checkpoint(
    agent: Any,
    venv: Any,
    config: Any,
    args: Args,
    directory: Path,
    info: dict,
    env_state: dict[str, np.ndarray] | None = None,
) -> None:
    """Everything ``--resume`` needs, plus the policy checkpoint, in ``directory``.

    Complete or not at all (:func:`uasep_env.training.rundir.save_checkpoint_dir`).
    ``env_state``: the environments' and the loop's state between two rollouts
    (:meth:`SkrlView.rollout_state`), written as ``env_state.npz``; None (a checkpoint
    inside a rollout, whose transitions so far skrl's memory holds) writes none.
    """
    import torch

    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.training.rundir import save_checkpoint_dir

    def write(tmp: Path) -> None:
        buf = io.BytesIO()
        torch.save({"agent": _modules(agent), "torch_rng": torch.get_rng_state()}, buf)
        atomic_write(tmp / "state.pt", buf.getvalue())
        o = venv.obs_rms
        buf = io.BytesIO()
        np.savez(buf, obs_mean=o.mean, obs_var=o.var, obs_count=o.count)
        atomic_write(tmp / "normalization.npz", buf.getvalue())
        if env_state is not None:
            from uasep_env.training.sb3_state import ENV_STATE_FILE, npz_bytes

            atomic_write(tmp / ENV_STATE_FILE, npz_bytes(env_state))
        export_policy(agent, venv, config, args, tmp / "policy.zip", info)

    save_checkpoint_dir(directory, write, info, args)


def load_checkpoint(agent: Any, venv: Any, directory: Path) -> dict:
    """Restore a :func:`save_checkpoint` directory (weights-only loads; no unpickling)."""
    import torch

    from uasep_env.training.rundir import (
        check_checkpoint,
        load_normalization,
        read_state,
        read_tensors,
        restore_json,
        restore_module,
        restore_optimizer,
        restore_rng,
        tensor_part,
    )

    directory = check_checkpoint(directory)
    state = read_tensors(directory)  # every tensor checked as it is restored
    for uid, mods in agent.checkpoint_modules.items():
        for k, v in mods.items():
            if v is None:
                continue
            saved, where = tensor_part(directory, state, "agent", uid, k), f"agent.{uid}.{k}"
            if isinstance(v, torch.nn.Module):
                restore_module(directory, where, v, saved)
            elif isinstance(v, torch.optim.Optimizer):
                restore_optimizer(directory, where, v, saved)
            else:  # a plain state (the cost sampler's seed): its own checks, one line
                restore_json(directory, where, v.load_state_dict, saved, "state.pt")
    restore_rng(directory, "torch_rng", tensor_part(directory, state, "torch_rng"))
    load_normalization(venv, directory / "normalization.npz")  # the observations' only
    return read_state(directory)


def continue_episodes(env: SkrlView, args: Args, directory: Path, resumed: dict) -> int | None:
    """Continue the environments' episodes from a checkpoint's ``env_state.npz``, if it can.

    It can where the checkpoint has one (saved between two rollouts) and the run has the
    checkpoint's environment options
    (:func:`~uasep_env.training.sb3_state.continues_episodes`); otherwise (a checkpoint
    inside a rollout, or of an older version; another ``--n-envs``...) the environments
    restart their episodes from their seeds, said in a line. Sets ``env.continued``.

    Returns:
        The loop's timestep to continue from, or None (reset the environments).

    Raises:
        RunFolderError: ``env_state.npz`` refused (one line naming the array).
    """
    from uasep_env.training.rundir import (
        ENV_STATE_FILE,
        check_checkpoint,
        read_env_state,
        restore_arrays,
    )
    from uasep_env.training.sb3_state import continues_episodes

    directory = check_checkpoint(directory)
    episodes = continues_episodes(args, resumed, directory)
    state = read_env_state(directory) if episodes else None
    env.continued = state is not None
    if state is None:
        why = (f"{directory.name} has no {ENV_STATE_FILE} (saved inside a rollout, or by an "
               "older version)" if episodes
               else "the environment's options are not the checkpoint's")  # fmt: skip
        print(f"{why}: the environments restart their episodes from their seeds (a valid "
              "continuation, not bit-identical with an uninterrupted run)")  # fmt: skip
        return None
    timestep: list[int] = []
    restore_arrays(
        directory, ENV_STATE_FILE, lambda s: timestep.append(env.load_rollout_state(s)), state
    )
    return timestep[0]


class Hooks:
    """What a variant of the recipe adds to :func:`train`'s loop; here, nothing.

    MAPPO-Lagrangian (:mod:`uasep_env.training.mappo_lagrangian`) reads the costs, moves its
    multiplier once per rollout and keeps both in the checkpoints through these.

    Attributes:
        agent_class: The skrl agent :func:`build` makes (None: skrl's ``MAPPO``).
    """

    agent_class: type | None = None

    def start(self, agent: Any, env: SkrlView, out: Path, resumed: dict) -> None:
        """Before the first step; ``resumed`` is the checkpoint's ``state.json`` (or ``{}``)."""

    def step(self, env: SkrlView) -> dict:
        """After each environment step: more ``infos`` for skrl's ``record_transition``."""
        return {}

    def rollout_end(self, agent_steps: int) -> None:
        """At the last step of each rollout, before skrl's update (``agent_steps`` after it)."""

    def info(self) -> dict:
        """Facts added to the run's summary (``state.json``, ``validation.json``)."""
        return {}

    def state(self) -> dict:
        """What a checkpoint's ``state.json`` holds beyond :meth:`info` (replacing its keys)."""
        return {}

    def close(self) -> None:
        """After the last checkpoint."""

    def stop(self) -> bool:
        """Whether training ends before the next rollout (the step and wall budgets aside).

        ``benchmarks/time_to_policy.py`` stops a run at its bar through it.
        """
        return False


def train(
    args: Args, config: Any, out: Path | RunFolder, hooks: Hooks | None = None
) -> tuple[Any, Any, dict]:
    """The training loop (skrl's trainer loop, with the recipes' bookkeeping and ``hooks``).

    ``out``: the run's :class:`~uasep_env.training.rundir.RunFolder`, or the folder of a run
    claimed by the caller (its ``--resume`` checkpoint checked here).
    """
    import torch

    from uasep_env.training.rundir import RunFolder

    run = out if isinstance(out, RunFolder) else RunFolder.attach(args, out=out)
    hooks = hooks or Hooks()
    venv, env, agent = build(args, config, hooks.agent_class)
    resumed = run.resumed
    timestep = None
    if run.resume is not None:
        load_checkpoint(agent, venv, run.resume)
        timestep = continue_episodes(env, args, run.resume, resumed)
    hooks.start(agent, env, run.out, resumed)  # checked before the folder is rewound
    if run.resume is not None:
        run.rewind(int(resumed["agent_steps"]))
    notice = budget_notice(args, config.n_uavs, int(resumed.get("agent_steps", 0)))
    if notice:
        print(notice)
    steps, wall_offset = int(resumed.get("agent_steps", 0)), float(resumed.get("wall_s", 0.0))
    per_step = args.n_envs * env.n
    t0 = time.perf_counter() - wall_offset
    window = run.episode_window()
    episodes = int(resumed.get("episodes", 0))
    log = run.progress_log()
    next_ckpt = run.next_checkpoint(steps)
    bar = None
    if args.progress:
        from tqdm import tqdm

        bar = tqdm(
            total=rounded_budget(args, config.n_uavs, steps),  # where the run ends
            initial=steps,
            unit="step",
            unit_scale=True,
            desc="mappo",
            dynamic_ncols=True,
        )

    def summary() -> dict:
        if not window:
            return {}
        w = np.array(window, dtype=float)
        names = (
            "return_mean",
            "collision_rate",
            "loss_of_separation_rate",
            "max_deviation_mean",
            "episode_length_mean",
        )
        return {k: float(np.mean(w[:, i])) for i, k in enumerate(names)}

    def facts() -> dict:
        return {
            "agent_steps": steps,
            "wall_s": time.perf_counter() - t0,
            "episodes": episodes,
            **summary(),
            **hooks.info(),
        }

    def checkpoint(between_rollouts: bool) -> None:
        # Between two rollouts (after the last one's update, skrl's memory spent) the
        # environments' state is all a resumed run needs to go on exactly.
        env_state = env.rollout_state(t) if between_rollouts else None
        run.save_checkpoint(
            steps, {**facts(), **hooks.state()}, window,
            lambda d, state: save_checkpoint(agent, venv, config, args, d, state, env_state),
        )  # fmt: skip

    if timestep is None:
        obs, _ = env.reset()
        t = 0
    else:  # the episodes go on from the checkpoint's (no reset)
        obs, t = env._obs, timestep
    states = env.state()
    horizon = max(1, args.total_timesteps // per_step)
    while (
        steps < args.total_timesteps
        and time.perf_counter() - t0 < args.max_minutes * 60
        and not hooks.stop()
    ):
        for i in range(args.n_steps):  # one rollout, then skrl's update
            agent.pre_interaction(timestep=t, timesteps=horizon)
            with torch.no_grad():
                actions, _ = agent.act(obs, states, timestep=t, timesteps=horizon)
                next_obs, rewards, term, trunc, infos = env.step(actions)
                next_states = env.state()
                infos = {**infos, **hooks.step(env)}
                agent.record_transition(
                    observations=obs,
                    states=states,
                    actions=actions,
                    rewards=rewards,
                    next_observations=next_obs,
                    next_states=next_states,
                    terminated=term,
                    truncated=trunc,
                    infos=infos,
                    timestep=t,
                    timesteps=horizon,
                )
            if i == args.n_steps - 1:
                hooks.rollout_end(steps + per_step)
            agent.post_interaction(timestep=t, timesteps=horizon)
            obs, states, t, steps = next_obs, next_states, t + 1, steps + per_step
            for k, info in enumerate(env.infos):
                if k % env.n == 0 and "episode_safety" in info:
                    s, ep = info["episode_safety"], info.get("episode", {"r": np.nan, "l": np.nan})
                    window.append(
                        (
                            ep["r"],
                            s["collision"],
                            s["loss_of_separation"],
                            s["max_deviation"],
                            ep["l"],
                        )
                    )
                    episodes += 1
            if i == args.n_steps - 1:  # the rollout's row: before a checkpoint at its end
                s = summary()
                row = {"agent_steps": steps, "wall_s": round(time.perf_counter() - t0, 2)}
                log.write({**row, "episodes": episodes, **s})
                if bar is not None:
                    bar.update(steps - bar.n)
                    if s:
                        bar.set_postfix(**ppo_shared.bar_postfix(s))
            # Checkpoints fall at a rollout's end (the first at or past each multiple of
            # --checkpoint-every): there a resumed run goes on exactly, as the SB3 recipes'.
            if i == args.n_steps - 1 and steps >= next_ckpt:
                checkpoint(True)
                while next_ckpt <= steps:
                    next_ckpt += args.checkpoint_every
    checkpoint(True)
    run.close()
    hooks.close()
    if bar is not None:
        bar.close()
    return agent, venv, facts()


def main(argv: list[str] | None = None, defaults: Args | None = None) -> dict:
    """Train (or resume), export the actor, validate against the APF; returns the summary."""
    args = parse_args(argv, defaults)
    if args.trainer == "lean":
        from uasep_env.training import lean_recipe

        return lean_recipe.train(args, central=True)
    import torch  # lazy: the training extra

    from uasep_env.training.rundir import RunFolder, check_switch

    torch.set_num_threads(args.torch_threads)
    config = ppo_shared.make_env_config(args)
    # The lean loop's checkpoints are not skrl's; skrl saves the value preprocessor's
    # statistics under --value-norm only.
    run = RunFolder.start(
        args, lambda ck, info: check_switch(ck, info, args, "value_norm", default=True)
    )
    agent, venv, info = train(args, config, run)
    return run.publish(
        lambda path: export_policy(agent, venv, config, args, path, info),
        config, info, "MAPPO (skrl)",
    )  # fmt: skip


def cli(argv: list[str] | None = None) -> None:
    """Run :func:`main` (:func:`uasep_env.training.ppo_shared.cli`'s error handling)."""
    ppo_shared.cli(None, argv, main)


run = cli  # ``uasep-train mappo``
