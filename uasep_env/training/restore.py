"""A checkpoint's state restored only once checked: tensors, optimizer, random state, JSON parts.

The parts of a ``state.pt`` (:func:`~uasep_env.training.checkpoint_readers.read_tensors`,
loaded weights-only) and of a ``state.json`` are untrusted: each is compared with what it is
restored into (the same keys, shapes and dtypes, finite values) and refused in one line naming
the file and the part (:class:`~uasep_env.training.checkpoint_readers.RunFolderError`) before
anything is loaded. :mod:`~uasep_env.training.rundir` re-exports every name.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from uasep_env.training.checkpoint_readers import RunFolderError, _count


def tensor_part(directory: Path, state: Any, *keys: str) -> Any:
    """``state[keys[0]][keys[1]]...`` of a ``state.pt``, or one line naming the missing key.

    Raises:
        RunFolderError: A key missing (or a part that is not a dict).
    """
    where = []
    for key in keys:
        where.append(key)
        if not isinstance(state, dict) or key not in state:
            raise RunFolderError(directory, f"state.pt: no {'.'.join(where)!r}")
        state = state[key]
    return state


def _check_tensor(directory: Path, where: str, value: Any, like: Any) -> None:
    """``value`` a tensor of ``like``'s shape and dtype, finite; else one line."""
    import torch

    def bad(message: str) -> RunFolderError:
        return RunFolderError(directory, f"state.pt: {where}: {message}")

    if not isinstance(value, torch.Tensor):
        raise bad(f"{type(value).__name__}, not a tensor")
    if value.shape != like.shape:
        raise bad(f"shape {tuple(value.shape)}, expected {tuple(like.shape)}")
    if value.dtype != like.dtype:
        raise bad(f"dtype {value.dtype}, expected {like.dtype}")
    if (value.is_floating_point() or value.is_complex()) and not torch.isfinite(value).all():
        raise bad("non-finite values")


def restore_module(directory: Path, where: str, module: Any, saved: Any) -> None:
    """Load ``saved`` into ``module`` once every tensor matches the module's own.

    The same keys; each tensor of the same shape and dtype (an int64 weight is refused, not
    cast) and finite.

    Raises:
        RunFolderError: One line naming ``state.pt``, ``where`` and the tensor.
    """
    own = module.state_dict()
    if not isinstance(saved, dict):
        raise RunFolderError(directory, f"state.pt: {where}: {type(saved).__name__}, not a dict")
    missing, extra = sorted(set(own) - set(saved)), sorted(set(saved) - set(own), key=str)
    if missing or extra:
        detail = ", ".join([*(f"{k} missing" for k in missing[:3]),
                            *(f"{k!r:.40} unexpected" for k in extra[:3])])  # fmt: skip
        raise RunFolderError(directory, f"state.pt: {where}: {detail}")
    for key, value in saved.items():
        _check_tensor(directory, f"{where}.{key}", value, own[key])
    module.load_state_dict(saved)


def _walk(directory: Path, where: str, value: Any, depth: int = 0) -> None:
    """Every tensor and number in ``value`` finite (an optimizer's state)."""
    import torch

    if depth > 16:
        raise RunFolderError(directory, f"state.pt: {where}: nested too deep")
    if isinstance(value, dict):
        for k, v in value.items():
            _walk(directory, f"{where}.{k}", v, depth + 1)
    elif isinstance(value, (list, tuple)):
        for k, v in enumerate(value):
            _walk(directory, f"{where}[{k}]", v, depth + 1)
    elif isinstance(value, torch.Tensor):
        if value.is_floating_point() and not torch.isfinite(value).all():
            raise RunFolderError(directory, f"state.pt: {where}: non-finite values")
    elif isinstance(value, float) and not math.isfinite(value):
        raise RunFolderError(directory, f"state.pt: {where}: {value}, not finite")


def restore_optimizer(directory: Path, where: str, optimizer: Any, saved: Any) -> None:
    """Load ``saved`` into ``optimizer`` once it matches the optimizer's parameters.

    The same groups of the same sizes; every per-parameter tensor (Adam's moments) of its
    parameter's shape and dtype; everything finite.

    Raises:
        RunFolderError: One line naming ``state.pt``, ``where`` and what is wrong.
    """
    import torch

    def bad(message: str) -> RunFolderError:
        return RunFolderError(directory, f"state.pt: {where}: {message}")

    if not isinstance(saved, dict) or set(saved) != {"state", "param_groups"}:
        raise bad("not an optimizer's state (keys 'state' and 'param_groups')")
    _walk(directory, where, saved)
    groups = saved["param_groups"]
    ours = optimizer.param_groups
    sizes = [len(g.get("params", ())) if isinstance(g, dict) else -1 for g in groups]
    if not isinstance(groups, list) or sizes != [len(g["params"]) for g in ours]:
        raise bad(f"parameter groups of sizes {sizes}, expected {[len(g['params']) for g in ours]}")
    params = [p for g in ours for p in g["params"]]
    if not isinstance(saved["state"], dict):
        raise bad("state is not a dict")
    for index, entry in saved["state"].items():
        if not (_count(index) and index < len(params)) or not isinstance(entry, dict):
            raise bad(f"state of parameter {index!r:.40}, which it does not have")
        for key, value in entry.items():
            if isinstance(value, torch.Tensor) and value.dim() > 0:  # a moment, not 'step'
                _check_tensor(directory, f"{where}.state[{index}].{key}", value, params[index])
    try:
        optimizer.load_state_dict(saved)
    except Exception as err:  # anything else torch refuses, in one line
        raise bad(f"refused by the optimizer ({' '.join(str(err).split())[:200]})") from None


def restore_rng(directory: Path, where: str, saved: Any) -> None:
    """Set torch's CPU random state from ``saved`` (checked: a byte tensor of its size)."""
    import torch

    _check_tensor(directory, where, saved, torch.get_rng_state())
    torch.set_rng_state(saved)


def restore_json(
    directory: Path,
    where: str,
    loader: Callable[[Any], None],
    saved: Any,
    file: str = "state.json",
) -> None:
    """``loader(saved)`` of a part of a checkpoint (a multiplier's state), in one line.

    Raises:
        RunFolderError: ``loader`` refused it (ValueError, KeyError, TypeError,
            RuntimeError): one line naming ``file`` and ``where``.
    """
    try:
        loader(saved)
    except (ValueError, KeyError, TypeError, RuntimeError) as err:
        detail = f"missing {err}" if isinstance(err, KeyError) else " ".join(str(err).split())
        detail = detail.removeprefix("invalid config value ")
        raise RunFolderError(directory, f"{file}: {where}: {detail[:200]}") from None


def restore_arrays(directory: Path, file: str, loader: Callable[[Any], None], saved: Any) -> None:
    """``loader(saved)`` of a checkpoint's arrays (an environments' state), in one line.

    Raises:
        RunFolderError: ``loader`` refused them (ValueError, KeyError, TypeError): one
            line naming ``file`` and the array.
    """
    try:
        loader(saved)
    except (ValueError, KeyError, TypeError) as err:
        detail = f"{err}: missing" if isinstance(err, KeyError) else " ".join(str(err).split())
        raise RunFolderError(directory, f"{file}: {detail[:200]}") from None
