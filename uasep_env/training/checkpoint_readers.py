"""A run folder's checkpoint files, read and checked: the one reader of each (untrusted input).

A checkpoint folder (``checkpoints/step_<agent-steps>``) holds :data:`CHECKPOINT_FILES`.
:func:`check_checkpoint` checks the folder before anything is read (every file present, inside
the folder, a regular file within :data:`LIMITS`), then each file has one reader here:
:func:`read_state` (``state.json``), :func:`read_tensors` (``state.pt``),
:func:`load_normalization` (``normalization.npz``) and :func:`read_policy` (``policy.zip``'s
metadata); the tensors are checked where they are restored (:mod:`~uasep_env.training.restore`).
Every refusal is one line naming the folder and the file (:class:`RunFolderError`, exit
status 2). :mod:`~uasep_env.training.rundir` re-exports every name.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.boundedzip import HOSTILE_FILE_ERRORS, check_member, check_members
from uasep_env.runtime.jsonio import loads_bounded
from uasep_env.runtime.runfiles import RunFileRefused, check_inside, read_inside
from uasep_env.training.curves import WINDOW_EPISODES

#: The files of a complete checkpoint folder (``state.json`` last).
CHECKPOINT_FILES = ("state.pt", "normalization.npz", "policy.zip", "state.json")
#: The SB3 recipes' environments' state (:mod:`uasep_env.training.sb3_state`), read by
#: :func:`read_env_state`: in their checkpoints, absent from older ones and other trainers'.
ENV_STATE_FILE = "env_state.npz"


class RunError(SystemExit):
    """A run that cannot start: one line for the user (exit status 1)."""

    def __init__(self, message: str) -> None:
        super().__init__(f"{Path(sys.argv[0]).name}: error: {message}")


class RunFolderError(RunError):
    """A run folder's file refused (untrusted input): one line, exit status 2.

    The line names the folder, the file and what is wrong. As :mod:`argparse`'s errors
    (also status 2) it is printed when raised: a :class:`SystemExit` of status 2 prints
    nothing itself.
    """

    def __init__(self, folder: Path | str, message: str) -> None:
        prefix = f"{folder}{os.sep}"
        message = message.replace(prefix, "")  # the file by its name within the folder
        super().__init__(f"--resume {folder}: {message}" if message else f"{folder}")
        self.code = 2
        print(self.args[0], file=sys.stderr)


@dataclasses.dataclass(frozen=True, kw_only=True)
class RunFolderLimits:
    """Hard bounds on a run folder's files (a file beyond them is refused, not read).

    Attributes:
        state_json: Largest ``state.json`` (counters, a window of 200 episodes, options).
        json_depth: Deepest nesting of ``state.json``.
        state_pt: Largest ``state.pt`` (networks, Adam's moments, torch's RNG).
        record: Largest record (one tensor's storage) of ``state.pt``.
        ratio: Largest compression ratio of a zip member over 64 KiB.
        normalization: Largest ``normalization.npz``.
        policy: Largest ``policy.zip`` (its reader has its own, finer limits).
        env_state: Largest ``env_state.npz``, and the most its arrays inflate to in all
            (the worlds' arrays and buffered noise).
        env_state_arrays: Most arrays in ``env_state.npz``.
    """

    state_json: int = 4 * 1024 * 1024
    json_depth: int = 16
    state_pt: int = 512 * 1024 * 1024
    record: int = 128 * 1024 * 1024
    ratio: float = 50.0
    normalization: int = 16 * 1024 * 1024
    policy: int = 64 * 1024 * 1024
    env_state: int = 256 * 1024 * 1024
    env_state_arrays: int = 4096


#: The limits the run folder's readers apply.
LIMITS = RunFolderLimits()


def check_checkpoint(directory: Path) -> Path:
    """The resolved checkpoint folder, or a one-line error naming what is missing.

    Raises:
        RunError: The folder does not exist or lacks one of :data:`CHECKPOINT_FILES`.
    """
    if not directory.is_dir():
        raise RunError(f"--resume {directory}: no such checkpoint folder")
    missing = [f for f in CHECKPOINT_FILES if not os.path.lexists(directory / f)]
    if missing:
        raise RunError(
            f"--resume {directory}: incomplete checkpoint (missing {', '.join(missing)}; "
            "a kill while it was saved?); resume from an earlier checkpoints/step_N"
        )
    resolved = directory.resolve()
    limits = {"state.pt": LIMITS.state_pt, "normalization.npz": LIMITS.normalization,
              "policy.zip": LIMITS.policy, "state.json": LIMITS.state_json}  # fmt: skip
    if os.path.lexists(resolved / ENV_STATE_FILE):  # optional: checked alike where present
        limits[ENV_STATE_FILE] = LIMITS.env_state
    for name in limits:  # links out, FIFOs, devices, huge files: before any read
        try:
            check_inside(resolved, resolved / name, limits[name])
        except RunFileRefused as err:
            raise RunFolderError(resolved, str(err)) from None
    return resolved


def _read(directory: Path, name: str, limit: int) -> bytes:
    """A checkpoint file's bytes, through the run folder's one file reader (runfiles)."""
    try:
        return read_inside(directory, directory / name, limit)
    except RunFileRefused as err:
        raise RunFolderError(directory, str(err)) from None


def _count(value: Any, low: int = 0) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _finite(value: Any, low: float = -math.inf) -> bool:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    return number and math.isfinite(value) and value >= low


def read_state(directory: Path) -> dict:
    """A checkpoint folder's ``state.json`` (the counters, the episode window, the options).

    Read within :data:`LIMITS` by the project's bounded JSON reader (no NaN or Infinity, no
    repeated key); the counters, the wall time and the episode window are checked.

    Raises:
        RunFolderError: One line naming the folder, ``state.json`` and what is wrong.
    """
    raw = _read(directory, "state.json", LIMITS.state_json)
    try:
        info = loads_bounded(raw, max_depth=LIMITS.json_depth)
    except ValueError as err:
        raise RunFolderError(directory, f"state.json: {err}") from None

    def bad(message: str) -> RunFolderError:
        return RunFolderError(directory, f"state.json: {message}")

    if not isinstance(info, dict):
        raise bad(f"holds {type(info).__name__}, not an object")
    if not _count(info.get("agent_steps")):
        raise bad(f"agent_steps must be a whole number >= 0, got {info.get('agent_steps')!r:.40}")
    for key in ("episodes", "updates"):
        if key in info and not _count(info[key]):
            raise bad(f"{key} must be a whole number >= 0, got {info[key]!r:.40}")
    if "wall_s" in info and not _finite(info["wall_s"], 0.0):
        raise bad(f"wall_s must be a finite number >= 0, got {info['wall_s']!r:.40}")
    window = info.get("window", [])
    if not isinstance(window, list) or len(window) > WINDOW_EPISODES:
        raise bad(f"window must be a list of at most {WINDOW_EPISODES} episodes")
    for k, episode in enumerate(window):  # null: an episode without a return (NaN, saved)
        if not isinstance(episode, list) or not all(e is None or _finite(e) for e in episode):
            raise bad(f"window[{k}] must be a list of finite numbers, got {episode!r:.60}")
    for key in ("args", "lagrangian"):
        if key in info and not isinstance(info[key], dict):
            raise bad(f"{key} must be an object")
    return info


def read_tensors(directory: Path) -> dict:
    """A checkpoint folder's ``state.pt``, loaded weights-only (no unpickling).

    Its zip directory is checked first, as the policy reader checks ``policy.zip``
    (:mod:`uasep_env.runtime.boundedzip`): every record's declared size, its compression
    ratio (torch stores its records uncompressed: a compressed one is refused) and their
    total, so that ``torch.load`` (which inflates before it checks) never meets a deflate
    bomb. The tensors themselves are checked where they are restored
    (:func:`restore_module`, :func:`restore_optimizer`, :func:`restore_rng`).

    Raises:
        RunFolderError: One line naming the folder, ``state.pt`` and what is wrong.
    """
    import pickle
    import zipfile

    import torch

    raw = _read(directory, "state.pt", LIMITS.state_pt)

    def bad(message: str) -> RunFolderError:
        return RunFolderError(directory, f"state.pt: {message}")

    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            total = 0
            for info in z.infolist():
                check_member(info, LIMITS.record, LIMITS.ratio)
                if info.compress_type != zipfile.ZIP_STORED:
                    raise ValueError(f"{info.filename}: compressed (torch stores its records)")
                total += info.file_size
            if total > LIMITS.state_pt:
                raise ValueError(f"records of {total:,} bytes in all, limit {LIMITS.state_pt:,}")
    except (*HOSTILE_FILE_ERRORS, pickle.UnpicklingError) as err:
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise bad(f"not a torch checkpoint ({detail})") from None
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as err:  # whatever a hostile file makes torch raise
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise bad(f"not a weights-only torch checkpoint ({type(err).__name__}: {detail})") from None
    if not isinstance(state, dict):
        raise bad(f"holds {type(state).__name__}, not a dict of the run's tensors")
    return state


def read_env_state(directory: Path) -> dict[str, np.ndarray] | None:
    """A checkpoint folder's ``env_state.npz`` (plain arrays; ``None`` where there is none).

    Read within :data:`LIMITS` (its zip directory checked first: at most
    ``env_state_arrays`` members, their declared sizes and compression ratios, their
    total) and loaded with ``allow_pickle=False``. The arrays are checked where they are
    restored (:func:`uasep_env.training.sb3_state.load_rollout_state`).

    Raises:
        RunFolderError: One line naming the folder, ``env_state.npz`` and what is wrong.
    """
    import zipfile

    if not os.path.lexists(directory / ENV_STATE_FILE):
        return None
    raw = _read(directory, ENV_STATE_FILE, LIMITS.env_state)
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            infos = z.infolist()
            if len(infos) > LIMITS.env_state_arrays:
                raise ValueError(f"{len(infos):,} members, limit {LIMITS.env_state_arrays:,}")
            members = {i.filename: LIMITS.env_state for i in infos}
            check_members(z, members, LIMITS.ratio)  # duplicates, encryption, bombs
            total = sum(i.file_size for i in infos)
            if total > LIMITS.env_state:
                raise ValueError(f"arrays of {total:,} bytes in all, limit {LIMITS.env_state:,}")
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            return {name: np.asarray(z[name]) for name in z.files}
    except HOSTILE_FILE_ERRORS as err:
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise RunFolderError(
            directory, f"{ENV_STATE_FILE}: not an environment state ({detail})"
        ) from None


def read_policy(directory: Path) -> Any:
    """The metadata of a checkpoint folder's ``policy.zip`` (its algorithm, its options).

    Raises:
        RunFolderError: Not a regular file inside the folder, or refused by the policy
            checkpoint reader (its limits): one line.
    """
    return read_policy_inside(directory, directory / "policy.zip")[0]


def read_policy_inside(directory: Path, path: Path) -> Any:
    """The policy checkpoint ``path`` of the folder ``directory``, read within limits.

    Returns:
        The policy checkpoint reader's ``(meta, arrays)``.

    Raises:
        RunFolderError: Not a regular file inside the folder, or refused by the policy
            checkpoint reader (its limits): one line.
    """
    from uasep_env.policies.checkpoint import CheckpointError
    from uasep_env.policies.learned import read_checkpoint

    try:
        check_inside(directory, path, LIMITS.policy)
        return read_checkpoint(path)
    except (RunFileRefused, CheckpointError) as err:
        raise RunFolderError(directory, str(err)) from None


def load_normalization(norm: Any, path: Path) -> None:
    """Restore :func:`normalization_bytes`' statistics into ``norm`` (no unpickling).

    The return statistics only where the file has them (skrl's MAPPO saves the
    observations' alone). Read within :data:`LIMITS` (its zip directory checked first);
    each array must have ``norm``'s shape and be finite, variances >= 0, counts > 0.

    Raises:
        RunFolderError: One line naming the folder, the file and the array.
    """
    import zipfile

    directory, name = path.parent, path.name
    raw = _read(directory, name, LIMITS.normalization)
    own = {"obs_": norm.obs_rms, "ret_": getattr(norm, "ret_rms", None)}
    names = [f"{p}{k}" for p in own for k in ("mean", "var", "count")]
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            infos = z.infolist()
            present = {i.filename.removesuffix(".npy") for i in infos}
            expected = names if present - set(names[:3]) else names[:3]
            check_members(z, {f"{n}.npy": LIMITS.normalization for n in expected}, LIMITS.ratio)
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            arrays = {n: np.asarray(z[n]) for n in expected}
    except HOSTILE_FILE_ERRORS as err:
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise RunFolderError(directory, f"{name}: not the run's statistics ({detail})") from None
    for prefix, rms in own.items():
        if f"{prefix}mean" not in arrays or rms is None:
            continue
        shape = np.shape(rms.mean)
        for key in ("mean", "var", "count"):
            a = arrays[prefix + key]
            want = () if key == "count" else shape
            problem = (
                f"shape {a.shape}, expected {want}" if a.shape != want
                else f"{a.dtype} data, expected floats" if a.dtype.kind not in "fiu"
                else "non-finite values" if not np.isfinite(a).all()
                else "negative values" if key == "var" and (a < 0).any()
                else "not > 0" if key == "count" and not a > 0
                else ""
            )  # fmt: skip
            if problem:
                raise RunFolderError(directory, f"{name}: {prefix}{key}: {problem}")
        rms.mean = arrays[prefix + "mean"].astype(np.float64)
        rms.var = arrays[prefix + "var"].astype(np.float64)
        rms.count = float(arrays[prefix + "count"])
