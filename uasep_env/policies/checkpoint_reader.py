"""Reading a policy checkpoint with hard limits: a hostile file is refused, never obeyed.

See :mod:`uasep_env.policies.checkpoint` for the format. Before a byte is decompressed the zip
directory is checked; the JSON's nesting depth is bounded before it is parsed; every field is
type- and range-checked; the network and the observation are bounded (:data:`LIMITS`); each
array's header is checked against the shape the description implies before its data is read.
Every failure is a :class:`~uasep_env.policies.checkpoint.CheckpointError` of one line.
"""

from __future__ import annotations

import io
import itertools
import json
import math
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.config.groups import ACTION_MODES
from uasep_env.policies.checkpoint import (
    ACTIVATIONS,
    CHECKPOINT_ALGORITHMS,
    CHECKPOINT_FORMAT,
    META,
    READABLE_FORMATS,
    WEIGHTS,
    CheckpointError,
    PolicyCheckpoint,
    StoredLayout,
)
from uasep_env.policies.set_network import (
    ARCHITECTURES,
    NEIGHBOURS,
    split_layout,
    tensor_shapes,
    untied,
)
from uasep_env.runtime.boundedzip import HOSTILE_FILE_ERRORS, check_members, read_member
from uasep_env.runtime.jsonio import DuplicateKeyError, json_depth, loads_unique

__all__ = ["LIMITS", "CheckpointLimits", "read_checkpoint"]


@dataclass(frozen=True, kw_only=True)
class CheckpointLimits:
    """Hard bounds applied while reading a checkpoint (a file beyond them is refused).

    Attributes:
        meta_bytes: Largest JSON description (uncompressed).
        weights_bytes: Largest ``weights.npz`` (uncompressed).
        ratio: Largest compression ratio of a member over 64 KiB (zeros deflate 1000:1).
        json_depth: Deepest nesting of the JSON.
        info_bytes: Largest ``info`` (training facts) as JSON text.
        obs_dim: Widest observation.
        width: Widest hidden layer.
        layers: Most hidden layers.
        parameters: Most network parameters (weights and biases).
        clip_obs: Range of ``clip_obs`` (a normalised observation clipped to 1e-300 is the
            same for every state: a constant policy).
    """

    meta_bytes: int = 256 * 1024
    weights_bytes: int = 32 * 1024 * 1024
    ratio: float = 50.0
    json_depth: int = 16
    info_bytes: int = 64 * 1024
    obs_dim: int = 4096
    width: int = 4096
    layers: int = 8
    parameters: int = 4_000_000
    clip_obs: tuple[float, float] = (1e-3, 1e6)


#: The limits :func:`read_checkpoint` applies.
LIMITS = CheckpointLimits()


_F32_MAX = float(np.finfo(np.float32).max)


def _fail(p: Path, message: str) -> CheckpointError:
    return CheckpointError(f"{p}: {message}")


def _members(
    p: Path, z: zipfile.ZipFile, expected: Mapping[str, int], limits: CheckpointLimits
) -> dict[str, zipfile.ZipInfo]:
    """Check a zip's directory: exactly ``expected`` (name -> largest size), nothing read."""
    try:
        return check_members(z, expected, limits.ratio)
    except ValueError as err:
        raise _fail(p, str(err)) from None


def _integer(p: Path, name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise _fail(p, f"{name} must be an integer in [{low}, {high}], got {_short(value)}")
    return value


def _real(p: Path, name: str, value: Any, low: float, high: float, low_open: bool) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok:
        value = float(value)
        ok = math.isfinite(value) and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise _fail(p, f"{name} must be a finite number in {bracket}{low:g}, {high:g}], "
                       f"got {_short(value)}")  # fmt: skip
    return value


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _layout(p: Path, value: Any, limits: CheckpointLimits) -> StoredLayout:
    if not isinstance(value, dict) or set(value) != {"k_uavs", "k_obstacles", "features"}:
        raise _fail(p, "layout must be {k_uavs, k_obstacles, features}")
    k_u = _integer(p, "layout.k_uavs", value["k_uavs"], 0, limits.obs_dim)
    k_o = _integer(p, "layout.k_obstacles", value["k_obstacles"], 0, limits.obs_dim)
    feats = value["features"]
    if not isinstance(feats, list) or not 0 < len(feats) <= limits.obs_dim:
        raise _fail(p, f"layout.features must be a list of at most {limits.obs_dim} features")
    out = []
    for k, f in enumerate(feats):
        if not (isinstance(f, list) and len(f) == 2 and isinstance(f[0], str) and 0 < len(f[0])
                <= 64):  # fmt: skip
            raise _fail(p, f"layout.features[{k}] must be [name, width], got {_short(f)}")
        out.append((f[0], _integer(p, f"layout.features[{k}] width", f[1], 1, limits.obs_dim)))
    return StoredLayout(k_uavs=k_u, k_obstacles=k_o, features=tuple(out))


_FIELDS = {
    "format", "config", "obs_dim", "activation", "hidden", "obs_norm", "clip_obs",
    "obs_epsilon", "algorithm", "info", "n_layers", "layout", "architecture",
}  # fmt: skip


def _description(p: Path, raw: bytes, limits: CheckpointLimits) -> tuple[PolicyCheckpoint, int]:
    """Parse and check the JSON description; returns it and its number of layers."""
    text = raw.decode("utf-8")
    depth = json_depth(text)
    if depth > limits.json_depth:
        raise _fail(p, f"{META} nests {depth} levels deep, limit {limits.json_depth}")
    try:
        desc = loads_unique(text)
    except DuplicateKeyError as err:
        raise _fail(p, f"{META}: {err} (which one would be obeyed?)") from None
    if not isinstance(desc, dict):
        raise _fail(p, f"{META} must hold an object, got {type(desc).__name__}")
    fmt = desc.get("format")
    if fmt not in READABLE_FORMATS:
        raise _fail(p, f"unknown checkpoint format {_short(fmt)}, expected {READABLE_FORMATS}")
    unknown = sorted(set(desc) - _FIELDS)
    if unknown or (fmt != CHECKPOINT_FORMAT and "layout" in desc):
        raise _fail(p, f"unknown field(s) {', '.join(map(_short, unknown or ['layout']))}")
    required = {"config", "obs_dim", "activation", "hidden", "obs_norm", "n_layers"}
    missing = sorted(required - set(desc))
    if fmt == CHECKPOINT_FORMAT and "layout" not in desc:
        missing.append("layout")
    if missing:
        raise _fail(p, f"missing field(s) {', '.join(missing)}")
    if not isinstance(desc["config"], dict):
        raise _fail(p, "config must be an object")
    hidden = desc["hidden"]
    if not isinstance(hidden, list) or len(hidden) > limits.layers:
        raise _fail(p, f"hidden must be a list of at most {limits.layers} widths")
    hidden = tuple(_integer(p, f"hidden[{k}]", h, 1, limits.width) for k, h in enumerate(hidden))
    obs_dim = _integer(p, "obs_dim", desc["obs_dim"], 1, limits.obs_dim)
    architecture = desc.get("architecture", "mlp")
    if architecture not in ARCHITECTURES:
        raise _fail(p, f"architecture must be one of {ARCHITECTURES}, got {_short(architecture)}")
    layout = _layout(p, desc["layout"], limits) if "layout" in desc else None
    if architecture == "set":
        if layout is None:
            raise _fail(p, "a set network's checkpoint must store its layout")
        try:
            shapes = list(tensor_shapes(layout, hidden).values())
        except ValueError as err:
            raise _fail(p, f"set network: {err}") from None
    else:
        sizes = [obs_dim, *hidden, 3]
        shapes = [(o, i) for i, o in itertools.pairwise(sizes)]
    params = sum(o * i + o for o, i in shapes)
    if params > limits.parameters:
        raise _fail(p, f"network of {params:,} parameters, limit {limits.parameters:,}")
    # A set network has its own, encoders' and attention's layers besides the head's.
    extra = 1 + 4 * len(NEIGHBOURS) if architecture == "set" else 0
    n_layers = _integer(p, "n_layers", desc["n_layers"], 1, limits.layers + 1 + extra)
    if desc["activation"] not in ACTIVATIONS:
        raise _fail(p, f"activation must be one of {ACTIVATIONS}, got {_short(desc['activation'])}")
    if not isinstance(desc["obs_norm"], bool):
        raise _fail(p, f"obs_norm must be true or false, got {_short(desc['obs_norm'])}")
    info = desc.get("info", {})
    if not isinstance(info, dict):
        raise _fail(p, "info must be an object")
    if len(json.dumps(info)) > limits.info_bytes:
        raise _fail(p, f"info is larger than {limits.info_bytes:,} bytes")
    if "env_version" in info:  # read as the env version it was trained in: an integer
        _integer(p, "info.env_version", info["env_version"], 0, 999)
    algorithm = desc.get("algorithm", "PPO")
    if algorithm not in CHECKPOINT_ALGORITHMS:
        raise _fail(p, f"algorithm must be one of {CHECKPOINT_ALGORITHMS}, got {_short(algorithm)}")
    meta = PolicyCheckpoint(
        config=desc["config"],
        obs_dim=obs_dim,
        activation=desc["activation"],
        hidden=hidden,
        obs_norm=desc["obs_norm"],
        clip_obs=_real(p, "clip_obs", desc.get("clip_obs", 10.0), *limits.clip_obs, False),
        obs_epsilon=_real(p, "obs_epsilon", desc.get("obs_epsilon", 1e-8), 0.0, 1e-2, True),
        algorithm=algorithm,
        info=info,
        format=fmt,
        layout=layout,
        architecture=architecture,
    )
    try:
        trained = meta.env_config
    except (TypeError, ValueError) as err:
        raise _fail(p, f"invalid checkpoint description (config: {err})") from err
    if layout is not None and layout.dim != obs_dim:
        raise _fail(p, f"layout is {layout.dim} wide, obs_dim says {obs_dim}")
    if trained.action.mode not in ACTION_MODES:  # pragma: no cover - config checks
        raise _fail(p, f"unknown action mode {trained.action.mode!r}")
    return meta, n_layers


def _array(p: Path, z: zipfile.ZipFile, info: zipfile.ZipInfo, shape: tuple[int, ...]) -> Any:
    """One ``.npy`` member: header checked (float, expected shape) before its data is read."""
    with z.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            got, fortran, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=1024)
        elif version == (2, 0):
            got, fortran, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=1024)
        else:
            raise _fail(p, f"{info.filename}: .npy version {version} refused")
        if dtype.kind != "f" or dtype.itemsize not in (4, 8) or dtype.hasobject:
            raise _fail(p, f"{info.filename}: {dtype} data, expected float32 or float64")
        if tuple(got) != shape:
            raise _fail(p, f"{info.filename}: shape {tuple(got)}, expected {shape}")
        n = int(np.prod(shape)) * dtype.itemsize
        data = fh.read(n + 1)
    if len(data) != n:
        raise _fail(p, f"{info.filename}: {len(data):,} data bytes, expected {n:,}")
    a = np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")
    if not np.isfinite(a).all():
        raise _fail(p, f"{info.filename}: non-finite values")
    # The policy computes in float32: a finite float64 beyond its range would become inf.
    if a.size and (big := float(np.abs(a).max())) > _F32_MAX:
        raise _fail(p, f"{info.filename}: value {big:.3g} beyond the float32 range")
    return a.astype(dtype.newbyteorder("="))


def _weights(
    p: Path, raw: bytes, meta: PolicyCheckpoint, n_layers: int, limits: CheckpointLimits
) -> tuple[list[tuple[np.ndarray, np.ndarray]], Any, Any]:
    if meta.architecture == "set":
        layers = tensor_shapes(meta.observation_layout, meta.hidden)
        if n_layers != len(layers):
            raise _fail(p, f"{n_layers} layers stored, the set network has {len(layers)}")
    else:
        sizes = [meta.obs_dim, *meta.hidden, 3]
        if n_layers != len(sizes) - 1:
            raise _fail(p, f"{n_layers} layers stored, the description says {sizes[1:]}")
        layers = {f"layer{k}": (sizes[k + 1], sizes[k]) for k in range(n_layers)}
    shapes: dict[str, tuple[int, ...]] = {}
    for name, (n_out, n_in) in layers.items():
        shapes[f"{name}.weight"] = (n_out, n_in)
        shapes[f"{name}.bias"] = (n_out,)
    if meta.obs_norm:
        shapes["obs_mean"] = shapes["obs_var"] = (meta.obs_dim,)
    # Each .npy member: a header (<= 1 KiB) and at most float64 data.
    expected = {f"{k}.npy": 1024 + 8 * int(np.prod(s)) for k, s in shapes.items()}
    with zipfile.ZipFile(io.BytesIO(raw)) as z:
        infos = _members(p, z, expected, limits)
        arrays = {k: _array(p, z, infos[f"{k}.npy"], s) for k, s in shapes.items()}
    weights = [(arrays[f"{name}.weight"], arrays[f"{name}.bias"]) for name in layers]
    mean = arrays.get("obs_mean")
    var = arrays.get("obs_var")
    if var is not None and (var < 0).any():
        raise _fail(p, "obs_var has negative entries")
    if meta.architecture == "set" and mean is not None:
        # Shared by the slots, or the network would not read its neighbours as a set.
        problem = untied(split_layout(meta.observation_layout), mean, var)
        if problem:
            raise _fail(p, f"obs_mean/obs_var: {problem}")
    return weights, mean, var


def read_checkpoint(
    path: str | Path, limits: CheckpointLimits = LIMITS
) -> tuple[PolicyCheckpoint, list[tuple[np.ndarray, np.ndarray]], Any, Any]:
    """Read and check a policy checkpoint.

    Args:
        path: The file.
        limits: The bounds applied (:data:`LIMITS`).

    Returns:
        ``(meta, [(W, b), ...], obs_mean, obs_var)``; the means are None without ``obs_norm``.

    Raises:
        CheckpointError: For anything that is not a valid checkpoint within ``limits``: one
            line naming the file and what is wrong.
    """
    p = Path(path)
    try:
        with zipfile.ZipFile(p) as z:
            bounds = {META: limits.meta_bytes, WEIGHTS: limits.weights_bytes}
            infos = _members(p, z, bounds, limits)
            text = read_member(z, infos[META], limits.meta_bytes)
            meta, n_layers = _description(p, text, limits)
            raw = read_member(z, infos[WEIGHTS], limits.weights_bytes)
        weights, mean, var = _weights(p, raw, meta, n_layers, limits)
    except CheckpointError:
        raise
    except FileNotFoundError as err:
        raise CheckpointError(f"no policy checkpoint at {p}") from err
    except HOSTILE_FILE_ERRORS as err:
        detail = " ".join(str(err).split())[:200] or "no detail"
        raise CheckpointError(
            f"{p} is not a valid uasep policy checkpoint ({type(err).__name__}: {detail})"
        ) from err
    return meta, weights, mean, var
