"""Write the README's result tables from the results files (``baselines/results/*.md``).

A source with a ``/`` is a path from the repository's root (the trade-off tables:
``docs/figures/tradeoff.md``).

Each table in the README stands between two markers naming its source: a results file and
the heading of its section there (the first table after that heading is taken)::

    <!-- results summary.md "Paper scenario" pretty -->
    | metric | ... |
    <!-- /results -->

``pretty`` writes the controllers as the README names them (``APF (proposed)``, ...) and
units with superscripts (``m/s²``). The tables are re-laid out by
:func:`uasep_env.tables.render_table`, so the README says exactly what the results say.

    python tools/sync_readme.py          # rewrite README.md
    python tools/sync_readme.py --check  # exit 1 if README.md is out of date
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from uasep_env.atomic import atomic_write
from uasep_env.tables import render_table

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "baselines" / "results"

#: The README's names of the controllers (``pretty`` tables).
README_LABELS = {
    "apf": "APF (proposed)",
    "motion-state-apf": "motion-state APF",
    "traditional-apf": "traditional APF",
}
_UNITS = {"m/s^2": "m/s²", "m/s^3": "m/s³"}
_BLOCK = re.compile(
    r'(?P<open><!-- results (?P<file>\S+) "(?P<heading>[^"]+)"(?P<pretty> pretty)? -->\n)'
    r".*?(?P<close><!-- /results -->)",
    re.DOTALL,
)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def section_table(text: str, heading: str) -> tuple[list[str], list[list[str]]]:
    """The first markdown table after the heading line containing ``heading``.

    Args:
        text: A results file's markdown.
        heading: Text of the section's heading (``#`` lines).

    Returns:
        ``(header, rows)`` as text cells.

    Raises:
        ValueError: If there is no such heading or no table after it.
    """
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.startswith("#") and heading in ln), None)
    if start is None:
        raise ValueError(f"no heading with {heading!r}")
    table: list[str] = []
    for ln in lines[start + 1 :]:
        if ln.startswith("|"):
            table.append(ln)
        elif table or ln.startswith("#"):
            break
    if len(table) < 2:
        raise ValueError(f"no table after the heading {heading!r}")
    return _cells(table[0]), [_cells(ln) for ln in table[2:]]


def _prettify(cell: str) -> str:
    cell = README_LABELS.get(cell, cell)
    for raw, nice in _UNITS.items():
        cell = cell.replace(raw, nice)
    return cell


def render_readme(readme: str, results: Path = RESULTS) -> str:
    """The README with every marked table rewritten from its results file.

    Args:
        readme: The README's text.
        results: Folder of the results files.

    Returns:
        The new text.
    """

    def block(m: re.Match[str]) -> str:
        # A bare name is a results file; a path (with "/") is relative to the repository.
        path = ROOT / m["file"] if "/" in m["file"] else results / m["file"]
        header, rows = section_table(path.read_text(), m["heading"])
        if m["pretty"]:
            header = [_prettify(c) for c in header]
            rows = [[_prettify(c) for c in r] for r in rows]
        return m["open"] + render_table(header, rows, markdown=True) + "\n" + m["close"]

    return _BLOCK.sub(block, readme)


def main(argv: list[str] | None = None) -> int:
    """Rewrite README.md (or, with ``--check``, say whether it is up to date)."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--check", action="store_true", help="exit 1 if README.md is out of date")
    args = p.parse_args(argv)
    old = README.read_text()
    new = render_readme(old)
    if args.check:
        if new != old:
            print("README.md's result tables differ from baselines/results: run "
                  "python tools/sync_readme.py", file=sys.stderr)  # fmt: skip
            return 1
        return 0
    if new != old:
        atomic_write(README, new)
        print(f"rewrote the result tables of {README}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
