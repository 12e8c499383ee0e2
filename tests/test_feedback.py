"""Feedback on long work: progress on stderr only, the slow-kernels note, no blank curves."""

import sys

import pytest
from conftest import HANG_GUARD_S

from uasep_env import _numba
from uasep_env.evaluation import main
from uasep_env.evaluation.progress import LineProgress
from uasep_env.training import rundir


@pytest.fixture
def no_tqdm(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm -> ImportError


def test_progress_without_tqdm_goes_to_stderr_and_never_to_stdout(tmp_path, capsys, no_tqdm):
    out = tmp_path / "run.csv"
    argv = ["--policy", "zero", "--episodes", "2", "--batch-size", "1", "--csv", str(out),
            "--config", "episode_duration=20"]  # fmt: skip
    assert main([*argv, "--progress"]) == 0
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.startswith("uasep-eval: ")]
    assert [ln.split(" (")[0] for ln in lines] == [
        "uasep-eval: 0/2 episodes",
        "uasep-eval: 1/2 episodes",
        "uasep-eval: 2/2 episodes",
    ]
    assert not [ln for ln in captured.out.splitlines() if ln.startswith("uasep-eval: ")]
    # Not a terminal and not asked for: no progress; --quiet wins over --progress.
    assert main([*argv]) == 0
    assert "uasep-eval: " not in capsys.readouterr().err
    assert main([*argv, "--progress", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")


def test_line_progress_rewrites_one_line_on_a_terminal():
    class Tty:
        text = ""

        def isatty(self):
            return True

        def write(self, s):
            self.text += s

        def flush(self):
            pass

    tty = Tty()
    bar = LineProgress(3, stream=tty)
    bar.update(2)
    bar.close()
    assert tty.text.count("\r") == 2 and tty.text.endswith("\n") and "2/3 episodes" in tty.text


def test_the_slow_kernels_note_once_per_process_and_not_when_chosen(monkeypatch, capsys):
    monkeypatch.setattr(_numba, "_state", {"numba": None})  # as without numba
    monkeypatch.delenv("UASEP_NUMBA", raising=False)
    assert _numba.note_slow_kernels() is True
    assert _numba.note_slow_kernels() is False  # once
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "slower" in err and "uasep-env[fast]" in err
    monkeypatch.setattr(_numba, "_state", {"numba": None})
    monkeypatch.setenv("UASEP_NUMBA", "0")  # the user's explicit choice: no note
    assert _numba.note_slow_kernels() is False
    assert capsys.readouterr().err == ""


def test_uasep_eval_notes_slow_kernels_on_stderr(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(_numba, "_state", {"numba": None})
    monkeypatch.delenv("UASEP_NUMBA", raising=False)
    out = tmp_path / "run.csv"
    assert main(["--policy", "zero", "--config", "episode_duration=5", "--csv", str(out)]) == 0
    captured = capsys.readouterr()
    assert "numba is not installed" in captured.err
    assert "numba is not installed" not in captured.out


def test_no_blank_curves_figure_for_a_run_too_short_to_plot(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from uasep_env.training.ppo_shared import CSV_FIELDS as fields

    rows = [{f: 1.0 for f in fields} | {"agent_steps": 64 * k, "episodes": k}
            for k in range(1, 4)]  # fmt: skip
    rundir.write_rows(tmp_path / "progress.csv", fields, rows)
    png = tmp_path / "curves.png"
    assert rundir.plot_curves(tmp_path / "progress.csv", png, fields) is None
    assert not png.exists()
    assert "curves.png not written" in capsys.readouterr().err


def test_seeds_curves_are_not_drawn_from_nothing(tmp_path, capsys):
    sys.path.insert(0, str(rundir.Path(__file__).resolve().parents[1] / "train"))
    import seeds

    (tmp_path / "seed_0").mkdir()
    assert seeds.plot_curves(tmp_path, 2, "shared") is None
    assert not (tmp_path / "curves.png").exists()
    assert "not written" in capsys.readouterr().err


def test_the_heartbeat_redraws_between_chunks_and_stops_on_close():
    import time

    from uasep_env.evaluation.progress import Heartbeat

    class Bar:
        refreshed = updated = closed = 0

        def refresh(self):
            self.refreshed += 1

        def update(self, n):
            self.updated += n

        def close(self):
            self.closed += 1

    bar = Bar()
    beat = Heartbeat(bar, interval=0.01)
    deadline = time.monotonic() + HANG_GUARD_S  # a guard against a hang only
    while bar.refreshed < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    beat.update(3)
    beat.close()
    seen = bar.refreshed
    time.sleep(0.05)
    assert seen >= 2 and bar.refreshed == seen  # no redraw after close
    assert (bar.updated, bar.closed) == (3, 1)


#: A tiny run whose --total-timesteps (700) is not whole rollouts: it trains to 768
#: (SB3's and the lean loop's: 2 envs x 2 UAVs x 32 steps = 128 a rollout; skrl's MAPPO:
#: 2 envs x 3 UAVs x 16 steps = 96 a rollout).
_BAR_RUNS = {
    "sb3": ("ppo_shared", ["--n-uavs", "2", "--n-steps", "32", "--batch-size", "64"], 768),
    "lean": ("ppo_shared", ["--n-uavs", "2", "--n-steps", "32", "--batch-size", "64",
                            "--trainer", "lean"], 768),
    "mappo": ("mappo", ["--n-steps", "16", "--batch-size", "16"], 768),
}  # fmt: skip


@pytest.mark.parametrize("trainer", list(_BAR_RUNS))
def test_the_progress_bar_ends_where_the_run_ends(trainer, tmp_path, monkeypatch):
    """The bar's total is the rounded budget: it reaches 100 % at the run's end, not before."""
    import importlib

    tqdm = pytest.importorskip("tqdm")
    pytest.importorskip("torch")
    if trainer == "mappo":
        pytest.importorskip("skrl")
    else:
        pytest.importorskip("stable_baselines3")
    bars = []

    class Recorded(tqdm.tqdm):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **{**kwargs, "disable": False, "file": sys.stderr})
            bars.append(self)

    monkeypatch.setattr(tqdm, "tqdm", Recorded)
    module, argv, end = _BAR_RUNS[trainer]
    recipe = importlib.import_module(f"uasep_env.training.{module}")
    out = str(tmp_path / "run")
    recipe.main([*argv, "--n-envs", "2", "--episode-duration", "4", "--hidden", "16",
                 "--n-epochs", "1", "--total-timesteps", "700", "--checkpoint-every", "100000",
                 "--eval-episodes", "0", "--progress", "--out-dir", out])  # fmt: skip
    (bar,) = bars
    assert (bar.total, bar.n) == (end, end)
