"""The permutation-invariant (``"set"``) actor of a policy checkpoint: its tensors, numpy forward.

A slot MLP reads the K nearest UAVs and obstacles in fixed slots, so its weights are tied to
K and to the slots' order. The set network (DeepSets with attention, as InforMARL and GCBF+
read their neighbours) reads them as sets:

* the own features (the ``self`` block, and ``base_action`` in ``residual_apf``) go through
  a linear layer and the activation: the own embedding ``e`` (width ``d = hidden[0]``);
* every observed UAV's block goes through one shared encoder (a linear layer and the
  activation), every observed obstacle's through another; slots whose presence mask is 0
  (unobserved, padding) are left out;
* per type, one attention head pools the encoded neighbours: the query ``Wq e``, keys and
  values ``Wk h_j``, ``Wv h_j``, weights ``softmax_j(q . k_j / sqrt(d))`` over the present
  slots (no present slot: the pooled vector is 0);
* a head MLP (widths ``hidden[1:]``, then 3) reads ``[e, pooled UAVs, pooled obstacles]``.

The weights do not depend on K, so a checkpoint trained with ``k_uavs=2`` acts with any
``observation.k_uavs`` (the slot MLP refuses another K). The observation normalisation is
shared by the slots of a type (one mean and variance per slot feature, the same in every
slot; :func:`tied_moments` keeps it so while training) and leaves the masks as they are
(mean 0, variance 1), so it too fits any K.

A checkpoint declares ``"architecture": "set"``; its tensors and their shapes follow from its
stored observation layout and ``hidden`` (:func:`tensor_shapes`): ``own``, then per type
``<type>.encoder``, ``<type>.query``, ``<type>.key``, ``<type>.value``, then ``head<i>``,
each a ``.weight`` and a ``.bias``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "ARCHITECTURES",
    "NEIGHBOURS",
    "SetLayout",
    "SetNetwork",
    "set_difference",
    "slot_padding",
    "split_layout",
    "tensor_shapes",
    "tied_moments",
]

#: What a checkpoint's ``architecture`` may say (``"mlp"`` for files that do not say).
ARCHITECTURES = ("mlp", "set")
#: The neighbour types, in the order the set network pools them.
NEIGHBOURS = ("uav", "obstacle")
_SLOT = re.compile(r"^(uav|obstacle)(\d+)\.(.+)$")


@dataclass(frozen=True, kw_only=True)
class Slots:
    """One neighbour type's slots in the vector.

    Attributes:
        start: The first slot's first column.
        k: Slots.
        features: ``(name, width)`` of one slot's features (empty when ``k`` is 0).
    """

    start: int
    k: int
    features: tuple[tuple[str, int], ...]

    @property
    def width(self) -> int:
        """Columns of one slot."""
        return sum(w for _, w in self.features)

    @property
    def mask(self) -> int:
        """The presence mask's column within a slot (-1 without one)."""
        col = 0
        for name, w in self.features:
            if name == "mask":
                return col
            col += w
        return -1


@dataclass(frozen=True, kw_only=True)
class SetLayout:
    """A stored observation layout split into own features and neighbour slots.

    Attributes:
        own_cols: The own features' columns (the ``self`` block, ``base_action``).
        own_features: Their ``(name, width)``, in order.
        slots: Per neighbour type, its :class:`Slots`.
        dim: Width of the vector.
    """

    own_cols: tuple[int, ...]
    own_features: tuple[tuple[str, int], ...]
    slots: dict[str, Slots]
    dim: int


def split_layout(layout: Any) -> SetLayout:
    """Split a :class:`~uasep_env.policies.checkpoint.StoredLayout` into own features and slots.

    Raises:
        ValueError: If the neighbour slots are not contiguous, numbered in order, alike.
    """
    own_cols: list[int] = []
    own: list[tuple[str, int]] = []
    per: dict[str, list[list[tuple[str, int]]]] = {t: [] for t in NEIGHBOURS}
    start: dict[str, int] = {}
    col = 0
    for name, width in layout.features:
        m = _SLOT.match(name)
        if m is None:
            own_cols += range(col, col + width)
            own.append((name, width))
        else:
            kind, j = m.group(1), int(m.group(2))
            blocks = per[kind]
            if j == len(blocks):
                if blocks and start[kind] + j * _width(blocks[0]) != col:
                    raise ValueError(f"layout: {kind} slots are not contiguous at {name!r}")
                start.setdefault(kind, col)
                blocks.append([])
            elif j != len(blocks) - 1:
                raise ValueError(f"layout: {name!r} out of slot order")
            blocks[-1].append((m.group(3), width))
        col += width
    slots = {}
    for kind in NEIGHBOURS:
        blocks = per[kind]
        k = getattr(layout, f"k_{kind}s")
        if len(blocks) != k or any(b != blocks[0] for b in blocks):
            raise ValueError(f"layout: {len(blocks)} {kind} slots, not {k} alike ones")
        slots[kind] = Slots(
            start=start.get(kind, col), k=k, features=tuple(blocks[0]) if blocks else ()
        )
    return SetLayout(own_cols=tuple(own_cols), own_features=tuple(own), slots=slots, dim=col)


def _width(block: list[tuple[str, int]]) -> int:
    return sum(w for _, w in block)


def slot_padding(small: SetLayout, full: SetLayout) -> np.ndarray:
    """Where each column of ``full`` comes from in ``small`` (-1: a padded, absent slot).

    A formation of fewer UAVs than ``k_uavs + 1`` observes fewer UAV slots; its observation
    padded to ``full`` has the same own features and first slots, and zeros (masks 0: left
    out by the set network) in the slots past its own.

    Raises:
        ValueError: The own features or a type's slot features differ, or ``small`` has
            more slots of a type than ``full``.
    """
    if small.own_features != full.own_features:
        raise ValueError("slot padding: the own features differ")
    src = np.full(full.dim, -1, dtype=np.int64)
    src[list(full.own_cols)] = small.own_cols
    for kind, f in full.slots.items():
        s = small.slots[kind]
        if s.k > f.k or (s.k and s.features != f.features):
            raise ValueError(f"slot padding: {s.k} {kind} slots do not pad to {f.k}")
        src[f.start : f.start + s.k * s.width] = np.arange(s.start, s.start + s.k * s.width)
    return src


def tensor_shapes(layout: Any, hidden: Sequence[int]) -> dict[str, tuple[int, int]]:
    """The set network's linear layers, in order: name -> ``(out, in)`` (:mod:`this module`).

    Args:
        layout: The stored layout it was trained on (every neighbour type observed at least
            once, so that a slot's width is known).
        hidden: ``hidden[0]`` is the embedding width, ``hidden[1:]`` the head's hidden widths.

    Raises:
        ValueError: No hidden width, a type with no slot or no presence mask.
    """
    if not hidden:
        raise ValueError("a set network needs at least one hidden width (the embedding's)")
    split = split_layout(layout)
    d = int(hidden[0])
    shapes: dict[str, tuple[int, int]] = {"own": (d, len(split.own_cols))}
    for kind in NEIGHBOURS:
        s = split.slots[kind]
        if s.k == 0 or s.mask < 0:
            raise ValueError(
                f"a set network needs its {kind} slots' features and mask: the layout has "
                f"k_{kind}s={s.k}"
            )
        shapes[f"{kind}.encoder"] = (d, s.width)
        for part in ("query", "key", "value"):
            shapes[f"{kind}.{part}"] = (d, d)
    sizes = [d * (1 + len(NEIGHBOURS)), *map(int, hidden[1:]), 3]
    for i in range(len(sizes) - 1):
        shapes[f"head{i}"] = (sizes[i + 1], sizes[i])
    return shapes


def set_difference(mine: Any, env: Any) -> str | None:
    """What first keeps a set network trained on layout ``mine`` from reading ``env``'s, or None.

    The own features must be the same; each neighbour type's slot features too (any number
    of slots, none included).
    """
    a, b = split_layout(mine), split_layout(env)
    if a.own_features != b.own_features:
        return (
            f"own features: the network reads {[n for n, _ in a.own_features]}, this env "
            f"gives {[n for n, _ in b.own_features]}"
        )
    for kind in NEIGHBOURS:
        theirs = b.slots[kind]
        if theirs.k and theirs.features != a.slots[kind].features:
            return (
                f"{kind} slot features: the network reads {list(a.slots[kind].features)}, "
                f"this env gives {list(theirs.features)}"
            )
    return None


def tied_moments(
    split: SetLayout, obs: np.ndarray, mean: np.ndarray, var: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A batch's per-column moments with every slot of a type given the same ones.

    Own columns: their own mean and variance over the batch. A type's slot columns: the mean
    and variance of that slot feature over the present slots of the batch (the current
    ``mean``/``var`` of its first slot when none is present: no change), the same in every
    slot; the masks: mean 0, variance 1 (left as they are by the normalisation).

    Args:
        split: The layout.
        obs: ``(rows, dim)`` raw observations.
        mean: The running mean ``(dim,)`` (slot-tied).
        var: The running variance ``(dim,)``.

    Returns:
        ``(batch_mean, batch_var)``, each ``(dim,)``, for ``update_from_moments``.
    """
    obs = np.asarray(obs, dtype=np.float64)
    bm, bv = np.mean(obs, axis=0), np.var(obs, axis=0)
    for s in split.slots.values():
        if s.k == 0:
            continue
        stop = s.start + s.k * s.width
        block = obs[:, s.start : stop].reshape(-1, s.width)
        present = block[block[:, s.mask] > 0.5]
        if len(present):
            m, v = present.mean(axis=0), present.var(axis=0)
        else:
            m, v = mean[s.start : s.start + s.width], var[s.start : s.start + s.width]
        m, v = np.array(m), np.array(v)
        m[s.mask], v[s.mask] = 0.0, 1.0
        bm[s.start : stop], bv[s.start : stop] = np.tile(m, s.k), np.tile(v, s.k)
    return bm, bv


def untied(split: SetLayout, mean: np.ndarray, var: np.ndarray) -> str | None:
    """Where normalisation statistics ``mean``/``var`` are not slot-tied (or None)."""
    for kind, s in split.slots.items():
        first = slice(s.start, s.start + s.width)
        if s.k and (mean[s.start + s.mask] != 0.0 or var[s.start + s.mask] != 1.0):
            return f"{kind}0.mask is normalised (a set network reads masks as they are)"
        for j in range(1, s.k):
            at = slice(s.start + j * s.width, s.start + (j + 1) * s.width)
            if not (np.array_equal(mean[at], mean[first]) and np.array_equal(var[at], var[first])):
                return f"slot {kind}{j}'s statistics differ from {kind}0's"
    return None


class SetNetwork:
    """The set actor in numpy (float64 sums, as :func:`~.checkpoint_policy.dense`), for one env.

    Args:
        trained: The stored layout it was trained on.
        env: The layout of the env it acts in (any K; :func:`set_difference` is None).
        hidden: The checkpoint's hidden widths.
        activation: The activation function.
        dense: One layer ``dense(x, W.T, b)`` (:func:`~.checkpoint_policy.dense`: float64
            sums in one order, rounded to float32), as the MLP's.
        weights: ``[(W, b), ...]`` in :func:`tensor_shapes`' order.
        obs_mean: The slot-tied mean of the trained layout (None: no normalisation).
        obs_var: Its variance.
        epsilon: Added to the variance.
        clip: Bound of the normalised observation.
    """

    def __init__(
        self,
        trained: Any,
        env: Any,
        hidden: Sequence[int],
        activation: Any,
        dense: Any,
        weights: Sequence[tuple[np.ndarray, np.ndarray]],
        obs_mean: np.ndarray | None,
        obs_var: np.ndarray | None,
        epsilon: float,
        clip: float,
    ) -> None:
        self._dense, self._act = dense, activation
        names = list(tensor_shapes(trained, hidden))
        self._w = {
            n: (np.ascontiguousarray(np.asarray(w, np.float32).T, dtype=np.float64),
                np.asarray(b, np.float32).astype(np.float64))
            for n, (w, b) in zip(names, weights, strict=True)
        }  # fmt: skip
        self._n_head = sum(n.startswith("head") for n in names)
        self._d = int(hidden[0])
        t, self.env = split_layout(trained), split_layout(env)
        self._clip = clip
        self._norm = obs_mean is not None
        if self._norm:
            # The trained layout's statistics placed in the env's: own columns as they are,
            # one slot's statistics in every slot of the env.
            mean, std = np.zeros(self.env.dim), np.ones(self.env.dim)
            t_std = np.sqrt(np.asarray(obs_var, np.float64) + epsilon)
            t_mean = np.asarray(obs_mean, np.float64)
            mean[list(self.env.own_cols)] = t_mean[list(t.own_cols)]
            std[list(self.env.own_cols)] = t_std[list(t.own_cols)]
            for kind, s in self.env.slots.items():
                first = slice(t.slots[kind].start, t.slots[kind].start + s.width)
                at = slice(s.start, s.start + s.k * s.width)
                mean[at], std[at] = np.tile(t_mean[first], s.k), np.tile(t_std[first], s.k)
            self._mean, self._std = mean, std

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The deterministic action ``(rows, 3)`` float32 for raw observations ``(rows, dim)``."""
        x = np.asarray(obs, dtype=np.float32)
        if self._norm:
            x = np.clip((x - self._mean) / self._std, -self._clip, self._clip).astype(np.float32)
        rows = len(x)
        own = np.ascontiguousarray(x[:, list(self.env.own_cols)])
        e = self._act(self._dense(own, *self._w["own"]))
        parts = [e]
        for kind in NEIGHBOURS:
            parts.append(self._pool(kind, x, e, rows))
        h = np.concatenate(parts, axis=1)
        for i in range(self._n_head - 1):
            h = self._act(self._dense(h, *self._w[f"head{i}"]))
        return self._dense(h, *self._w[f"head{self._n_head - 1}"])

    def _pool(self, kind: str, x: np.ndarray, e: np.ndarray, rows: int) -> np.ndarray:
        """One type's attention-pooled neighbours ``(rows, d)`` float32 (0 without any)."""
        s, d, dense = self.env.slots[kind], self._d, self._dense
        if s.k == 0:
            return np.zeros((rows, d), np.float32)
        block = x[:, s.start : s.start + s.k * s.width].reshape(rows * s.k, s.width)
        present = (block[:, s.mask] > 0.5).reshape(rows, s.k)
        h = self._act(dense(np.ascontiguousarray(block), *self._w[f"{kind}.encoder"]))
        q = dense(e, *self._w[f"{kind}.query"]).astype(np.float64)
        keys = dense(h, *self._w[f"{kind}.key"]).astype(np.float64).reshape(rows, s.k, d)
        values = dense(h, *self._w[f"{kind}.value"]).astype(np.float64).reshape(rows, s.k, d)
        # Sums in one fixed order (component by component), as dense's.
        score = np.zeros((rows, s.k))
        for c in range(d):
            score += q[:, c, None] * keys[:, :, c]
        score = np.where(present, score / math.sqrt(d), -np.inf)
        top = score.max(axis=1, keepdims=True)
        top[~np.isfinite(top)] = 0.0  # no neighbour present: every weight 0
        weight = np.exp(score - top)
        total = np.zeros((rows, 1))
        for j in range(s.k):
            total[:, 0] += weight[:, j]
        weight = weight / np.where(total > 0.0, total, 1.0)
        pooled = np.zeros((rows, d))
        for j in range(s.k):
            pooled += weight[:, j, None] * values[:, j]
        return pooled.astype(np.float32)
