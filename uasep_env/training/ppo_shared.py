"""Train one PPO policy shared by every UAV (parameter sharing), pure or residual on the APF.

A single-file recipe in the CleanRL style: every option is a field of
:class:`~uasep_env.training.args.Args`.

    uasep-train ppo_shared                                     # pure policy
    uasep-train ppo_shared --action-mode residual_apf          # = uasep-train ppo_residual_apf
    uasep-train ppo_shared --resume runs/ppo_shared/checkpoints/latest
    uasep-train ppo_residual_apf --trainer lean   # the lean PPO loop in place of SB3's

(``python train/ppo_shared.py`` in a checkout is the same command.)

Each UAV of each of ``n_envs`` batched environments is one SB3 sub-environment
(:class:`uasep_env.envs.sb3.UAVSharedVecEnv`), wrapped in SB3's ``VecNormalize``
(observation and return normalisation). Each UAV observes a fixed number of neighbours
(``--k-uavs`` 2, ``--k-obstacles`` 1): the observation's width does not depend on the
formation size or the obstacle count, so the policy flies any of them (``docs/protocol.md``).
The defaults are the ones the sweep in ``train/README.md`` chose. A run writes to ``out_dir``:

* ``progress.csv``: one row per PPO iteration (agent-steps, wall time, and over the last
  200 finished episodes: mean return per agent, collision rate, loss-of-separation rate,
  mean max deviation, mean length); ``curves.png`` drawn from it at the end;
* ``checkpoints/step_<agent-steps>/`` every ``checkpoint_every`` agent-steps, and
  ``checkpoints/latest``: what ``--resume`` needs (torch state dicts, loaded weights-only,
  normalisation statistics, counters) and ``policy.zip``, the policy checkpoint;
* ``policy.zip``: the final policy checkpoint (:mod:`uasep_env.policies.learned`: config,
  action mode, normalisation and weights; loads without unpickling, runs in numpy);
* ``validation.json``: the policy and the APF on ``eval_episodes`` validation encounters.

A fresh run refuses a non-empty ``out_dir`` unless ``--overwrite`` (which deletes only the
files above) or ``--resume`` is given; every file is written atomically, and ``--resume``
rewinds ``progress.csv`` and the checkpoints to the one it resumes from
(:mod:`uasep_env.training.rundir`).
A resumed run restores the weights, the optimiser, the normalisation statistics, the
counters (agent-steps, episodes, the 200-episode window, wall time), torch's and numpy's
random states, the environments' episodes in progress and SB3's rollout state
(``env_state.npz``, :mod:`~uasep_env.training.sb3_state`), all as they were after the
updates of the checkpoint's last rollout (a checkpoint is saved when the next rollout
starts, so no rollout is in progress): it is bit-identical with an uninterrupted run (the
same weights and ``progress.csv`` but its wall times). A checkpoint of an older version,
without ``env_state.npz``, resumes with the environments' episodes restarted from their
seeds.

``--trainer lean`` trains the same recipe with :mod:`~uasep_env.training.ppo_lean` in place
of SB3 (:mod:`~uasep_env.training.lean_recipe`: the same files and ``--resume``).

Seeds: training environments are seeded ``seed + e`` inside
:data:`uasep_env.scenarios.TRAINING_SEEDS`; validation uses
:data:`~uasep_env.scenarios.VALIDATION_SEEDS`; neither meets the held-out bank
(:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`) that ``baselines/learned_vs_apf.py`` uses.
Requires the ``train`` extra (install ``torch==2.13.0`` first).
"""

from __future__ import annotations

import collections
import io
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.training.args import (
    Args,
    budget_notice,
    hidden,
    make_env_config,
    rounded_budget,
    shield_problem,
    sizes_problem,
)
from uasep_env.training.args import parse_args as _parse_args

# What every trainer writes the same way (rundir); mappo and the scripts read it from here too.
from uasep_env.training.rundir import (
    CSV_FIELDS,
    bar_postfix,
    export_actor,
    load_normalization,
    normalization_bytes,
    window_summary,
    write_validation,
)

__all__ = [
    "CSV_FIELDS",
    "Args",
    "build",
    "cli",
    "export_policy",
    "load_checkpoint",
    "main",
    "make_callback",
    "make_env_config",
    "parse_args",
    "run",
    "save_checkpoint",
    "train",
    "write_validation",
]


def parse_args(argv: list[str] | None = None, defaults: Args | None = None) -> Args:
    """Build :class:`Args` from the command line (one ``--kebab-case`` flag per field).

    A bad value exits with one line naming the flag (:mod:`uasep_env.training.args`).
    """
    return _parse_args(
        argv, defaults, prog=_prog(), description=_PROG.get("doc", __doc__), check=_check
    )


def _check(args: Args) -> str | None:
    """What the PPO recipes refuse beyond each flag's range (one message naming the flag)."""
    if args.trainer == "lean" and args.tensorboard:
        return "argument --tensorboard: SB3's logger; not with --trainer lean"
    return arch_problem(args) or shield_problem(args) or sizes_problem(args)


def arch_problem(args: Args) -> str | None:
    """Why ``--arch`` cannot train with these flags (one line naming the flag), or None."""
    if args.arch == "set" and args.trainer != "lean":
        return "argument --arch: 'set' trains with --trainer lean only"
    if args.arch == "set" and args.n_uavs < 2:
        return f"argument --n-uavs: --arch set needs 2 or more UAVs, got {args.n_uavs}"
    return None


def _prog() -> str | None:
    """``uasep-train RECIPE`` under the entry point, else the script's name (argparse's)."""
    return _PROG.get("prog")


#: Set by :mod:`uasep_env.training.cli` to name the program in messages.
_PROG: dict[str, str] = {}


def _say(line: str | None) -> None:
    """Print ``line``, if any (a notice at a run's start)."""
    if line:
        print(line)


def _hidden(args: Args) -> list[int]:
    return hidden(args)


#: The options handed to SB3's ``PPO`` under their own names.
_PPO_OPTIONS = ("n_steps", "batch_size", "n_epochs", "learning_rate", "gamma", "gae_lambda",
                "clip_range", "ent_coef")  # fmt: skip


def build(args: Args, config: Any) -> tuple[Any, Any]:
    """The vectorised env (normalised) and a fresh PPO model for ``args``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from uasep_env.config.options import pick
    from uasep_env.envs.sb3 import UAVSharedVecEnv
    from uasep_env.scenarios import check_training_seeds

    check_training_seeds(args.seed, args.n_envs)
    venv = VecMonitor(UAVSharedVecEnv(n_envs=args.n_envs, config=config, seed=args.seed))
    venv = VecNormalize(
        venv, norm_obs=args.norm_obs, norm_reward=args.norm_reward, gamma=args.gamma
    )
    hidden = _hidden(args)
    act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[args.activation]
    model = PPO(
        "MlpPolicy",
        venv,
        **pick(args, *_PPO_OPTIONS),
        target_kl=args.target_kl or None,
        policy_kwargs={
            "net_arch": {"pi": hidden, "vf": hidden},
            "activation_fn": act,
            "log_std_init": args.log_std_init,
        },
        seed=args.seed,
        device=args.device,
        verbose=0,
        tensorboard_log=str(Path(args.out_dir) / "tb") if args.tensorboard else None,
    )
    return venv, model


def export_policy(model: Any, venv: Any, config: Any, args: Args, path: Path, info: dict) -> Path:
    """Write the actor and the normalisation of ``model`` as a policy checkpoint."""
    import torch

    linears = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
    linears.append(model.policy.action_net)
    return export_actor(linears, venv, config, args, path, "PPO", info)


def save_checkpoint(
    model: Any, venv: Any, config: Any, args: Args, directory: Path, info: dict
) -> None:
    """Everything ``--resume`` needs, plus the policy checkpoint, in ``directory``.

    Complete or not at all (:func:`uasep_env.training.rundir.save_checkpoint_dir`: written
    under a temporary name, ``state.json`` last, renamed into place).
    """
    from uasep_env.training.rundir import save_checkpoint_dir

    save_checkpoint_dir(
        directory, lambda tmp: _write_checkpoint(model, venv, config, args, tmp, info), info, args
    )


def _write_checkpoint(
    model: Any, venv: Any, config: Any, args: Args, tmp: Path, info: dict
) -> None:
    import torch

    from uasep_env.runtime.atomic import atomic_write

    state = {
        "policy": model.policy.state_dict(),
        "optimizer": model.policy.optimizer.state_dict(),
        "torch_rng": torch.get_rng_state(),
    }
    if model.device.type == "cuda":  # SB3 draws the actions' noise there
        state["cuda_rng"] = torch.cuda.get_rng_state(model.device)
    buf = io.BytesIO()
    torch.save(state, buf)
    atomic_write(tmp / "state.pt", buf.getvalue())
    atomic_write(tmp / "normalization.npz", normalization_bytes(venv))
    # The episodes in progress and the rollouts' state: a resumed run continues them exactly.
    from uasep_env.training.sb3_state import ENV_STATE_FILE, env_state_bytes

    atomic_write(tmp / ENV_STATE_FILE, env_state_bytes(model, venv))
    export_policy(model, venv, config, args, tmp / "policy.zip", info)


def load_checkpoint(model: Any, venv: Any, directory: Path, episodes: bool = True) -> dict:
    """Restore a :func:`save_checkpoint` directory (weights-only loads; no unpickling).

    With ``episodes`` and its ``env_state.npz`` (:mod:`~uasep_env.training.sb3_state`) the
    environments' episodes and SB3's rollout state continue where the checkpoint's run was:
    the resumed run is the uninterrupted one, bit for bit. Otherwise (a checkpoint of an
    older version, or ``episodes`` False: :func:`~uasep_env.training.sb3_state.continues_episodes`
    said no) the environments restart their episodes from their seeds (said in a line).
    """
    import torch

    from uasep_env.training.rundir import (
        ENV_STATE_FILE,
        check_checkpoint,
        read_env_state,
        read_state,
        read_tensors,
        restore_arrays,
        restore_module,
        restore_optimizer,
        restore_rng,
        tensor_part,
    )
    from uasep_env.training.sb3_state import load_rollout_state

    directory = check_checkpoint(directory)
    state = read_tensors(directory)  # every tensor checked as it is restored
    restore_module(directory, "policy", model.policy, tensor_part(directory, state, "policy"))
    restore_optimizer(
        directory, "optimizer", model.policy.optimizer, tensor_part(directory, state, "optimizer")
    )
    if "torch_rng" in state:
        restore_rng(directory, "torch_rng", state["torch_rng"])
    if "cuda_rng" in state and model.device.type == "cuda":
        torch.cuda.set_rng_state(state["cuda_rng"], model.device)
    load_normalization(venv, directory / "normalization.npz")
    info = read_state(directory)
    env_state = read_env_state(directory) if episodes else None
    if env_state is None:
        why = (f"{directory.name} has no {ENV_STATE_FILE}" if episodes
               else "the environment's options are not the checkpoint's")  # fmt: skip
        print(f"{why}: the environments restart their episodes from their seeds (a valid "
              "continuation, not bit-identical with an uninterrupted run)")  # fmt: skip
    else:
        restore_arrays(
            directory, ENV_STATE_FILE, lambda s: load_rollout_state(model, venv, s), env_state
        )
    model.num_timesteps = int(info["agent_steps"])
    return info


def make_callback(
    args: Args,
    config: Any,
    venv: Any,
    wall_offset: float,
    total: int,
    resumed: dict | None = None,
    extra: Any = None,
    run: Any = None,
) -> Any:
    """The SB3 callback: progress bar, learning curve rows, checkpoints, wall budget.

    ``resumed``: the ``state.json`` of the checkpoint a run resumes from (its episode count
    and 200-episode window continue). ``extra``: a function returning more facts for
    :meth:`info` and every checkpoint's ``state.json`` (a recipe's own state to resume).
    ``run``: the run's :class:`~uasep_env.training.rundir.RunFolder` (default: ``--out-dir``'s,
    claimed by the caller), which writes the curve's rows and the checkpoints.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from uasep_env.training.rundir import RunFolder

    resumed = resumed or {}
    if run is None:
        run = RunFolder(args, Path(args.out_dir), resumed=resumed)
    n_uavs = config.n_uavs

    class Progress(BaseCallback):
        def _actor_params(self) -> list:
            p = self.model.policy
            return [*p.mlp_extractor.policy_net.parameters(), *p.action_net.parameters(),
                    p.log_std]  # fmt: skip

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter() - wall_offset
            # Critic warm-up: a residual policy starts at the APF, and updates driven by an
            # untrained critic only move it away; freeze the actor for the first iterations.
            self.iterations = self.num_timesteps // (args.n_envs * n_uavs * args.n_steps)
            for q in self._actor_params():
                q.requires_grad_(self.iterations >= args.critic_warmup)
            self.window: collections.deque = run.episode_window()
            self.episodes = int(resumed.get("episodes", 0))
            self.next_ckpt = run.next_checkpoint(self.num_timesteps)
            self.due = False  # a checkpoint to save at the next rollout's start
            self.csv = run.progress_log()
            self.bar = None
            if args.progress:
                from tqdm import tqdm

                self.bar = tqdm(
                    total=total, initial=self.num_timesteps, unit="step", unit_scale=True,
                    desc=args.action_mode, dynamic_ncols=True,
                )  # fmt: skip

        def wall(self) -> float:
            return time.perf_counter() - self.t0

        def summary(self) -> dict:
            return window_summary(self.window)

        def _on_step(self) -> bool:
            for k, info in enumerate(self.locals["infos"]):
                if k % n_uavs == 0 and "episode_safety" in info:
                    s = info["episode_safety"]
                    ep = info.get("episode", {"r": np.nan, "l": np.nan})
                    # A Python float, as a resumed window's (from state.json) holds: the
                    # mean of float32 returns would round otherwise.
                    row = (float(ep["r"]), s["collision"], s["loss_of_separation"])
                    self.window.append((*row, s["max_deviation"], ep["l"]))
                    self.episodes += 1
            if self.bar is not None:
                self.bar.update(self.num_timesteps - self.bar.n)
            # Due now, saved when the next rollout starts: after this rollout's updates (the
            # multiplier's at its end, PPO's weights), the state its kept CSV rows record.
            # The last one is saved at the end (after the final update), not twice.
            if self.next_ckpt <= self.num_timesteps < total:
                self.due = True
                self.next_ckpt = run.next_checkpoint(self.num_timesteps)
            return self.wall() < args.max_minutes * 60.0

        def _on_rollout_start(self) -> None:
            if self.due:
                self.checkpoint()
                self.due = False

        def _on_rollout_end(self) -> None:
            self.iterations += 1
            if self.iterations == args.critic_warmup:
                for q in self._actor_params():
                    q.requires_grad_(True)
            s = self.summary()
            row = {"agent_steps": self.num_timesteps, "wall_s": round(self.wall(), 2),
                   "episodes": self.episodes, **s}  # fmt: skip
            self.csv.write(row)
            if self.bar is not None and s:
                self.bar.set_postfix(**bar_postfix(s))
            if args.tensorboard and s:
                for k, v in s.items():
                    self.logger.record(f"uasep/{k}", v)

        def info(self) -> dict:
            more = extra() if extra is not None else {}
            return {"agent_steps": int(self.num_timesteps), "wall_s": self.wall(),
                    "episodes": self.episodes, **self.summary(), **more}  # fmt: skip

        def checkpoint(self) -> None:
            run.save_checkpoint(
                self.num_timesteps, self.info(), self.window,
                lambda d, state: save_checkpoint(self.model, venv, config, args, d, state),
            )  # fmt: skip

        def _on_training_end(self) -> None:
            self.checkpoint()
            run.close()
            if self.bar is not None:
                self.bar.close()

    return Progress()


def main(argv: list[str] | None = None, defaults: Args | None = None) -> dict:
    """Train (or resume), export the policy, validate against the APF; returns the summary."""
    return train(parse_args(argv, defaults))


def train(args: Args, plugin: Any = None) -> dict:
    """Train (or resume) with ``args``, export the policy, validate; returns the summary.

    Args:
        args: The recipe's options.
        plugin: A recipe's addition to the loop (the Lagrangian recipe's constraint), or
            None. It has ``start(out, config, resumed) -> list`` (SB3 callbacks run before
            the progress callback; ``resumed`` is the resumed checkpoint's ``state.json``,
            ``{}`` for a fresh run), ``facts() -> dict`` (saved in every checkpoint and in
            ``validation.json``), ``finish(out)`` and ``title``.
    """
    if args.trainer == "lean":
        from uasep_env.training import lean_recipe

        return lean_recipe.train(args, plugin)
    import torch
    from stable_baselines3.common.callbacks import CallbackList  # lazy: the training extra

    from uasep_env.training.rundir import RunFolder

    torch.set_num_threads(args.torch_threads)
    config = make_env_config(args)
    run = RunFolder.start(args)
    venv, model = build(args, config)
    if run.resume is not None:
        from uasep_env.training.sb3_state import continues_episodes

        episodes = continues_episodes(args, run.resumed, run.resume)
        load_checkpoint(model, venv, run.resume, episodes)
    # The plugin's state restored (and checked) before the folder is rewound: a refused
    # checkpoint leaves the folder as it was.
    before = plugin.start(run.out, config, run.resumed) if plugin is not None else []
    if run.resume is not None:
        run.rewind(model.num_timesteps)
    _say(budget_notice(args, config.n_uavs, model.num_timesteps))
    remaining = max(0, args.total_timesteps - model.num_timesteps)
    if remaining or run.resume is None:
        callback = make_callback(
            args, config, venv, float(run.resumed.get("wall_s", 0.0)),
            rounded_budget(args, config.n_uavs, model.num_timesteps),  # where the run ends
            run.resumed, extra=plugin.facts if plugin is not None else None, run=run,
        )  # fmt: skip
        model.learn(
            total_timesteps=remaining,
            callback=CallbackList([*before, callback]),
            reset_num_timesteps=run.resume is None,
            tb_log_name=args.action_mode,
        )
        info = callback.info()
    else:  # resumed at the end: only the final outputs are (re)written
        info = run.resumed_info()
    title = plugin.title if plugin is not None else "PPO"
    return run.publish(
        lambda path: export_policy(model, venv, config, args, path, info),
        config, info, f"{title} ({args.action_mode})",
        more=plugin.finish if plugin is not None else None,
    )  # fmt: skip


def cli(defaults: Args | None = None, argv: list[str] | None = None, entry: Any = None) -> None:
    """Run a recipe's ``main`` (this one's by default) with ``argv`` and ``defaults``.

    Every recipe's command line ends here: a file that cannot be written (a full disk) is
    one line naming it, status 1.
    """
    try:
        (entry or main)(argv, defaults)
    except OSError as err:
        sys.exit(f"{_prog() or Path(sys.argv[0]).name}: error: {err}")


if __name__ == "__main__":
    cli()


def run(argv: list[str] | None = None) -> None:
    """``uasep-train ppo_shared``: :func:`cli` with this recipe's defaults."""
    cli(argv=argv)
