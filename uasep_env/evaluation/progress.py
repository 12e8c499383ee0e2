"""Progress of a long evaluation on stderr: tqdm when installed, else one plain line.

Shown when stderr is a terminal or when asked (``uasep-eval --progress``), never with
``--quiet``; stdout (the summary) is never written to. Episodes finish a chunk (a batched
simulator) at a time, so on a terminal the display is also redrawn every few seconds
(:class:`Heartbeat`): its elapsed time shows the work goes on between chunks.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, TextIO

__all__ = ["Heartbeat", "LineProgress", "progress_bar"]

#: Seconds between redraws of a terminal's progress display while no chunk finishes.
HEARTBEAT_S = 2.0


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

    def refresh(self) -> None:
        """Redraw (on a terminal only: a log gets a line per finished chunk)."""
        if self.tty:
            self._write()

    def close(self) -> None:
        """End the line (on a terminal)."""
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


class Heartbeat:
    """A progress display whose ``refresh()`` a daemon thread calls every ``interval`` s.

    ``update`` and ``close`` are the display's (``close`` stops the thread first).

    Args:
        bar: A tqdm bar or a :class:`LineProgress`.
        interval: Seconds between redraws.
    """

    def __init__(self, bar: Any, interval: float = HEARTBEAT_S) -> None:
        self.bar = bar
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, args=(interval,), daemon=True)
        self._thread.start()

    def _beat(self, interval: float) -> None:
        while not self._stop.wait(interval):
            with self._lock:
                self.bar.refresh()

    def update(self, n: int = 1) -> None:
        """``n`` more episodes finished."""
        with self._lock:
            self.bar.update(n)

    def close(self) -> None:
        """Stop redrawing and close the display."""
        self._stop.set()
        self._thread.join()
        self.bar.close()


def progress_bar(total: int, quiet: bool, force: bool = False) -> Any:
    """A progress display on stderr: tqdm's bar when installed, else a :class:`LineProgress`.

    None with ``quiet``, or when stderr is not a terminal unless ``force``.
    """
    tty = sys.stderr.isatty()
    if quiet or not (force or tty):
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # a core install: no extra needed for feedback
        bar: Any = LineProgress(total)
    else:
        bar = tqdm(total=total, unit="ep", desc="uasep-eval", file=sys.stderr, leave=False)
    return Heartbeat(bar) if tty else bar
