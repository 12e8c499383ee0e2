"""Train one PPO policy shared by every UAV (parameter sharing), pure or residual on the APF.

A single-file recipe in the CleanRL style: every option is a field of
:class:`~uasep_env.training.args.Args`.

    uasep-train ppo_shared                                     # pure policy
    uasep-train ppo_shared --action-mode residual_apf          # = uasep-train ppo_residual_apf
    uasep-train ppo_shared --resume runs/ppo_shared/checkpoints/latest

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
counters (agent-steps, episodes, the 200-episode window, wall time) and torch's random
state; it is not bit-exact with an uninterrupted run: the episodes and the rollout in
progress at the checkpoint are dropped, and the environments restart their episodes from
their seeds (see ``docs/robustness.md``).

Seeds: training environments are seeded ``seed + e`` inside
:data:`uasep_env.scenarios.TRAINING_SEEDS`; validation uses
:data:`~uasep_env.scenarios.VALIDATION_SEEDS`; neither meets the held-out bank
(:data:`~uasep_env.scenarios.HELD_OUT_SEEDS`) that ``baselines/learned_vs_apf.py`` uses.
Requires the ``train`` extra (install ``torch==2.13.0`` first).
"""

from __future__ import annotations

import collections
import dataclasses
import io
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.training.args import Args, hidden, make_env_config
from uasep_env.training.args import parse_args as _parse_args

__all__ = [
    "CSV_FIELDS",
    "Args",
    "build",
    "cli",
    "export_actor",
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
    return _parse_args(argv, defaults, prog=_prog(), description=_PROG.get("doc", __doc__))


def _prog() -> str | None:
    """``uasep-train RECIPE`` under the entry point, else the script's name (argparse's)."""
    return _PROG.get("prog")


#: Set by :mod:`uasep_env.training.cli` to name the program in messages.
_PROG: dict[str, str] = {}


def _hidden(args: Args) -> list[int]:
    return hidden(args)


def build(args: Args, config: Any) -> tuple[Any, Any]:
    """The vectorised env (normalised) and a fresh PPO model for ``args``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

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
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=args.n_epochs,
        learning_rate=args.learning_rate,
        gamma=args.gamma,
        gae_lambda=args.gae_lambda,
        clip_range=args.clip_range,
        ent_coef=args.ent_coef,
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


def export_actor(
    linears: list, venv: Any, config: Any, args: Args, path: Path, algorithm: str, info: dict
) -> Path:
    """Write an MLP actor and its observation normalisation as a policy checkpoint.

    Every recipe exports through here: ``linears`` are the actor's ``torch.nn.Linear``
    layers in order, the normalisation is ``venv``'s; the file is pickle-free.
    """
    from uasep_env.policies.learned import PolicyCheckpoint, save_policy

    weights = [(m.weight.detach().cpu().numpy(), m.bias.detach().cpu().numpy()) for m in linears]
    meta = PolicyCheckpoint(
        config=config.to_dict(),
        obs_dim=int(venv.observation_space.shape[0]),
        activation=args.activation,
        hidden=tuple(_hidden(args)),
        obs_norm=bool(venv.norm_obs),
        clip_obs=float(venv.clip_obs),
        obs_epsilon=float(venv.epsilon),
        algorithm=algorithm,
        info={**info, "args": dataclasses.asdict(args)},
    )
    rms = venv.obs_rms
    return save_policy(path, meta, weights, rms.mean, rms.var)


def save_checkpoint(
    model: Any, venv: Any, config: Any, args: Args, directory: Path, info: dict
) -> None:
    """Everything ``--resume`` needs, plus the policy checkpoint, in ``directory``.

    The folder is written under a temporary name and renamed into place when complete
    (:func:`uasep_env.training.rundir.publish_dir`), so ``directory`` is either the old
    checkpoint or the new one; ``state.json`` is written last (a folder without it is
    incomplete).
    """
    from uasep_env.training.rundir import publish_dir

    directory.parent.mkdir(parents=True, exist_ok=True)
    tmp = directory.with_name(f".{directory.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _write_checkpoint(model, venv, config, args, tmp, info)
        publish_dir(tmp, directory)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)  # the previous checkpoint stays as it was
        raise


def _write_checkpoint(
    model: Any, venv: Any, config: Any, args: Args, tmp: Path, info: dict
) -> None:
    import torch

    from uasep_env.atomic import atomic_write
    from uasep_env.jsonio import dumps

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
    o, r = venv.obs_rms, venv.ret_rms
    buf = io.BytesIO()
    np.savez(
        buf,
        obs_mean=o.mean, obs_var=o.var, obs_count=o.count,
        ret_mean=r.mean, ret_var=r.var, ret_count=r.count,
    )  # fmt: skip
    atomic_write(tmp / "normalization.npz", buf.getvalue())
    export_policy(model, venv, config, args, tmp / "policy.zip", info)
    state = dumps({**info, "args": dataclasses.asdict(args)}, indent=2)
    atomic_write(tmp / "state.json", state)


def load_checkpoint(model: Any, venv: Any, directory: Path) -> dict:
    """Restore a :func:`save_checkpoint` directory (weights-only loads; no unpickling)."""
    import torch

    from uasep_env.training.rundir import check_checkpoint

    directory = check_checkpoint(directory)
    state = torch.load(directory / "state.pt", map_location="cpu", weights_only=True)
    model.policy.load_state_dict(state["policy"])
    model.policy.optimizer.load_state_dict(state["optimizer"])
    if "torch_rng" in state:
        torch.set_rng_state(state["torch_rng"])
    if "cuda_rng" in state and model.device.type == "cuda":
        torch.cuda.set_rng_state(state["cuda_rng"], model.device)
    with np.load(directory / "normalization.npz", allow_pickle=False) as z:
        venv.obs_rms.mean, venv.obs_rms.var = z["obs_mean"], z["obs_var"]
        venv.obs_rms.count = float(z["obs_count"])
        venv.ret_rms.mean, venv.ret_rms.var = z["ret_mean"], z["ret_var"]
        venv.ret_rms.count = float(z["ret_count"])
    info = json.loads((directory / "state.json").read_text())
    model.num_timesteps = int(info["agent_steps"])
    return info


CSV_FIELDS = (
    "agent_steps",
    "wall_s",
    "episodes",
    "return_mean",
    "collision_rate",
    "loss_of_separation_rate",
    "max_deviation_mean",
    "episode_length_mean",
)


def make_callback(
    args: Args,
    config: Any,
    venv: Any,
    wall_offset: float,
    total: int,
    resumed: dict | None = None,
    extra: Any = None,
) -> Any:
    """The SB3 callback: progress bar, learning curve rows, checkpoints, wall budget.

    ``resumed``: the ``state.json`` of the checkpoint a run resumes from (its episode count
    and 200-episode window continue). ``extra``: a function returning more facts for
    :meth:`info` and every checkpoint's ``state.json`` (a recipe's own state to resume).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from uasep_env.atomic import atomic_symlink
    from uasep_env.training.rundir import ProgressLog

    resumed = resumed or {}

    out = Path(args.out_dir)
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
            self.window: collections.deque = collections.deque(
                (tuple(e) for e in resumed.get("window", ())), maxlen=200
            )
            self.episodes = int(resumed.get("episodes", 0))
            self.next_ckpt = (
                self.num_timesteps // args.checkpoint_every + 1
            ) * args.checkpoint_every
            self.csv = ProgressLog(out / "progress.csv", CSV_FIELDS)
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
            w = list(self.window)
            if not w:
                return {}
            return {
                "return_mean": float(np.mean([e[0] for e in w])),
                "collision_rate": float(np.mean([e[1] for e in w])),
                "loss_of_separation_rate": float(np.mean([e[2] for e in w])),
                "max_deviation_mean": float(np.mean([e[3] for e in w])),
                "episode_length_mean": float(np.mean([e[4] for e in w])),
            }

        def _on_step(self) -> bool:
            for k, info in enumerate(self.locals["infos"]):
                if k % n_uavs == 0 and "episode_safety" in info:
                    s = info["episode_safety"]
                    ep = info.get("episode", {"r": np.nan, "l": np.nan})
                    row = (ep["r"], s["collision"], s["loss_of_separation"])
                    self.window.append((*row, s["max_deviation"], ep["l"]))
                    self.episodes += 1
            if self.bar is not None:
                self.bar.update(self.num_timesteps - self.bar.n)
            # The last one is saved at the end (after the final update), not twice.
            if self.next_ckpt <= self.num_timesteps < total:
                self.checkpoint()
                self.next_ckpt += args.checkpoint_every
            return self.wall() < args.max_minutes * 60.0

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
                self.bar.set_postfix(
                    ret=f"{s['return_mean']:.0f}",
                    coll=f"{s['collision_rate']:.1%}",
                    los=f"{s['loss_of_separation_rate']:.1%}",
                    dev=f"{s['max_deviation_mean']:.1f}m",
                )
            if args.tensorboard and s:
                for k, v in s.items():
                    self.logger.record(f"uasep/{k}", v)

        def info(self) -> dict:
            more = extra() if extra is not None else {}
            return {"agent_steps": int(self.num_timesteps), "wall_s": self.wall(),
                    "episodes": self.episodes, **self.summary(), **more}  # fmt: skip

        def checkpoint(self) -> None:
            info = self.info()
            d = out / "checkpoints" / f"step_{self.num_timesteps}"
            window = [[float(x) for x in e] for e in self.window]
            save_checkpoint(self.model, venv, config, args, d, {**info, "window": window})
            atomic_symlink(d.name, out / "checkpoints" / "latest")  # once d is complete

        def _on_training_end(self) -> None:
            self.checkpoint()
            self.csv.close()
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
    import torch  # lazy: the training extra
    from stable_baselines3.common.callbacks import CallbackList

    from uasep_env.training.rundir import check_checkpoint, plot_curves, prepare_out_dir, rewind

    torch.set_num_threads(args.torch_threads)
    config = make_env_config(args)
    out = Path(args.out_dir)
    resume = check_checkpoint(Path(args.resume)) if args.resume else None
    prepare_out_dir(out, args.resume, args.overwrite)
    venv, model = build(args, config)
    resumed: dict = {}
    if resume is not None:
        resumed = load_checkpoint(model, venv, resume)
        rewind(out, CSV_FIELDS, model.num_timesteps)
        print(f"resumed from {resume} at {model.num_timesteps:,} agent-steps")
    before = plugin.start(out, config, resumed) if plugin is not None else []
    remaining = max(0, args.total_timesteps - model.num_timesteps)
    if remaining or resume is None:
        callback = make_callback(
            args, config, venv, float(resumed.get("wall_s", 0.0)), args.total_timesteps, resumed,
            extra=plugin.facts if plugin is not None else None,
        )  # fmt: skip
        model.learn(
            total_timesteps=remaining,
            callback=CallbackList([*before, callback]),
            reset_num_timesteps=resume is None,
            tb_log_name=args.action_mode,
        )
        info = callback.info()
    else:  # resumed at the end: only the final outputs are (re)written
        info = {k: v for k, v in resumed.items() if k not in ("window", "args")}
    policy_path = export_policy(model, venv, config, args, out / "policy.zip", info)
    title = plugin.title if plugin is not None else "PPO"
    plot_curves(out / "progress.csv", out / "curves.png", CSV_FIELDS,
                f"{title} ({args.action_mode})")  # fmt: skip
    if plugin is not None:
        plugin.finish(out)
    return write_validation(out, config, policy_path, info, args.eval_episodes)


def write_validation(out: Path, config: Any, policy_path: Path, info: dict, episodes: int) -> dict:
    """The policy and the APF on ``episodes`` validation encounters: ``validation.json``."""
    from uasep_env.atomic import atomic_write
    from uasep_env.evaluation import evaluate
    from uasep_env.jsonio import dumps
    from uasep_env.policies import load_policy
    from uasep_env.scenarios import VALIDATION_SEEDS

    eval_cfg = config.replace(action={"mode": "direct"})
    seeds = list(VALIDATION_SEEDS)[:episodes]
    summary: dict = {"training": info, "policy": str(policy_path), "validation": {}}
    if seeds:
        policies = {"learned": load_policy(policy_path, eval_cfg), "apf": "apf"}
        result = evaluate(policies, eval_cfg, seeds)
        keys = ("collision", "loss_of_separation", "max_deviation")
        for label, res in result.results.items():
            agg = res.aggregate
            summary["validation"][label] = {
                k: agg[f"episode.{k}"].get("mean", agg[f"episode.{k}"].get("rate"))
                for k in keys
                if f"episode.{k}" in agg
            }
    text = dumps(summary, indent=2, default=str)
    atomic_write(out / "validation.json", text + "\n")
    print(text)
    return summary


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
