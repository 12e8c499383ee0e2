"""The one table renderer (on ``tabulate``): plain-text tables for terminals, markdown for files.

Callers format their cells as text first (so every table says numbers the way its caller
chose) and pick each column's alignment; this module only lays the cells out.
"""

from __future__ import annotations

from collections.abc import Sequence

from tabulate import tabulate

__all__ = ["render_table"]


def render_table(
    headers: Sequence[str],
    rows: Sequence[Sequence[str]],
    *,
    align: Sequence[str] | None = None,
    markdown: bool = False,
) -> str:
    """Lay out a table of text cells.

    Args:
        headers: Column headers.
        rows: Rows of text cells, each as long as ``headers``.
        align: Per-column ``"left"`` / ``"right"``; None: all left.
        markdown: A GitHub markdown table (``| a | b |``) instead of plain text (columns
            separated by two spaces, a dashed rule under the header).

    Returns:
        The table, without a trailing newline or trailing blanks.

    Raises:
        ValueError: If a row's length differs from the header's.

    Examples:
        >>> print(render_table(["policy", "collisions"], [["apf", "0.0%"]], markdown=True))
        | policy   | collisions   |
        |----------|--------------|
        | apf      | 0.0%         |
    """
    width = len(headers)
    for r in rows:
        if len(r) != width:
            raise ValueError(f"rows: a row has {len(r)} cells, the header has {width}")
    text = tabulate(
        [list(r) for r in rows],
        headers=list(headers),
        tablefmt="github" if markdown else "simple",
        disable_numparse=True,  # cells are already formatted: keep them as written
        colalign=tuple(align) if align is not None else None,
    )
    return "\n".join(line.rstrip() for line in text.splitlines())
