"""A recipe trained by the lean loop: ``uasep-train ppo_residual_apf --trainer lean``.

:mod:`~uasep_env.training.ppo_lean` is the SB3 recipes' algorithm in one loop on the batched
core (1.3x SB3's agent-steps a minute on the residual recipe, ``docs/speed.md``). This
module gives it what a recipe's run has under SB3 (:func:`uasep_env.training.ppo_shared.train`),
in the same files, so that ``train/seeds.py``, the checkpoint selection, ``uasep-eval`` and
``train/reproduce.py`` take its runs as they take SB3's:

* ``progress.csv`` (the same columns: the last 200 finished episodes' return of the first
  UAV, collision and loss-of-separation rates, mean max deviation and length, one row per
  update) and ``curves.png``;
* ``checkpoints/step_<agent-steps>/`` every ``checkpoint_every`` agent-steps and
  ``checkpoints/latest``: ``state.pt`` (the networks' and Adam's state dicts and torch's
  random state, loaded weights-only), ``normalization.npz``, ``policy.zip`` and
  ``state.json`` (the counters, the 200-episode window and the options), written under a
  temporary name and renamed into place;
* ``policy.zip`` and ``validation.json`` at the end.

``--resume`` restores the weights, Adam, the normalisation, torch's random state and the
counters (agent-steps, updates, so the critic warm-up goes on where it was, episodes, the
window and the training time spent), and refuses a checkpoint of the other trainer. Like
SB3's resume it is not bit-exact: the environments restart their episodes from their seeds.
The wall budget (``--max-minutes``) counts training time, not the checkpoints' and the
curve's writing. The Lagrangian recipes (their constraint is an SB3 callback) refuse
``--trainer lean``, and so does ``--tensorboard`` (SB3's logger).

``uasep-train mappo --trainer lean`` trains MAPPO in the same loop (``central=True``: the
centralised critic of :mod:`~uasep_env.training.ppo_lean`), in the same files; its
``state.pt`` holds the critic's input and value statistics too, and a resume refuses a PPO
run's checkpoint (and a PPO run a MAPPO one).
"""

from __future__ import annotations

import collections
import io
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.training.args import Args
from uasep_env.training.ppo_lean import Hooks

__all__ = ["check_algorithm", "load_checkpoint", "restore", "save_checkpoint", "train"]

#: The networks' parts in ``state.pt``.
_PARTS = ("pi", "vf", "mu", "v")


def save_checkpoint(state: Any, config: Any, args: Args, directory: Path, info: dict) -> None:
    """Everything ``--resume`` needs, plus the policy checkpoint, in ``directory``.

    Complete or not at all (:func:`uasep_env.training.rundir.save_checkpoint_dir`).

    Args:
        state: The run's :class:`~uasep_env.training.ppo_lean.State`.
        config: The run's env config.
        args: The run's options.
        directory: The checkpoint folder (``checkpoints/step_N``).
        info: The counters and figures for ``state.json`` (the options are added).
    """
    from uasep_env.training.rundir import save_checkpoint_dir

    save_checkpoint_dir(
        directory, lambda tmp: _write_checkpoint(state, config, args, tmp, info), info, args
    )


def _write_checkpoint(state: Any, config: Any, args: Args, tmp: Path, info: dict) -> None:
    import torch

    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.training import ppo_lean
    from uasep_env.training.rundir import normalization_bytes

    learner = state.learner
    nets = {part: getattr(learner, part).state_dict() for part in _PARTS}
    nets["log_std"] = learner.log_std.detach().clone()
    saved = {"nets": nets, "optimizer": state.opt.state_dict(), "torch_rng": torch.get_rng_state()}
    device = learner.log_std.device
    if device.type == "cuda":
        saved["cuda_rng"] = torch.cuda.get_rng_state(device)
    if state.critic_norm is not None:  # MAPPO's critic: its input and value statistics
        parts = {"critic_": state.critic_norm.obs_rms}
        if state.value_scale is not None:
            parts["value_"] = state.value_scale.rms
        saved["central"] = {
            prefix + k: torch.as_tensor(v)
            for prefix, rms in parts.items()
            for k, v in _rms(rms).items()
        }
    buf = io.BytesIO()
    torch.save(saved, buf)
    atomic_write(tmp / "state.pt", buf.getvalue())
    atomic_write(tmp / "normalization.npz", normalization_bytes(state.norm))
    ppo_lean.export_policy(state.nets, state.norm, config, args, tmp / "policy.zip", info)


def _rms(rms: Any) -> dict:
    """A ``RunningMeanStd``'s statistics, as arrays."""
    return {k: np.asarray(getattr(rms, k), dtype=np.float64) for k in ("mean", "var", "count")}


class _LogStd:
    """The learner's ``log_std`` as a module of one tensor (checked and restored alike)."""

    def __init__(self, log_std: Any) -> None:
        self.log_std = log_std

    def state_dict(self) -> dict:
        return {"log_std": self.log_std.detach()}

    def load_state_dict(self, saved: dict) -> None:
        import torch

        with torch.no_grad():
            self.log_std.copy_(saved["log_std"])


def _restore_rms(directory: Path, rms: Any, saved: dict, prefix: str) -> None:
    """A ``RunningMeanStd`` from ``state.pt``'s ``central`` (checked: shapes, finite, > 0)."""
    import torch

    from uasep_env.training.rundir import RunFolderError, restore_module

    own = {k: torch.as_tensor(v) for k, v in _rms(rms).items()}  # float64, rms's shapes
    part = {k: saved.get(prefix + k) for k in own} if isinstance(saved, dict) else saved
    restore_module(directory, f"central.{prefix}", _Stats(own), part)
    if (own["var"] < 0).any() or not own["count"] > 0:
        raise RunFolderError(directory, f"state.pt: central.{prefix}var/count out of range")
    rms.mean = own["mean"].numpy().copy()
    rms.var = own["var"].numpy().copy()
    rms.count = float(own["count"])


class _Stats:
    """A dict of tensors as a module (restore_module checks keys, shapes, dtypes, finite)."""

    def __init__(self, tensors: dict) -> None:
        self.tensors = tensors

    def state_dict(self) -> dict:
        return dict(self.tensors)

    def load_state_dict(self, saved: dict) -> None:
        self.tensors.update(saved)


def check_algorithm(directory: Path, info: dict, args: Args, central: bool) -> None:
    """Refuse a checkpoint of the other algorithm, architecture or value normalisation.

    MAPPO's for a PPO run (``central`` False) or the reverse; one of the other ``--arch``; a
    MAPPO checkpoint whose
    ``--value-norm`` (in ``info``, its ``state.json``) is not ``args``'.

    Raises:
        RunError: One line naming both (the checkpoint's ``policy.zip`` says which it is,
            its ``state.json`` its flags).
    """
    from uasep_env.training.rundir import RunError, check_switch, read_policy

    policy = read_policy(directory)
    theirs = policy.algorithm
    ours = "MAPPO" if central else "PPO"
    if theirs != ours:
        raise RunError(f"--resume {directory}: a {theirs} checkpoint, not {ours}'s")
    if policy.architecture != getattr(args, "arch", "mlp"):
        raise RunError(
            f"--resume {directory}: a checkpoint of --arch {policy.architecture}; resume it "
            f"with --arch {policy.architecture}"
        )
    if central:
        check_switch(directory, info, args, "value_norm", default=True)


def load_checkpoint(state: Any, directory: Path, args: Args) -> dict:
    """Restore a :func:`save_checkpoint` folder into ``state``; returns its ``state.json``.

    Weights-only loads (no unpickling). The learner takes the weights (``state.nets`` takes
    them from it when the run starts).

    Raises:
        RunError: The folder is incomplete, a checkpoint of SB3's (or skrl's) trainer, or
            of MAPPO resumed as PPO or the reverse (one line).
    """
    from uasep_env.training.rundir import check_checkpoint, check_trainer

    directory = check_checkpoint(directory)
    info = check_trainer(directory, args)
    check_algorithm(directory, info, args, state.critic_norm is not None)
    restore(state, directory, info)
    return info


def restore(state: Any, directory: Path, info: dict) -> None:
    """Load a checked checkpoint folder (``state.json``: ``info``) into ``state``.

    Raises:
        RunError: Its ``state.pt`` is a PPO run's and ``state`` MAPPO's, or the reverse.
    """
    import torch

    from uasep_env.training.rundir import (
        RunError,
        load_normalization,
        read_tensors,
        restore_module,
        restore_optimizer,
        restore_rng,
        tensor_part,
    )

    central = state.critic_norm is not None
    saved = read_tensors(directory)  # every tensor checked as it is restored
    if ("central" in saved) != central:  # a policy.zip swapped in: still one line
        raise RunError(f"--resume {directory}: its state.pt and policy.zip disagree")
    learner = state.learner
    for part in _PARTS:
        net = tensor_part(directory, saved, "nets", part)
        restore_module(directory, f"nets.{part}", getattr(learner, part), net)
    log_std = tensor_part(directory, saved, "nets", "log_std")
    restore_module(directory, "nets", _LogStd(learner.log_std), {"log_std": log_std})
    restore_optimizer(directory, "optimizer", state.opt, tensor_part(directory, saved, "optimizer"))
    restore_rng(directory, "torch_rng", tensor_part(directory, saved, "torch_rng"))
    device = learner.log_std.device
    if "cuda_rng" in saved and device.type == "cuda":
        torch.cuda.set_rng_state(saved["cuda_rng"], device)
    load_normalization(state.norm, directory / "normalization.npz")
    if central:
        stats = tensor_part(directory, saved, "central")
        _restore_rms(directory, state.critic_norm.obs_rms, stats, "critic_")
        if state.value_scale is not None:
            _restore_rms(directory, state.value_scale.rms, stats, "value_")
    state.agent_steps = int(info["agent_steps"])
    state.updates = int(info["updates"])
    state.episodes = int(info["episodes"])
    state.wall_s = float(info["wall_s"])


def train(args: Args, plugin: Any = None, central: bool = False) -> dict:
    """Train (or resume) ``args``' recipe with the lean loop; export, validate, summarise.

    The contract of :func:`uasep_env.training.ppo_shared.train`, which calls this for
    ``--trainer lean`` (and :func:`uasep_env.training.mappo.main`, with ``central``: MAPPO's
    centralised critic).

    ``plugin``: the PPO-Lagrangian recipes' constraint, whose ``start_lean(out, config,
    resumed)`` gives the loop's multiplier (:class:`~uasep_env.training.constraint.LeanCost`:
    the rewards shaped at every step, the multiplier moved at every rollout's end); its
    ``facts()`` go into every checkpoint and ``validation.json``.

    Raises:
        ValueError: A ``plugin`` with no lean-loop part.
    """
    if plugin is not None and not hasattr(plugin, "start_lean"):
        raise ValueError(f"trainer 'lean': the {plugin.title} recipe trains on SB3 only")
    import torch

    from uasep_env.training import ppo_lean
    from uasep_env.training.args import budget_notice, make_env_config
    from uasep_env.training.rundir import RunFolder

    torch.set_num_threads(args.torch_threads)
    config = make_env_config(args)
    run = RunFolder.start(args, lambda ck, info: check_algorithm(ck, info, args, central))
    # The constraint's state restored (and checked) before the folder is rewound.
    cost = plugin.start_lean(run.out, config, run.resumed) if plugin is not None else None
    hooks = _RunHooks(run, config, cost, plugin.facts if plugin is not None else None)
    if args.shield == "cbf":
        from uasep_env.training.shield_loop import ShieldInLoop

        hooks.shield = ShieldInLoop(config)

    def prepare(state: Any) -> None:
        hooks.last_state = state
        if run.resume is not None:
            restore(state, run.resume, run.resumed)
            run.rewind(state.agent_steps)
        notice = budget_notice(args, config.n_uavs, state.agent_steps)
        if notice:
            print(notice)

    nets, norm, facts = ppo_lean.train(args, config, hooks, prepare, central=central)
    if run.resume is None or facts["updates"] > int(run.resumed.get("updates", 0)):
        if run.saved_at != hooks.last_state.agent_steps:
            hooks.checkpoint(hooks.last_state)  # the final one (after the last update)
        info = hooks.info(hooks.last_state)
    else:  # resumed at the end: only the final outputs are (re)written
        info = run.resumed_info()
    hooks.close()
    name = plugin.title if plugin is not None else "PPO"
    title = "MAPPO, lean loop" if central else f"{name}, lean loop ({args.action_mode})"
    return run.publish(
        lambda path: ppo_lean.export_policy(nets, norm, config, args, path, info),
        config, info, title, more=plugin.finish if plugin is not None else None,
    )  # fmt: skip


class _RunHooks(Hooks):
    """The run's learning curve, progress bar and checkpoints around the lean loop."""

    def __init__(self, run: Any, config: Any, cost: Any = None, facts: Any = None) -> None:
        self.run, self.args, self.config = run, run.args, config
        self.last_state: Any = None  # the loop's State
        self.bar: Any = None
        self.cost, self.facts = cost, facts  # a Lagrangian recipe's multiplier and state
        self.shield: Any = None  # training under the shield: its filter (--shield cbf)

    def start(self, nets: Any, norm: Any) -> None:
        args, run = self.args, self.run
        self.window: collections.deque = run.episode_window()
        steps = int(run.resumed.get("agent_steps", 0))
        self.next_ckpt = run.next_checkpoint(steps)
        self.csv = run.progress_log()
        if self.cost is not None:
            self.cost.start(self.args.n_envs * self.config.n_uavs)
        if args.progress:
            from tqdm import tqdm

            from uasep_env.training.args import rounded_budget

            end = rounded_budget(args, self.config.n_uavs, steps)  # whole rollouts
            self.bar = tqdm(
                total=end, initial=steps, unit="step", unit_scale=True,
                desc=f"{args.action_mode} (lean)", dynamic_ncols=True,
            )  # fmt: skip

    def rollout_end(self, agent_steps: int) -> None:
        if self.cost is not None:
            self.cost.rollout_end(agent_steps)
        if self.bar is not None:
            self.bar.update(agent_steps - self.bar.n)

    def act(self, actions: Any, observations: Any) -> Any:
        return actions if self.shield is None else self.shield.act(actions, observations)

    def shape(self, res: Any, reward: Any, dones: Any) -> Any:
        if self.cost is None:
            return reward
        shield = self.shield.interventions if self.shield is not None else None
        return self.cost.shape(res, reward, dones, shield)

    def update_end(self, state: Any) -> None:
        from uasep_env.training.rundir import bar_postfix, window_summary

        self.last_state = state
        self.window.extend(state.finished)
        s = window_summary(self.window)
        self.csv.write({"agent_steps": state.agent_steps, "wall_s": round(state.wall_s, 2),
                        "episodes": state.episodes, **s})  # fmt: skip
        if self.bar is not None and s:
            self.bar.set_postfix(**bar_postfix(s))
        # The last one is saved at the end, not twice.
        if self.next_ckpt <= state.agent_steps < self.args.total_timesteps:
            self.checkpoint(state)
            self.next_ckpt = self.run.next_checkpoint(state.agent_steps)

    def info(self, state: Any) -> dict:
        from uasep_env.training.rundir import window_summary

        return {"agent_steps": int(state.agent_steps), "wall_s": state.wall_s,
                "episodes": state.episodes, "updates": state.updates,
                **window_summary(self.window),
                **(self.facts() if self.facts is not None else {}),
                **(self._shield_facts() if self.shield is not None else {})}  # fmt: skip

    def _shield_facts(self) -> dict:
        """Training under the shield: its interventions per agent-step (this process's run)."""
        rate = self.shield.rate()
        return {"shield": {"filter": self.args.shield, "interventions_per_agent_step":
                           None if rate != rate else round(rate, 6)}}  # fmt: skip

    def checkpoint(self, state: Any) -> None:
        self.run.save_checkpoint(
            state.agent_steps, self.info(state), self.window,
            lambda d, info: save_checkpoint(state, self.config, self.args, d, info),
        )  # fmt: skip

    def close(self) -> None:
        if self.cost is not None:
            self.cost.close()
        self.run.close()
        if self.bar is not None:
            self.bar.close()
