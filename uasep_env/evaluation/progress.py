"""Progress of a long evaluation on stderr: tqdm when installed, else one plain line.

Shown when stderr is a terminal or when asked (``uasep-eval --progress``), never with
``--quiet``; stdout (the summary, ``--json -`` style output) is never written to.
"""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

__all__ = ["LineProgress", "progress_bar"]


class LineProgress:
    """A minimal progress line: ``uasep-eval: 3/8 episodes (12 s)``, without tqdm.

    On a terminal the line is rewritten in place; elsewhere (a log file) each update is a
    line of its own.

    Args:
        total: Episodes to play.
        stream: Where to write (stderr).
        desc: The line's prefix.
    """

    def __init__(self, total: int, stream: TextIO | None = None, desc: str = "uasep-eval") -> None:
        self.total, self.n, self.desc = total, 0, desc
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self._write()

    def _write(self) -> None:
        elapsed = time.perf_counter() - self.t0
        text = f"{self.desc}: {self.n}/{self.total} episodes ({elapsed:.0f} s)"
        self.stream.write(f"\r{text}" if self.tty else f"{text}\n")
        self.stream.flush()

    def update(self, n: int = 1) -> None:
        """``n`` more episodes finished."""
        self.n += n
        self._write()

    def close(self) -> None:
        """End the line (on a terminal)."""
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def progress_bar(total: int, quiet: bool, force: bool = False) -> Any:
    """A progress display on stderr: tqdm's bar when installed, else a :class:`LineProgress`.

    None with ``quiet``, or when stderr is not a terminal unless ``force``.
    """
    if quiet or not (force or sys.stderr.isatty()):
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # a core install: no extra needed for feedback
        return LineProgress(total)
    return tqdm(total=total, unit="ep", desc="uasep-eval", file=sys.stderr, leave=False)
