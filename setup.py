"""Build steps pyproject.toml cannot declare (everything else is in pyproject.toml).

* The shipped policies: ``baselines/checkpoints/*.zip`` (the source, where training writes
  them) are copied into the wheel as ``uasep_env/checkpoints/*.zip`` when the wheel is built,
  so the installed package resolves them by name and the copy cannot drift from the repo.
  A source checkout (and an editable install) reads them from ``baselines/checkpoints/``.
* The long description: the README with its relative links and images made absolute, so
  that they work on the package index's page (on GitHub and in the docs they stay relative),
  and without its opening block of a clone's ``make`` commands: the index's page opens with
  installing the package (``pip install``), the README's next section.
"""

from __future__ import annotations

import re
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
CHECKPOINTS = Path("baselines") / "checkpoints"
REPO = "https://github.com/uasep/uasep-env"
BLOB = f"{REPO}/blob/main/"
RAW = "https://raw.githubusercontent.com/uasep/uasep-env/main/"
# ![alt](target) or [text](target) whose target is not a URL, an anchor or an e-mail.
_LINK = re.compile(r"(!?)\[((?:[^\[\]]|\[[^\]]*\])*)\]\((?!https?://|#|mailto:)([^)\s]+)\)")


def absolute_links(markdown: str) -> str:
    """Relative Markdown links -> the repository's pages, images -> their raw files."""

    def repl(m: re.Match) -> str:
        bang, text, target = m.groups()
        target = target.removeprefix("./")
        return f"{bang}[{text}]({(RAW if bang else BLOB) + target})"

    return _LINK.sub(repl, markdown)


# The README's opening: its title, then the clone's set-up block (make eval / make test).
_CLONE_SETUP = re.compile(r"\A(# [^\n]+\n\n)```bash\n(?:make [^\n]*\n)+```\n\n")


def index_readme(markdown: str) -> str:
    """The README as the package index shows it: no clone set-up block, absolute links.

    Raises:
        ValueError: The README does not open with its title and the clone's ``make`` block
            (the page would open with something unchecked).
    """
    page, n = _CLONE_SETUP.subn(r"\1", markdown)
    if n != 1:
        raise ValueError("README.md does not open with its title and the make eval/test block")
    return absolute_links(page)


class BuildPyWithCheckpoints(build_py):
    """``build_py`` that also puts the shipped policy checkpoints into the package."""

    def run(self) -> None:
        """Build the package, then copy ``baselines/checkpoints/*.zip`` into it."""
        super().run()
        source = HERE / CHECKPOINTS
        zips = sorted(source.glob("*.zip"))
        if not zips:
            raise FileNotFoundError(f"no shipped policies in {source} (the wheel needs them)")
        target = Path(self.build_lib) / "uasep_env" / "checkpoints"
        self.mkpath(str(target))
        for src in zips:
            self.copy_file(str(src), str(target / src.name))


if __name__ == "__main__":
    setup(
        cmdclass={"build_py": BuildPyWithCheckpoints},
        long_description=index_readme((HERE / "README.md").read_text(encoding="utf-8")),
        long_description_content_type="text/markdown",
    )
