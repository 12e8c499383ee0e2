"""Write the result tables of the README and the docs pages from the results files.

The results files are ``baselines/results/*.md``; the pages are ``README.md`` and every
``docs/*.md`` (:data:`PAGES`).

A source with a ``/`` is a path from the repository's root (the trade-off tables:
``docs/figures/tradeoff.md``).

Each table in a page stands between two markers naming its source: a results file and
the heading of its section there (the first table after that heading is taken)::

    <!-- results summary.md "Paper scenario" pretty -->
    | metric | ... |
    <!-- /results -->

The table of scenario families stands between ``<!-- scenarios -->`` and
``<!-- /scenarios -->``; it is written from the scenario registry
(:data:`uasep_env.scenarios.FAMILIES`: each family's summary, parameters and gym id).

The table of registered controllers stands between ``<!-- controllers -->`` and
``<!-- /controllers -->``; it is written from the policy registry
(:data:`uasep_env.policies.REGISTRY`).

``list`` takes the bullet list after the heading instead of a table (the leaderboard's
verdict sentences, ``<!-- results bench/bench.md "Verdict" list -->``): sentences computed
from the numbers, so a page cannot quote a verdict the results do not give.

``pretty`` writes the controllers as the README names them (``APF (proposed)``, ...) and
units with superscripts (``m/s²``). The tables are re-laid out by
:func:`uasep_env.runtime.tables.render_table`, so the pages say exactly what the results say.

    python tools/sync_readme.py          # rewrite README.md and docs/*.md
    python tools/sync_readme.py --check  # exit 1 if one of them is out of date
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from uasep_env.policies import REGISTRY
from uasep_env.registration import ENV_VERSION
from uasep_env.runtime.atomic import atomic_write
from uasep_env.runtime.tables import render_table
from uasep_env.scenarios import FAMILIES

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "baselines" / "results"


def pages() -> list[Path]:
    """The pages whose marked tables are generated: the README and the docs pages."""
    return [README, *sorted((ROOT / "docs").glob("*.md"))]


#: The README's names of the controllers (``pretty`` tables): the registry's labels.
README_LABELS = {name: e.label for name, e in REGISTRY.items() if e.reference}
_UNITS = {"m/s^2": "m/s²", "m/s^3": "m/s³"}
_BLOCK = re.compile(
    r'(?P<open><!-- results (?P<file>\S+) "(?P<heading>[^"]+)"'
    r"(?P<pretty> pretty)?(?P<list> list)? -->\n)"
    r".*?(?P<close><!-- /results -->)",
    re.DOTALL,
)


_SCENARIOS = re.compile(
    r"(?P<open><!-- scenarios -->\n).*?(?P<close><!-- /scenarios -->)", re.DOTALL
)
_CONTROLLERS = re.compile(
    r"(?P<open><!-- controllers -->\n).*?(?P<close><!-- /controllers -->)", re.DOTALL
)


def controller_table() -> str:
    """The markdown table of the registered policies (:data:`uasep_env.policies.REGISTRY`)."""
    rows = []
    for name, e in REGISTRY.items():
        target = e.factory if isinstance(e.factory, type) else None
        cls = f"{{class}}`~{target.__module__}.{target.__qualname__}`" if target else "-"
        summary = e.summary.replace("``", "`")  # reST literals in docstrings
        rows.append([f"`{name}`", e.label, cls, "yes" if e.reference else "", summary])
    header = ["name", "label", "class", "reference", "what it is"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def scenario_table() -> str:
    """The markdown table of the registered scenario families."""
    rows = [
        [
            f"`{f.name}`",
            f.summary,
            f.parameters,
            f"`uasep/{f.gym_name}-v{ENV_VERSION}`" if f.gym_name else "",
        ]
        for f in FAMILIES.values()
    ]
    header = ["scenario", "encounter", "drawn per episode", "gym id"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _after_heading(text: str, heading: str) -> list[str]:
    """The lines after the first heading line (``#``) containing ``heading``.

    Raises:
        ValueError: If there is no such heading.
    """
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.startswith("#") and heading in ln), None)
    if start is None:
        raise ValueError(f"no heading with {heading!r}")
    return lines[start + 1 :]


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
    table: list[str] = []
    for ln in _after_heading(text, heading):
        if ln.startswith("|"):
            table.append(ln)
        elif table or ln.startswith("#"):
            break
    if len(table) < 2:
        raise ValueError(f"no table after the heading {heading!r}")
    return _cells(table[0]), [_cells(ln) for ln in table[2:]]


def section_list(text: str, heading: str) -> list[str]:
    """The bullet list (``* `` lines, with their continuation lines) after the heading.

    Raises:
        ValueError: If there is no such heading or no list after it.
    """
    items: list[str] = []
    for ln in _after_heading(text, heading):
        if ln.startswith("* "):
            items.append(ln)
        elif items and ln.startswith("  ") and ln.strip():
            items[-1] += "\n" + ln
        elif items or ln.startswith("#"):
            break
    if not items:
        raise ValueError(f"no list after the heading {heading!r}")
    return items


def _prettify(cell: str) -> str:
    cell = README_LABELS.get(cell, cell)
    for raw, nice in _UNITS.items():
        cell = cell.replace(raw, nice)
    return cell


def render_readme(readme: str, results: Path = RESULTS) -> str:
    """A page (the README or a docs page) with every marked table rewritten from its source.

    Args:
        readme: The page's text.
        results: Folder of the results files.

    Returns:
        The new text.
    """

    def block(m: re.Match[str]) -> str:
        # A bare name is a results file; a path (with "/") is relative to the repository.
        path = ROOT / m["file"] if "/" in m["file"] else results / m["file"]
        if m["list"]:
            return (
                m["open"]
                + "\n".join(section_list(path.read_text(), m["heading"]))
                + "\n"
                + m["close"]
            )
        header, rows = section_table(path.read_text(), m["heading"])
        if m["pretty"]:
            header = [_prettify(c) for c in header]
            rows = [[_prettify(c) for c in r] for r in rows]
        return m["open"] + render_table(header, rows, markdown=True) + "\n" + m["close"]

    readme = _SCENARIOS.sub(
        lambda m: m["open"] + scenario_table() + "\n" + m["close"], _BLOCK.sub(block, readme)
    )
    return _CONTROLLERS.sub(lambda m: m["open"] + controller_table() + "\n" + m["close"], readme)


def main(argv: list[str] | None = None) -> int:
    """Rewrite the pages' tables (or, with ``--check``, say whether they are up to date)."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--check", action="store_true", help="exit 1 if a page is out of date")
    args = p.parse_args(argv)
    stale = []
    for page in pages():
        old = page.read_text()
        new = render_readme(old)
        if new == old:
            continue
        stale.append(page)
        if not args.check:
            atomic_write(page, new)
            print(f"rewrote the result tables of {page.relative_to(ROOT)}")
    if args.check and stale:
        names = ", ".join(str(page.relative_to(ROOT)) for page in stale)
        print(f"result tables differ from the results files in {names}: run "
              "python tools/sync_readme.py", file=sys.stderr)  # fmt: skip
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
