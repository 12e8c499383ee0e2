"""A training run's folder: never mixed with another run, checkpoints that resume exactly.

Shared by the recipes (:mod:`~uasep_env.training.ppo_shared`, its residual variant and
:mod:`~uasep_env.training.mappo`): :func:`prepare_out_dir` is where a run's folder is
claimed and created. The rules:

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

It also holds what every trainer (SB3's, skrl's, the lean loop's) writes the same way: the
learning curve's columns (:data:`CSV_FIELDS`) and figures (:func:`window_summary`), a
checkpoint's normalisation (:func:`normalization_bytes`) and policy (:func:`export_actor`),
the check that a checkpoint resumes under the trainer that wrote it (:func:`check_trainer`),
and ``validation.json`` (:func:`write_validation`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_output, atomic_symlink, atomic_write, fsync_dir
from uasep_env.runtime.runlock import LOCK_NAME, RunFolderBusy, claim_run_folder
from uasep_env.training.args import Args, hidden, make_env_config

#: What a run writes in its folder (``--overwrite`` deletes these, and only these).
RUN_FILES = ("progress.csv", "curves.png", "policy.zip", "validation.json")
RUN_DIRS = ("checkpoints", "tb")
#: The files of a complete checkpoint folder (``state.json`` last).
CHECKPOINT_FILES = ("state.pt", "normalization.npz", "policy.zip", "state.json")


class RunError(SystemExit):
    """A run that cannot start: one line for the user (exit status 1)."""

    def __init__(self, message: str) -> None:
        super().__init__(f"{Path(sys.argv[0]).name}: error: {message}")


def start_run(
    args: Args, check: Callable[[Path, dict], None] | None = None
) -> tuple[Any, Path, Path | None]:
    """What every PPO trainer does first: ``(config, out_dir, checkpoint to resume or None)``.

    Sets torch's threads, builds the env config, checks the checkpoint (that it is this
    trainer's, then ``check(checkpoint, its state.json)``, which raises :class:`RunError`)
    before the output folder is claimed (:func:`prepare_out_dir`).
    """
    import torch

    torch.set_num_threads(args.torch_threads)
    config = make_env_config(args)
    out = Path(args.out_dir)
    resume = check_checkpoint(Path(args.resume)) if args.resume else None
    if resume is not None:
        info = check_trainer(resume, args)
        if check is not None:
            check(resume, info)
    prepare_out_dir(out, args.resume, args.overwrite)
    return config, out, resume


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
    used = any(p.name != LOCK_NAME for p in out.iterdir())
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


def check_checkpoint(directory: Path) -> Path:
    """The resolved checkpoint folder, or a one-line error naming what is missing.

    Raises:
        RunError: The folder does not exist or lacks one of :data:`CHECKPOINT_FILES`.
    """
    if not directory.is_dir():
        raise RunError(f"--resume {directory}: no such checkpoint folder")
    missing = [f for f in CHECKPOINT_FILES if not (directory / f).is_file()]
    if missing:
        raise RunError(
            f"--resume {directory}: incomplete checkpoint (missing {', '.join(missing)}; "
            "a kill while it was saved?); resume from an earlier checkpoints/step_N"
        )
    return directory.resolve()


def read_progress(path: Path) -> list[dict[str, str]]:
    """The rows of ``progress.csv``; a torn last line (a kill mid-write) is dropped."""
    if not path.exists():
        return []
    text = path.read_text(encoding="utf-8", errors="replace")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # the torn last row
    rows = list(csv.DictReader(io.StringIO(text)))
    return [r for r in rows if None not in r.values() and None not in r]


def write_rows(path: Path, fields: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    """Write ``rows`` as a whole CSV file, atomically."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, "") for k in fields})
    atomic_write(path, buf.getvalue())


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
    if path.exists():
        rows = [r for r in read_progress(path) if int(r["agent_steps"]) <= agent_steps]
        write_rows(path, fields, rows)


def publish_dir(tmp: Path, final: Path) -> None:
    """Move the complete folder ``tmp`` to ``final`` (replacing an older one of that name).

    A new name is one atomic rename. Replacing takes two (the old folder aside, the new one
    in): a kill between them leaves no ``final``, which ``--resume`` reports as missing
    (never a mix of old and new files).
    """
    fsync_dir(tmp)
    if final.exists():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        os.rename(final, old)
        os.rename(tmp, final)
        shutil.rmtree(old)
    else:
        os.rename(tmp, final)
    fsync_dir(final.parent)


class ProgressLog:
    """``progress.csv`` opened for appending: a header when new, each row flushed and synced."""

    def __init__(self, path: Path, fields: tuple[str, ...]) -> None:
        new = not path.exists() or path.stat().st_size == 0
        if new:
            write_rows(path, fields, [])
        self._fh = path.open("a", newline="", encoding="utf-8")
        self._csv = csv.DictWriter(self._fh, fieldnames=fields, lineterminator="\n")

    def write(self, row: dict[str, Any]) -> None:
        """Append one row, durably."""
        self._csv.writerow(row)
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file."""
        self._fh.close()


#: Episodes a progress row's window must hold to be plotted (the run's first rows are noise).
MIN_PLOTTED_EPISODES = 20


def plot_curves(
    csv_path: Path, png_path: Path, fields: tuple[str, ...], title: str = ""
) -> Path | None:
    """Learning curves (return, collision and loss-of-separation rates, deviation) as PNG.

    Returns:
        The figure's path, or None when nothing was written: no row of ``progress.csv``
        holds :data:`MIN_PLOTTED_EPISODES` finished episodes yet (a short run), or
        matplotlib is missing; either is said in one line on stderr, never a blank figure.
    """
    rows = [
        r
        for r in read_progress(csv_path)
        if r.get("return_mean") and int(r["episodes"]) >= MIN_PLOTTED_EPISODES
    ]
    if not rows:
        print(
            f"{png_path.name} not written: no row of {csv_path.name} has "
            f"{MIN_PLOTTED_EPISODES} finished episodes yet (a longer run has curves)",
            file=sys.stderr,
        )
        return None
    try:
        import matplotlib
    except ImportError:
        print(f"{png_path.name} not written: it needs matplotlib (the viz extra)", file=sys.stderr)
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = {k: np.array([float(r[k]) for r in rows]) for k in fields}
    fig, axes = plt.subplots(2, 4, figsize=(16, 6.5), sharey="col")
    panels = (
        ("return_mean", "mean return per agent"),
        ("collision_rate", "collision rate"),
        ("loss_of_separation_rate", "loss-of-separation rate"),
        ("max_deviation_mean", "mean max deviation (m)"),
    )
    for row, (x_key, x_label, scale) in enumerate(
        (("agent_steps", "agent-steps (millions)", 1e-6), ("wall_s", "wall time (min)", 1 / 60))
    ):
        for col, (key, label) in enumerate(panels):
            ax = axes[row, col]
            ax.plot(data[x_key] * scale, data[key], lw=1.2)
            ax.set_xlabel(x_label)
            ax.set_title(label, fontsize=10)
            ax.grid(alpha=0.3)
    fig.suptitle(title or csv_path.parent.name)
    fig.tight_layout()
    with atomic_output(png_path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
    return png_path


# What every trainer writes the same way: the learning curve's columns and figures, the
# normalisation and policy files of a checkpoint, and validation.json.

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


def load_normalization(norm: Any, path: Path) -> None:
    """Restore :func:`normalization_bytes`' statistics into ``norm`` (no unpickling)."""
    with np.load(path, allow_pickle=False) as z:
        norm.obs_rms.mean, norm.obs_rms.var = z["obs_mean"], z["obs_var"]
        norm.obs_rms.count = float(z["obs_count"])
        norm.ret_rms.mean, norm.ret_rms.var = z["ret_mean"], z["ret_var"]
        norm.ret_rms.count = float(z["ret_count"])


def check_trainer(directory: Path, args: Args) -> dict:
    """``directory``'s ``state.json``, once its trainer is ``args.trainer``'s.

    Raises:
        RunError: The checkpoint was written by the other trainer (one line).
    """
    info = json.loads((directory / "state.json").read_text())
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


def window_summary(window: Any) -> dict:
    """The learning curve's figures over the finished episodes of ``window``.

    ``window`` holds ``(return, collision, loss_of_separation, max_deviation, length)``
    tuples; ``{}`` when it is empty.
    """
    w = list(window)
    if not w:
        return {}
    return {
        "return_mean": float(np.mean([e[0] for e in w])),
        "collision_rate": float(np.mean([e[1] for e in w])),
        "loss_of_separation_rate": float(np.mean([e[2] for e in w])),
        "max_deviation_mean": float(np.mean([e[3] for e in w])),
        "episode_length_mean": float(np.mean([e[4] for e in w])),
    }


def bar_postfix(summary: dict) -> dict:
    """The progress bar's figures of a :func:`window_summary`."""
    return {
        "ret": f"{summary['return_mean']:.0f}",
        "coll": f"{summary['collision_rate']:.1%}",
        "los": f"{summary['loss_of_separation_rate']:.1%}",
        "dev": f"{summary['max_deviation_mean']:.1f}m",
    }


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
        hidden=tuple(hidden(args)),
        obs_norm=bool(venv.norm_obs),
        clip_obs=float(venv.clip_obs),
        obs_epsilon=float(venv.epsilon),
        algorithm=algorithm,
        info={**info, "args": dataclasses.asdict(args)},
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
