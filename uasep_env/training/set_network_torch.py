"""The permutation-invariant network in torch: the lean loop's ``--arch set`` actor and critic.

The network of :mod:`uasep_env.policies.set_network` (which runs it in numpy from a
checkpoint and defines its tensors): own features and each neighbour slot encoded, the
present slots pooled by one attention head per type from the own embedding, a head MLP.
:class:`SetBody` is everything but the last layer, so the lean loop's ``mu(pi(x))`` and
``v(vf(x))`` read it as they read an MLP body. Its linear layers are named and ordered as
:func:`~uasep_env.policies.set_network.tensor_shapes` declares them, the order the
checkpoint stores.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from uasep_env.policies.set_network import NEIGHBOURS, split_layout, tensor_shapes

__all__ = ["SetBody", "set_body"]


def set_body(layout: Any, sizes: list[int], act: type, out: int) -> tuple[Any, Any]:
    """``(body, last)``: a :class:`SetBody` and its last linear layer (``out`` wide)."""
    body = SetBody(layout, sizes, act)
    return body, body.last(out)


class SetBody(torch.nn.Module):
    """Own and neighbour encoders, attention pooling and the head's hidden layers.

    Args:
        layout: The stored layout it reads
            (:class:`~uasep_env.policies.checkpoint.StoredLayout`).
        sizes: Hidden widths: the embedding's, then the head's.
        act: The activation's module class.
    """

    def __init__(self, layout: Any, sizes: list[int], act: type) -> None:
        super().__init__()
        self.split = split_layout(layout)
        self.shapes = tensor_shapes(layout, sizes)
        self.d = int(sizes[0])
        # Every linear layer but the head's last, by name ("." is not allowed in a key).
        self.layers = torch.nn.ModuleDict({
            name.replace(".", "_"): torch.nn.Linear(n_in, n_out)
            for name, (n_out, n_in) in list(self.shapes.items())[:-1]
        })  # fmt: skip
        self.act = act()
        self.n_head = sum(n.startswith("head") for n in self.shapes)
        self.register_buffer(
            "own_cols", torch.tensor(self.split.own_cols, dtype=torch.long), persistent=False
        )

    def last(self, out: int) -> Any:
        """The head's last layer (the action mean: ``out`` 3; a value: ``out`` 1)."""
        _, n_in = self.shapes[f"head{self.n_head - 1}"]
        return torch.nn.Linear(n_in, out)

    def linears(self) -> list:
        """Its linear layers in the checkpoint's order (the last one not included)."""
        return [self.layers[name.replace(".", "_")] for name in list(self.shapes)[:-1]]

    def forward(self, x: Any) -> Any:
        """The head's last hidden features ``(rows, width)`` of normalised observations."""
        layers, act = self.layers, self.act
        e = act(layers["own"](x.index_select(-1, self.own_cols)))
        parts = [e]
        for kind in NEIGHBOURS:
            s = self.split.slots[kind]
            block = x[:, s.start : s.start + s.k * s.width].reshape(len(x), s.k, s.width)
            present = block[:, :, s.mask] > 0.5
            h = act(layers[f"{kind}_encoder"](block))
            q = layers[f"{kind}_query"](e)
            keys, values = layers[f"{kind}_key"](h), layers[f"{kind}_value"](h)
            score = (q.unsqueeze(1) * keys).sum(-1) / math.sqrt(self.d)
            # Absent slots weigh 0; a row with none pools 0 (its softmax is uniform, masked).
            weight = torch.softmax(score.masked_fill(~present, -1e30), dim=-1) * present
            parts.append((weight.unsqueeze(-1) * values).sum(1))
        h = torch.cat(parts, dim=-1)
        for i in range(self.n_head - 1):
            h = act(layers[f"head{i}"](h))
        return h
