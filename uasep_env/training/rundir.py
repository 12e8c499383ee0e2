"""A training run's folder: never mixed with another run, checkpoints that resume exactly.

Every recipe's loop (:mod:`~uasep_env.training.ppo_shared` and its variants,
:mod:`~uasep_env.training.lean_recipe`, :mod:`~uasep_env.training.mappo`,
:mod:`~uasep_env.training.mappo_lagrangian`) holds one :class:`RunFolder` for the run's
life: claimed and checked (or resumed) at the start, checkpoints and ``progress.csv`` in the
loop, the policy and ``validation.json`` published at the end. The rules:

* A run claims its ``--out-dir`` for its whole life (:mod:`uasep_env.runtime.runlock`): a second
  run started into the same folder fails at once, naming it.
* A fresh run refuses a non-empty ``--out-dir`` (a previous run's files would be mixed with
  its own); ``--overwrite`` first deletes the files a run writes there (``progress.csv``,
  ``curves.png``, ``policy.zip``, ``validation.json``, ``checkpoints/``, ``tb/``; nothing
  else), ``--resume CHECKPOINT`` continues the run.
* Every file is written atomically (:mod:`uasep_env.runtime.atomic`); a checkpoint folder's
  ``state.json`` is written last, so a folder without it (a kill while saving) is incomplete,
  and ``checkpoints/latest`` is swapped to a folder only once it is complete.
* ``progress.csv`` is appended (one row per PPO iteration, flushed and ``fsync``-ed); a kill
  can tear its last line, which the reader drops. ``--resume`` first rewrites it (atomically)
  to the rows up to the checkpoint, and deletes the checkpoints saved after it: the resumed
  run continues from exactly the checkpoint's progress (agent-steps, episodes, the window of
  the last 200 episodes, wall time), not from where the killed process happened to stop.

It also holds what every trainer (SB3's, skrl's, the lean loop's) writes the same way (the
learning curve's files are :mod:`~uasep_env.training.curves`'): a checkpoint's
normalisation (:func:`normalization_bytes`) and policy (:func:`export_actor`), the check
that a checkpoint resumes under the trainer that wrote it (:func:`check_trainer`), and
``validation.json`` (:func:`write_validation`).
"""

from __future__ import annotations

import collections
import dataclasses
import io
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_symlink, atomic_write, fsync_dir
from uasep_env.runtime.runfiles import RunFileRefused
from uasep_env.runtime.runlock import LOCK_NAME, RunFolderBusy, claim_run_folder, is_own_lock
from uasep_env.training.args import Args, hidden, make_env_config

# The checkpoint's readers (checkpoint_readers) and checked restoring (restore): imported by
# the recipes and tests from here, as they always were.
from uasep_env.training.checkpoint_readers import (  # noqa: F401
    CHECKPOINT_FILES,
    ENV_STATE_FILE,
    LIMITS,
    RunError,
    RunFolderError,
    RunFolderLimits,
    _count,
    _finite,
    _read,
    check_checkpoint,
    load_normalization,
    read_env_state,
    read_policy,
    read_state,
    read_tensors,
)

# The learning curve's files (curves); imported by the recipes from here, as they always were.
from uasep_env.training.curves import (  # noqa: F401
    CSV_FIELDS,
    MIN_PLOTTED_EPISODES,
    WINDOW_EPISODES,
    ProgressLog,
    bar_postfix,
    checkpoint_line,
    log_line,
    plot_curves,
    read_progress,
    validation_line,
    window_summary,
    write_rows,
)
from uasep_env.training.restore import (  # noqa: F401
    _check_tensor,
    _walk,
    restore_arrays,
    restore_json,
    restore_module,
    restore_optimizer,
    restore_rng,
    tensor_part,
)

#: What a run writes in its folder (``--overwrite`` deletes these, and only these).
RUN_FILES = ("progress.csv", "curves.png", "policy.zip", "validation.json")
RUN_DIRS = ("checkpoints", "tb")


class RunFolder:
    """One training run's folder, from its claim to the published policy.

    Every recipe's loop makes it once and calls it in order, so that a recipe reads as a
    CleanRL script: set up, loop, save::

        run = RunFolder.start(args)                  # checkpoint checked, folder claimed
        ...build the model; if run.resume: restore it from run.resume...
        run.rewind(agent_steps)                      # resuming: back to the checkpoint
        log, window = run.progress_log(), run.episode_window()
        ...loop: log.write(row); run.save_checkpoint(agent_steps, info, window, save)...
        run.close()
        return run.publish(export, config, info, title)

    The folder's files are read through few functions only, the ones to harden
    (:mod:`~uasep_env.training.checkpoint_readers`, re-exported here):
    :func:`check_checkpoint` (what a checkpoint folder holds), :func:`read_state`
    (``state.json``), :func:`read_tensors` (``state.pt``), :func:`load_normalization`
    (``normalization.npz``), :func:`read_policy` (``policy.zip``'s metadata) and
    :func:`read_progress` (the CSVs).

    Attributes:
        args: The run's options.
        out: The run's folder (``--out-dir``).
        resume: The checked checkpoint folder to resume from, or None (a fresh run).
        resumed: Its ``state.json`` (``{}`` for a fresh run).
        fields: The columns of ``progress.csv``.
        saved_at: Agent-steps of the last checkpoint saved (-1: none yet).
    """

    def __init__(
        self,
        args: Any,
        out: Path,
        resume: Path | None = None,
        resumed: dict | None = None,
        fields: tuple[str, ...] = (),
    ) -> None:
        self.args, self.out, self.resume = args, Path(out), resume
        self.resumed: dict = resumed or {}
        self.fields = fields or CSV_FIELDS
        self.saved_at = -1
        self._log: ProgressLog | None = None

    @classmethod
    def start(
        cls,
        args: Any,
        check: Callable[[Path, dict], None] | None = None,
        *,
        same_trainer: bool = True,
        own_files: tuple[str, ...] = (),
    ) -> RunFolder:
        """Check the checkpoint to resume (if any), then claim and prepare ``--out-dir``.

        Args:
            args: The run's options (``out_dir``, ``resume``, ``overwrite``, ``trainer``).
            check: The recipe's own check of the checkpoint: ``check(folder, state.json)``,
                raising :class:`RunError`; after the trainer's.
            same_trainer: Refuse a checkpoint of the other ``--trainer``
                (:func:`check_trainer`).
            own_files: The recipe's files beyond :data:`RUN_FILES` that ``--overwrite``
                deletes too.

        Raises:
            RunError: One line: the checkpoint is missing, incomplete or refused, or the
                folder is another run's or in use (:func:`prepare_out_dir`).
        """
        run = cls.attach(args)
        if run.resume is not None:
            if same_trainer:
                check_trainer(run.resume, args, run.resumed)
            if check is not None:
                check(run.resume, run.resumed)
        prepare_out_dir(run.out, args.resume, args.overwrite)
        if args.overwrite:
            for name in own_files:
                (run.out / name).unlink(missing_ok=True)
        return run

    @classmethod
    def attach(cls, args: Any, out: Path | None = None) -> RunFolder:
        """The folder of a run claimed elsewhere (a benchmark's, a test's): not claimed here.

        ``--resume``'s checkpoint is checked (:func:`check_checkpoint`) and its
        ``state.json`` read; ``out`` defaults to ``args.out_dir``.
        """
        resume, resumed = None, {}
        if args.resume:
            resume = check_checkpoint(Path(args.resume))
            resumed = read_state(resume)
        return cls(args, Path(args.out_dir) if out is None else out, resume, resumed)

    def rewind(self, agent_steps: int) -> None:
        """Make the folder what it was at the resumed checkpoint (:func:`rewind`); say so."""
        rewind(self.out, self.fields, agent_steps)
        print(f"resumed from {self.resume} at {agent_steps:,} agent-steps")

    def episode_window(self) -> collections.deque:
        """The last 200 finished episodes: the resumed checkpoint's, or none."""
        return collections.deque(
            (tuple(e) for e in self.resumed.get("window", ())), maxlen=WINDOW_EPISODES
        )

    def next_checkpoint(self, agent_steps: int) -> int:
        """The first multiple of ``--checkpoint-every`` after ``agent_steps``."""
        every = self.args.checkpoint_every
        return (agent_steps // every + 1) * every

    def progress_log(self) -> ProgressLog:
        """``progress.csv`` opened for appending (closed by :meth:`close`)."""
        self._log = ProgressLog(self.out / "progress.csv", self.fields)
        return self._log

    def save_checkpoint(
        self,
        agent_steps: int,
        info: dict,
        window: Any,
        save: Callable[[Path, dict], None],
    ) -> Path:
        """``checkpoints/step_<agent_steps>`` and ``checkpoints/latest`` pointing at it.

        ``save(folder, state)`` writes the trainer's checkpoint (complete or not at all:
        :func:`save_checkpoint_dir`); ``state`` is ``info`` with the episode ``window``.
        """
        folder = self.out / "checkpoints" / f"step_{agent_steps}"
        save(folder, {**info, "window": [[float(x) for x in e] for e in window]})
        self.saved_at = agent_steps
        atomic_symlink(folder.name, self.out / "checkpoints" / "latest")  # once it is complete
        log_line(checkpoint_line(folder.name, info, window))
        return folder

    def resumed_info(self) -> dict:
        """The resumed checkpoint's facts, for a run resumed at its end (nothing to train)."""
        return {k: v for k, v in self.resumed.items() if k not in ("window", "args")}

    def close(self) -> None:
        """Close ``progress.csv``."""
        if self._log is not None:
            self._log.close()
            self._log = None

    def publish(
        self,
        export: Callable[[Path], Path],
        config: Any,
        info: dict,
        title: str,
        more: Callable[[Path], None] | None = None,
    ) -> dict:
        """The run's end: ``policy.zip``, ``curves.png``, ``more(out)``, ``validation.json``.

        ``export(path)`` writes the final policy there (returning its path); ``more`` draws
        a recipe's own figures. Returns the summary :func:`write_validation` writes.
        """
        policy_path = export(self.out / "policy.zip")
        plot_curves(self.out / "progress.csv", self.out / "curves.png", self.fields, title)
        if more is not None:
            more(self.out)
        return write_validation(self.out, config, policy_path, info, self.args.eval_episodes)


def start_run(
    args: Args, check: Callable[[Path, dict], None] | None = None
) -> tuple[Any, Path, Path | None]:
    """``(config, out_dir, checkpoint to resume or None)``: :meth:`RunFolder.start`'s, kept.

    Sets torch's threads and builds the env config first, as the recipes do.
    """
    import torch

    torch.set_num_threads(args.torch_threads)
    config = make_env_config(args)
    run = RunFolder.start(args, check)
    return config, run.out, run.resume


def save_checkpoint_dir(
    directory: Path, write: Callable[[Path], None], info: dict, args: Any
) -> None:
    """A checkpoint folder, complete or not at all: what every trainer's checkpoint does.

    ``write(tmp)`` writes the trainer's files into a temporary folder beside ``directory``;
    ``state.json`` (``info`` and the options ``args``) is written last (a folder without it
    is incomplete), then the folder is renamed into place (:func:`publish_dir`), so
    ``directory`` is either the old checkpoint or the new one. On any error the temporary
    folder goes and the previous checkpoint stays as it was.
    """
    from uasep_env.runtime.jsonio import dumps

    directory.parent.mkdir(parents=True, exist_ok=True)
    tmp = directory.with_name(f".{directory.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        write(tmp)
        state = dumps({**info, "args": dataclasses.asdict(args)}, indent=2)
        atomic_write(tmp / "state.json", state)
        publish_dir(tmp, directory)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def prepare_out_dir(out: Path, resume: str, overwrite: bool) -> None:
    """Refuse to mix runs: check (or clear, with ``overwrite``) the output folder.

    Raises:
        RunError: ``out`` holds files and neither ``resume`` nor ``overwrite`` is given, or
            both are given, or another live run has claimed ``out``.
    """
    if resume and overwrite:
        raise RunError("--resume and --overwrite: choose one")
    if out.exists() and not out.is_dir():
        raise RunError(f"--out-dir {out} exists and is not a folder")
    try:
        claim_run_folder(out)  # first: two runs started together must not both see it empty
    except RunFolderBusy as err:
        raise RunError(f"--out-dir {err}") from None
    except RunFileRefused as err:  # the lock is a link or a FIFO: nothing written through it
        raise RunFolderError(out, str(err)) from None
    # The lock is not content only when it is the very file this run holds.
    used = any(p.name != LOCK_NAME or not is_own_lock(p) for p in out.iterdir())
    if used and overwrite:
        for name in RUN_FILES:
            (out / name).unlink(missing_ok=True)
        for name in RUN_DIRS:
            shutil.rmtree(out / name, ignore_errors=True)
    elif used and not resume:
        raise RunError(
            f"--out-dir {out} is not empty (a previous run?); continue it with --resume "
            f"{out / 'checkpoints' / 'latest'}, replace it with --overwrite, or choose another "
            "--out-dir"
        )
    out.mkdir(parents=True, exist_ok=True)


def rewind(out: Path, fields: tuple[str, ...], agent_steps: int) -> None:
    """Make ``out`` what it was when the checkpoint at ``agent_steps`` was saved.

    ``progress.csv`` keeps the rows up to ``agent_steps`` (rewritten atomically: there is no
    moment when a kill would leave it truncated), and checkpoints saved after it are deleted
    (they belong to the abandoned continuation).
    """
    for tmp in [*out.glob(".*.tmp*"), *out.glob("checkpoints/.*")]:  # a killed process's
        if tmp.is_dir() and not tmp.is_symlink():  # unfinished writes
            shutil.rmtree(tmp)
        else:
            tmp.unlink()
    rewind_csv(out / "progress.csv", fields, agent_steps)
    for d in (out / "checkpoints").glob("step_*"):
        step = d.name.removeprefix("step_")
        if step.isdigit() and int(step) > agent_steps and not d.is_symlink():
            shutil.rmtree(d)
    resumed = out / "checkpoints" / f"step_{agent_steps}"
    if resumed.is_dir():
        atomic_symlink(resumed.name, out / "checkpoints" / "latest")


def rewind_csv(path: Path, fields: tuple[str, ...], agent_steps: int) -> None:
    """Keep the rows of the CSV ``path`` up to ``agent_steps`` (rewritten atomically).

    For ``progress.csv`` (:func:`rewind`) and a recipe's own per-iteration CSV (MAPPO-
    Lagrangian's ``cost_progress.csv``); a file that does not exist is left so.
    """
    if os.path.lexists(path):
        try:  # untrusted: inside the folder, a regular file, parsed with its name in errors
            rows = read_progress(path, root=path.parent)
        except ValueError as err:
            raise RunFolderError(path.parent, str(err)) from None
        write_rows(path, fields, [r for r in rows if int(r["agent_steps"]) <= agent_steps])


def publish_dir(tmp: Path, final: Path) -> None:
    """Move the complete folder ``tmp`` to ``final`` (replacing an older one of that name).

    A new name is one atomic rename. Replacing takes two (the old folder aside, the new one
    in): a kill between them leaves no ``final``, which ``--resume`` reports as missing
    (never a mix of old and new files).
    """
    fsync_dir(tmp)
    if os.path.lexists(final):
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        os.rename(final, old)
        os.rename(tmp, final)
        if old.is_symlink() or not old.is_dir():  # a link is removed, never followed
            old.unlink()
        else:
            shutil.rmtree(old)
    else:
        os.rename(tmp, final)
    fsync_dir(final.parent)


# What every trainer writes the same way: the normalisation and policy files of a
# checkpoint, and validation.json.


def normalization_bytes(norm: Any) -> bytes:
    """A checkpoint's ``normalization.npz``: ``norm``'s running statistics.

    ``norm`` is a ``VecNormalize`` or the lean loop's
    :class:`~uasep_env.training.ppo_lean.Normaliser`.
    """
    o, r = norm.obs_rms, norm.ret_rms
    buf = io.BytesIO()
    np.savez(
        buf,
        obs_mean=o.mean, obs_var=o.var, obs_count=o.count,
        ret_mean=r.mean, ret_var=r.var, ret_count=r.count,
    )  # fmt: skip
    return buf.getvalue()


def check_trainer(directory: Path, args: Args, info: dict | None = None) -> dict:
    """``directory``'s ``state.json`` (``info`` if read already), once its trainer is ours.

    Raises:
        RunError: The checkpoint was written by the other trainer (one line).
    """
    info = read_state(directory) if info is None else info
    theirs = info.get("args", {}).get("trainer", "default")
    if theirs != args.trainer:
        raise RunError(
            f"--resume {directory}: a checkpoint of --trainer {theirs}; resume it with "
            f"--trainer {theirs}"
        )
    return info


def check_switch(directory: Path, info: dict, args: Any, name: str, default: bool) -> None:
    """Refuse to resume ``directory`` (``state.json``: ``info``) under the other ``--name``.

    For an on/off flag a checkpoint's files depend on (MAPPO's ``--value-norm``: its
    statistics are saved or not); a checkpoint written before the flag had ``default``.

    Raises:
        RunError: One line naming the flag to resume it with.
    """
    saved = info.get("args", {}).get(name, default)
    if saved != getattr(args, name):
        flag = "--" + ("" if saved else "no-") + name.replace("_", "-")
        raise RunError(f"--resume {directory}: a checkpoint of {flag}; resume it with {flag}")


def export_actor(
    linears: list,
    venv: Any,
    config: Any,
    args: Args,
    path: Path,
    algorithm: str,
    info: dict,
    architecture: str = "mlp",
) -> Path:
    """Write an actor and its observation normalisation as a policy checkpoint.

    Every recipe exports through here: ``linears`` are the actor's ``torch.nn.Linear``
    layers in order (a set network's in its checkpoint order, ``architecture`` ``"set"``),
    the normalisation is ``venv``'s; the file is pickle-free.
    """
    from uasep_env.policies.learned import PolicyCheckpoint, save_policy

    weights = [(m.weight.detach().cpu().numpy(), m.bias.detach().cpu().numpy()) for m in linears]
    meta = PolicyCheckpoint(
        config=config.to_dict(),
        obs_dim=int(venv.observation_space.shape[0]),
        activation=args.activation,
        hidden=tuple(hidden(args)),
        obs_norm=bool(venv.norm_obs),
        clip_obs=float(venv.clip_obs),
        obs_epsilon=float(venv.epsilon),
        algorithm=algorithm,
        info={**info, "args": dataclasses.asdict(args)},
        architecture=architecture,
    )
    rms = venv.obs_rms
    return save_policy(path, meta, weights, rms.mean, rms.var)


def write_validation(out: Path, config: Any, policy_path: Path, info: dict, episodes: int) -> dict:
    """The policy and the APF on ``episodes`` validation encounters: ``validation.json``."""
    from uasep_env.evaluation import evaluate
    from uasep_env.policies import load_policy
    from uasep_env.runtime.atomic import atomic_write
    from uasep_env.runtime.jsonio import dumps
    from uasep_env.scenarios import VALIDATION_SEEDS

    eval_cfg = config.replace(action={"mode": "direct"})
    seeds = list(VALIDATION_SEEDS)[:episodes]
    summary: dict = {"training": info, "policy": str(policy_path), "validation": {}}
    if seeds:
        from uasep_env.training.shield_loop import deployed

        # As deployed: a checkpoint trained under the shield is validated under it.
        learned = deployed(policy_path, load_policy(policy_path, eval_cfg).meta)
        policies = {"learned": learned, "apf": "apf"}
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
    atomic_write(out / "validation.json", text + "\n", replace_links=True)
    log_line(validation_line(summary, out / "validation.json", len(seeds)))
    return summary
