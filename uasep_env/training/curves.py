"""The learning curve every trainer writes the same way: ``progress.csv`` and ``curves.png``.

The columns (:data:`CSV_FIELDS`), one row per update appended durably (:class:`ProgressLog`:
flushed and ``fsync``-ed, so a kill tears at most the last line, which :func:`read_progress`
drops), the figures of the last finished episodes (:func:`window_summary`,
:func:`bar_postfix`) and the figure drawn at the end (:func:`plot_curves`). A run's folder
(:class:`~uasep_env.training.rundir.RunFolder`) opens and rewinds these files.

The training log on stdout is for people: one line a checkpoint (:func:`checkpoint_line`)
and one for the validation at the end (:func:`validation_line`), the summary figures only;
the episode windows a checkpoint keeps stay in its ``state.json`` and the whole summary in
``validation.json``.
"""

from __future__ import annotations

import csv
import io
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.runtime.atomic import atomic_output, atomic_write

__all__ = [
    "CSV_FIELDS",
    "FORMER_NAMES",
    "MIN_PLOTTED_EPISODES",
    "WINDOW_EPISODES",
    "ProgressLog",
    "bar_postfix",
    "checkpoint_line",
    "log_line",
    "plot_curves",
    "read_progress",
    "validation_line",
    "window_summary",
    "write_rows",
]


#: The largest CSV of a run folder read (a row is about 100 bytes: a million rows).
MAX_CSV_BYTES = 128 * 1024 * 1024


def read_progress(path: Path, root: Path | None = None) -> list[dict[str, str]]:
    """The rows of ``progress.csv`` (:func:`read_rows`, ``agent_steps`` whole numbers)."""
    return read_rows(path, root, whole="agent_steps")


def read_rows(
    path: Path, root: Path | None = None, whole: str | None = None
) -> list[dict[str, str]]:
    """The rows of a run's CSV; a torn last line (a kill mid-write) is dropped.

    With ``root`` (the run folder, when ``--resume`` reads it) the file is untrusted input:
    read through :func:`~uasep_env.runtime.runfiles.read_inside` (inside ``root``, a
    regular file, at most :data:`MAX_CSV_BYTES`), as UTF-8, and every kept row's
    column ``whole`` (``agent_steps`` for the learning curves), if named, must be a whole
    number.

    Raises:
        ValueError: A NUL byte or another CSV error, or (with ``root``) a refused entry,
            bytes that are not UTF-8, a bad ``whole`` column: one line naming the file.
    """
    if root is None:
        if not path.exists():
            return []
        text = path.read_text(encoding="utf-8", errors="replace")
    else:
        from uasep_env.runtime.runfiles import read_inside

        if not os.path.lexists(path):
            return []
        try:
            text = read_inside(root, path, MAX_CSV_BYTES).decode("utf-8")
        except UnicodeDecodeError as err:
            raise ValueError(f"{path}: not UTF-8 text (byte {err.start})") from None
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # the torn last row
    try:
        rows = list(csv.DictReader(io.StringIO(text)))
    except csv.Error as err:  # a NUL byte
        raise ValueError(f"{path}: not a CSV file ({err})") from None
    rows = [r for r in rows if None not in r.values() and None not in r]
    if root is not None and whole is not None:
        for k, r in enumerate(rows, start=2):
            steps = r.get(whole)
            if steps is None or not (steps.isascii() and steps.isdigit()):
                raise ValueError(f"{path}: line {k}: {whole} {steps!r:.40} is not a whole number")
    return rows


#: Columns renamed since a run's CSVs were first written: new name -> former name.
#: ``cost_progress.csv``'s ``episodes`` counted agent-episodes, ``progress.csv``'s count
#: environment episodes; one word, one meaning.
FORMER_NAMES = {"agent_episodes": "episodes"}


def write_rows(path: Path, fields: tuple[str, ...], rows: list[dict[str, Any]]) -> None:
    """Write ``rows`` as a whole CSV file, atomically.

    A row read from an older file gives a renamed column its value under the former name
    (:data:`FORMER_NAMES`), so rewinding an older run's CSV renames the column.
    """
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k, r.get(FORMER_NAMES.get(k, k), "")) for k in fields})
    atomic_write(path, buf.getvalue(), replace_links=True)  # a run folder's own file


class ProgressLog:
    """``progress.csv`` opened for appending: a header when new, each row flushed and synced.

    A run folder's own file: a link or a special file there is replaced by a new file (with
    the header), never appended to through it.
    """

    def __init__(self, path: Path, fields: tuple[str, ...]) -> None:
        import stat

        try:
            st = os.lstat(path)
            new = not stat.S_ISREG(st.st_mode) or st.st_size == 0
        except FileNotFoundError:
            new = True
        if new:
            write_rows(path, fields, [])
        flags = os.O_WRONLY | os.O_APPEND | getattr(os, "O_NOFOLLOW", 0)
        self._fh = open(os.open(path, flags), "a", newline="", encoding="utf-8")  # noqa: SIM115
        self._csv = csv.DictWriter(self._fh, fieldnames=fields, lineterminator="\n")

    def write(self, row: dict[str, Any]) -> None:
        """Append one row, durably."""
        self._csv.writerow(row)
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Close the file."""
        self._fh.close()


#: Finished episodes the learning curve's figures are taken over (a checkpoint keeps them).
WINDOW_EPISODES = 200

#: Episodes a progress row's window must hold to be plotted (the run's first rows are noise).
MIN_PLOTTED_EPISODES = 20


def plot_curves(
    csv_path: Path, png_path: Path, fields: tuple[str, ...], title: str = ""
) -> Path | None:
    """Learning curves (return, collision and loss-of-separation rates, deviation) as PNG.

    Returns:
        The figure's path, or None when nothing was written: no row of ``progress.csv``
        holds :data:`MIN_PLOTTED_EPISODES` finished episodes yet (a short run), or
        matplotlib is missing; either is said in one line on stderr, never a blank figure.
    """
    rows = [
        r
        for r in read_progress(csv_path)
        if r.get("return_mean") and int(r["episodes"]) >= MIN_PLOTTED_EPISODES
    ]
    if not rows:
        print(
            f"{png_path.name} not written: no row of {csv_path.name} has "
            f"{MIN_PLOTTED_EPISODES} finished episodes yet (a longer run has curves)",
            file=sys.stderr,
        )
        return None
    try:
        import matplotlib
    except ImportError:
        print(f"{png_path.name} not written: it needs matplotlib (the viz extra)", file=sys.stderr)
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = {k: np.array([float(r[k]) for r in rows]) for k in fields}
    fig, axes = plt.subplots(2, 4, figsize=(16, 6.5), sharey="col")
    panels = (
        ("return_mean", "mean return per agent"),
        ("collision_rate", "collision rate"),
        ("loss_of_separation_rate", "loss-of-separation rate"),
        ("max_deviation_mean", "mean max deviation (m)"),
    )
    for row, (x_key, x_label, scale) in enumerate(
        (("agent_steps", "agent-steps (millions)", 1e-6), ("wall_s", "wall time (min)", 1 / 60))
    ):
        for col, (key, label) in enumerate(panels):
            ax = axes[row, col]
            ax.plot(data[x_key] * scale, data[key], lw=1.2)
            ax.set_xlabel(x_label)
            ax.set_title(label, fontsize=10)
            ax.grid(alpha=0.3)
    fig.suptitle(title or csv_path.parent.name)
    fig.tight_layout()
    with atomic_output(png_path, replace_links=True) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)
    return png_path


#: The columns of ``progress.csv`` (every trainer's).
CSV_FIELDS = (
    "agent_steps",
    "wall_s",
    "episodes",
    "return_mean",
    "collision_rate",
    "loss_of_separation_rate",
    "max_deviation_mean",
    "episode_length_mean",
)


def window_summary(window: Any) -> dict:
    """The learning curve's figures over the finished episodes of ``window``.

    ``window`` holds ``(return, collision, loss_of_separation, max_deviation, length)``
    tuples; ``{}`` when it is empty.
    """
    w = list(window)
    if not w:
        return {}
    return {
        "return_mean": float(np.mean([e[0] for e in w])),
        "collision_rate": float(np.mean([e[1] for e in w])),
        "loss_of_separation_rate": float(np.mean([e[2] for e in w])),
        "max_deviation_mean": float(np.mean([e[3] for e in w])),
        "episode_length_mean": float(np.mean([e[4] for e in w])),
    }


def bar_postfix(summary: dict) -> dict:
    """The progress bar's figures of a :func:`window_summary`."""
    return {
        "ret": f"{summary['return_mean']:.0f}",
        "coll": f"{summary['collision_rate']:.1%}",
        "los": f"{summary['loss_of_separation_rate']:.1%}",
        "dev": f"{summary['max_deviation_mean']:.1f}m",
    }


def log_line(text: str) -> None:
    """Print one line of the training log on stdout (above a progress bar, if one is drawn)."""
    tqdm = sys.modules.get("tqdm")
    if tqdm is not None and getattr(tqdm, "tqdm", None) is not None:
        tqdm.tqdm.write(text, file=sys.stdout)  # clears and redraws the bar around the line
    else:
        print(text, flush=True)


def _lagrangian_part(lag: dict) -> str:
    """``cost C (limit L), lambda M`` of a checkpoint's ``lagrangian`` facts."""
    # PPO-Lagrangian keeps the tracker's figures under "state", MAPPO-Lagrangian at the top.
    cost = lag.get("episode_cost_window", lag.get("state", {}).get("episode_cost_window"))
    parts = []
    if cost is not None:
        parts.append(f"episode cost {float(cost):.3g} (limit {float(lag['cost_limit']):.3g})")
    parts.append(f"λ {float(lag['multiplier']):.3g}")
    return ", ".join(parts)


def checkpoint_line(name: str, info: dict, window: Any = ()) -> str:
    """The log's line for the checkpoint ``name``: its counters and summary figures.

    ``info`` is what the checkpoint's ``state.json`` holds (agent-steps, wall time,
    episodes, :func:`window_summary`'s figures, a Lagrangian recipe's ``lagrangian``);
    ``window`` the finished episodes the figures are taken over (only its length is said).
    """
    text = (
        f"{name}: {int(info['agent_steps']):,} agent-steps, "
        f"{float(info.get('wall_s', 0.0)) / 60:.1f} min, {int(info.get('episodes', 0)):,} episodes"
    )
    if info.get("return_mean") is not None:
        text += (
            f"; the last {len(window)}: return {info['return_mean']:.1f}, "
            f"collisions {info['collision_rate']:.1%}, "
            f"loss of separation {info['loss_of_separation_rate']:.1%}, "
            f"deviation {info['max_deviation_mean']:.1f} m"
        )
    if isinstance(info.get("lagrangian"), dict):
        text += "; " + _lagrangian_part(info["lagrangian"])
    return text


def validation_line(summary: dict, path: Path, episodes: int) -> str:
    """The log's line for the validation at a run's end (``summary``: ``validation.json``'s)."""
    results = summary.get("validation", {})
    if not results:
        return f"no validation (--eval-episodes 0); the run's summary: {path}"
    figures = []
    for label, res in results.items():
        figures.append(
            f"{label}: collisions {res.get('collision', float('nan')):.1%}, "
            f"loss of separation {res.get('loss_of_separation', float('nan')):.1%}, "
            f"deviation {res.get('max_deviation', float('nan')):.1f} m"
        )
    return f"validation on {episodes} encounters ({path}): " + "; ".join(figures)
