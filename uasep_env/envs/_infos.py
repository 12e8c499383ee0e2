"""Per-agent info dicts made from columns, with their keys written out once.

The views hand out one info dict per agent every step (the PettingZoo env's, the SB3
view's): at a training's batch sizes that is hundreds of dicts a step, and at one
environment a tenth of the step. A dict display with its keys written out
(``{"a": x, "b": y}``) costs half of ``dict(zip(names, row))``, so :func:`row_dicts`
writes the display once for a layout of keys, as ``collections.namedtuple`` writes its
class, and the views call the function it makes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

__all__ = ["Layout", "row_dicts"]

#: Keys in order: a name is a value of its own, ``(name, names)`` a nested dict of those
#: names.
Layout = Sequence["str | tuple[str, Sequence[str]]"]


def row_dicts(layout: Layout) -> Callable[..., list[dict]]:
    """A function that makes one dict per row from columns, in ``layout``'s key order.

    The function takes one sequence per value, in the layout's order (a nested dict's values
    in its names' order), all of one length, and returns the rows' dicts, each dict its
    own (nested ones too).

    Args:
        layout: The keys (see :data:`Layout`); names are written as string literals, so any
            text is a name.

    Returns:
        ``make(*columns) -> list[dict]``; it raises ``ValueError`` for columns of unequal
        lengths.

    Raises:
        TypeError: A layout entry that is neither a name nor ``(name, names)``.
    """
    args: list[str] = []

    def value() -> str:
        args.append(f"c{len(args)}")
        return args[-1]

    entries = []
    for entry in layout:
        if isinstance(entry, str):
            entries.append(f"{entry!r}: {value()}")
        elif isinstance(entry, tuple) and len(entry) == 2 and isinstance(entry[0], str):
            inner = ", ".join(f"{name!r}: {value()}" for name in entry[1])
            entries.append(f"{entry[0]!r}: {{{inner}}}")
        else:
            raise TypeError(f"a layout entry is a name or (name, names), got {entry!r}")
    listed = "".join(a + ", " for a in args)  # "c0, c1, " (a one-column row unpacks too)
    source = (
        f"def make({listed}):\n"
        f"    return [{{{', '.join(entries)}}}\n"
        f"            for {listed or '_, '}in zip({listed or '(), '}strict=True)]\n"
    )
    namespace: dict = {}
    exec(source, namespace)  # the source is made of the layout's names, as literals
    return namespace["make"]
