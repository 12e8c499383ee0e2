"""A resumed Lagrangian run is the run it continues (issue 55).

Each Lagrangian recipe runs three ways with the same seeds: uninterrupted to N (``full``),
to its own end at the mid checkpoint M (``short``: its state there is the one after the
rollout's multiplier update and weight update), and to N killed right after the checkpoint
at M, then resumed to N (``killed``). The checkpoint a killed run resumes from must hold the
state after both updates of its last rollout (the ``short`` run's, bit for bit: weights,
optimiser, random state, the multiplier's state, the counters), the multiplier the kept
``cost_progress.csv`` row records, and the rows up to it must be the uninterrupted run's
(there, episodes end with the rollouts, so the rows after it match too).

The SB3 recipes (``ppo_lagrangian``, ``ppo_lagrangian_residual``, and ``ppo_shared``) go
further: their checkpoints keep the environments' episodes in progress and SB3's rollout
state (``env_state.npz``), so a run killed at a checkpoint that falls inside episodes and
resumed ends with the uninterrupted run's weights, optimiser, random state, multiplier,
``cost_progress.csv`` and ``progress.csv`` (but its wall times), bit for bit. So does skrl's
MAPPO-Lagrangian, whose checkpoints between two rollouts keep the same ``env_state.npz``
(with the agents' last observations and the loop's timestep).
"""

import csv
import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")
from conftest import same_bits  # noqa: E402

#: SB3 recipes: 2 environments x 2 UAVs x 32 steps = 128 agent-steps a rollout.
SB3_TINY = [
    "--scenario", "collision_head_on", "--n-uavs", "2", "--episode-duration", "4",
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "2", "--hidden", "16",
    "--eval-episodes", "0", "--no-progress", "--cost-limit", "0.5", "--pid-ki", "0.5",
    "--multiplier-init", "0.25", "--torch-threads", "1",
    "--config", "reward=task uav.separation_distance=100",
]  # fmt: skip
#: skrl's MAPPO-Lagrangian: 2 environments x 3 UAVs x 20 steps = 120 agent-steps a rollout,
#: an episode a rollout (4 s at 5 Hz).
MAPPO_TINY = [
    "--n-envs", "2", "--n-steps", "20", "--batch-size", "20", "--episode-duration", "4",
    "--hidden", "16,16", "--no-progress", "--eval-episodes", "0", "--cost-limit", "1",
    "--multiplier-init", "0.7", "--pid-ki", "0.2", "--pid-kp", "0.5", "--torch-threads", "1",
    "--config", "reward=task uav.separation_distance=100",
]  # fmt: skip

#: recipe: (module, its main, its defaults or None, argv, rollout size in agent-steps).
RECIPES = {
    "ppo_lagrangian": ("ppo_lagrangian", "main", None, SB3_TINY, 128),
    "ppo_lagrangian_residual": (
        "ppo_lagrangian", "main", "RESIDUAL_LAGRANGIAN_DEFAULTS", SB3_TINY, 128,
    ),
    "mappo_lagrangian": ("mappo_lagrangian", "main", None, MAPPO_TINY, 120),
}  # fmt: skip


class _Killed(BaseException):
    """The process dies right after a checkpoint (a SIGKILL there, in-process)."""


def _main(name):
    import importlib

    module_name, func, defaults, argv, rollout = RECIPES[name]
    module = importlib.import_module(f"uasep_env.training.{module_name}")
    main = getattr(module, func)
    default = getattr(module, defaults) if defaults else None
    return (lambda extra: main([*argv, *extra], default)), rollout


def _rows(path):
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _key(rows):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


def _checkpoint(folder):
    """A checkpoint's tensors and its ``state.json`` less the wall time and the options."""
    tensors = torch.load(folder / "state.pt", map_location="cpu", weights_only=True)
    state = json.loads((folder / "state.json").read_text())
    return tensors, {k: v for k, v in state.items() if k not in ("wall_s", "args")}


@pytest.mark.parametrize("name", list(RECIPES))
def test_a_resumed_lagrangian_run_is_the_run_it_continues(name, tmp_path, monkeypatch):
    from uasep_env.training.rundir import RunFolder

    train, rollout = _main(name)
    mid, total = 2 * rollout, 3 * rollout
    every = ["--checkpoint-every", str(mid)]
    full, short, killed = tmp_path / "full", tmp_path / "short", tmp_path / "killed"
    train([*every, "--total-timesteps", str(total), "--out-dir", str(full)])
    train([*every, "--total-timesteps", str(mid), "--out-dir", str(short)])

    real = RunFolder.save_checkpoint

    def save_then_die(self, agent_steps, *args, **kwargs):
        folder = real(self, agent_steps, *args, **kwargs)
        if agent_steps == mid:
            raise _Killed
        return folder

    monkeypatch.setattr(RunFolder, "save_checkpoint", save_then_die)
    with pytest.raises(_Killed):
        train([*every, "--total-timesteps", str(total), "--out-dir", str(killed)])
    monkeypatch.setattr(RunFolder, "save_checkpoint", real)
    ckpt = killed / "checkpoints" / f"step_{mid}"
    assert ckpt.is_dir()

    # The checkpoint holds the state after the rollout's updates: the short run's end.
    tensors, state = _checkpoint(ckpt)
    end_tensors, end_state = _checkpoint(short / "checkpoints" / f"step_{mid}")
    assert same_bits(tensors, end_tensors), "the weights, optimiser or RNG are not the run's at M"
    assert state == end_state
    # ...and the multiplier the kept row of cost_progress.csv records.
    cost_rows = _rows(full / "cost_progress.csv")
    at_mid = next(r for r in cost_rows if int(r["agent_steps"]) == mid)
    assert state["lagrangian"]["multiplier"] == float(at_mid["multiplier"])

    train([*every, "--total-timesteps", str(total), "--out-dir", str(killed),
           "--resume", str(ckpt)])  # fmt: skip
    for csv_name in ("progress.csv", "cost_progress.csv"):
        ours, theirs = _rows(killed / csv_name), _rows(full / csv_name)
        assert [int(r["agent_steps"]) for r in ours] == [int(r["agent_steps"]) for r in theirs]
        upto = [r for r in theirs if int(r["agent_steps"]) <= mid]
        assert _key(ours[: len(upto)]) == _key(upto), csv_name
    # Every episode costs the same here (all its steps in loss of separation, at 100 m)
    # and the episodes end where the uninterrupted run's do (4 s; at the checkpoint too),
    # so the multiplier goes on as the uninterrupted run's, to the same value at N.
    assert _rows(killed / "cost_progress.csv") == cost_rows


#: SB3 recipes on random encounters (obstacles, noise) whose episodes (25 steps: 5 s at 5 Hz,
#: or fewer) end neither with the rollouts (32 steps) nor at the checkpoint, with costs that
#: differ from episode to episode (19 m of separation, the formation's spacing 20 m): 2
#: environments x 2 UAVs.
SB3_EXACT = [
    "--n-uavs", "2", "--episode-duration", "5",
    "--n-envs", "2", "--n-steps", "32", "--batch-size", "64", "--n-epochs", "2", "--hidden", "16",
    "--eval-episodes", "0", "--no-progress", "--cost-limit", "0.5", "--pid-ki", "0.5",
    "--multiplier-init", "0.25", "--torch-threads", "1", "--seed", "3",
    "--config", "reward=task uav.separation_distance=19",
]  # fmt: skip
SB3_RECIPES = {"ppo_lagrangian": None, "ppo_lagrangian_residual": "RESIDUAL_LAGRANGIAN_DEFAULTS"}
#: The constraint's flags of SB3_EXACT (not ppo_shared's).
_CONSTRAINT_FLAGS = ("--cost-limit", "--pid-ki", "--multiplier-init")


def _sb3_train(name):
    from uasep_env.training import ppo_lagrangian, ppo_shared

    if name == "ppo_shared":  # the same loop without the constraint, returns normalised
        argv = [
            a
            for k, a in enumerate(SB3_EXACT)
            if a not in _CONSTRAINT_FLAGS and SB3_EXACT[k - 1] not in _CONSTRAINT_FLAGS
        ]
        return lambda extra: ppo_shared.main([*argv, "--norm-reward", *extra])  # fmt: skip
    default = getattr(ppo_lagrangian, SB3_RECIPES[name]) if SB3_RECIPES[name] else None
    return lambda extra: ppo_lagrangian.main([*SB3_EXACT, *extra], default)


def _kill_at(monkeypatch, step):
    """Make the run die right after saving its checkpoint at ``step`` (a SIGKILL there)."""
    from uasep_env.training.rundir import RunFolder

    real = RunFolder.save_checkpoint

    def save_then_die(self, agent_steps, *args, **kwargs):
        folder = real(self, agent_steps, *args, **kwargs)
        if agent_steps == step:
            raise _Killed
        return folder

    monkeypatch.setattr(RunFolder, "save_checkpoint", save_then_die)
    return lambda: monkeypatch.setattr(RunFolder, "save_checkpoint", real)


def _without_wall(path):
    """``progress.csv``'s bytes less its wall-time column (the one figure that may differ)."""
    lines = path.read_text().splitlines()
    col = lines[0].split(",").index("wall_s")
    return [",".join(c for k, c in enumerate(line.split(",")) if k != col) for line in lines]


def _assert_costs_and_multiplier_vary(full):
    """What makes an exact-resume test able to fail: costs and multiplier that move."""
    rows = _rows(full / "cost_progress.csv")
    assert len({r["episode_cost_mean"] for r in rows}) > 1
    assert len({r["multiplier"] for r in rows}) > 2


def _assert_same_run(killed, full, total):
    """The resumed run ends as the uninterrupted one: weights, λ, both CSVs."""
    end = f"checkpoints/step_{total}"
    ours, theirs = _checkpoint(killed / end), _checkpoint(full / end)
    assert same_bits(ours[0], theirs[0]), "the final weights, optimiser or RNG differ"
    assert ours[1] == theirs[1]  # the multiplier's state, the counters, the window
    assert (killed / "cost_progress.csv").read_bytes() == (full / "cost_progress.csv").read_bytes()
    assert _without_wall(killed / "progress.csv") == _without_wall(full / "progress.csv")


@pytest.mark.parametrize("name", [*SB3_RECIPES, "ppo_shared"])
def test_a_resumed_sb3_run_is_bit_identical(name, tmp_path, monkeypatch):
    """Killed mid-episode at a checkpoint and resumed: the uninterrupted run, bit for bit."""
    train = _sb3_train(name)
    rollout = 2 * 2 * 32
    mid, total = 2 * rollout, 4 * rollout
    every = ["--checkpoint-every", str(mid), "--total-timesteps", str(total)]
    full, killed = tmp_path / "full", tmp_path / "killed"
    train([*every, "--out-dir", str(full)])
    put_back = _kill_at(monkeypatch, mid)
    with pytest.raises(_Killed):
        train([*every, "--out-dir", str(killed)])
    put_back()
    train([*every, "--out-dir", str(killed),
           "--resume", str(killed / "checkpoints" / f"step_{mid}")])  # fmt: skip

    # What makes this test able to fail: the checkpoint falls inside episodes (each env's
    # steps into its episode are not 0), and the multiplier moves with costs that vary.
    env = np.load(killed / "checkpoints" / f"step_{mid}" / "env_state.npz")
    assert (env["env.world.steps"] > 0).all()
    if name == "ppo_shared":
        assert _without_wall(killed / "progress.csv") == _without_wall(full / "progress.csv")
        end = f"checkpoints/step_{total}"
        assert same_bits(_checkpoint(killed / end), _checkpoint(full / end))
        return
    _assert_costs_and_multiplier_vary(full)

    _assert_same_run(killed, full, total)
    assert (
        json.loads((killed / "validation.json").read_text())["training"]["lagrangian"]
        == (json.loads((full / "validation.json").read_text())["training"]["lagrangian"])
    )


@pytest.mark.parametrize("change", ["--n-envs 3", "no env_state.npz"])
def test_a_resume_that_cannot_continue_the_episodes_restarts_them(change, tmp_path, capsys):
    """Other environments (or an older checkpoint without their state): not refused; said."""
    train = _sb3_train("ppo_lagrangian")
    out = tmp_path / "run"
    train(["--total-timesteps", "256", "--checkpoint-every", "128", "--out-dir", str(out)])
    ckpt = out / "checkpoints" / "step_128"
    extra = change.split() if change.startswith("--") else []
    if not extra:
        (ckpt / "env_state.npz").unlink()
    capsys.readouterr()
    summary = train([*extra, "--total-timesteps", "512", "--out-dir", str(out),
                     "--resume", str(ckpt)])  # fmt: skip
    said = capsys.readouterr().out
    assert "the environments restart their episodes from their seeds" in said, said
    assert summary["training"]["agent_steps"] >= 512


#: skrl's MAPPO-Lagrangian on random encounters whose episodes (25 steps: 5 s at 5 Hz) end
#: neither with the rollouts (20 steps) nor at the checkpoint, with costs that differ from
#: episode to episode: 2 environments x 3 UAVs x 20 steps = 120 agent-steps a rollout.
MAPPO_EXACT = [
    "--n-envs", "2", "--n-steps", "20", "--batch-size", "20", "--episode-duration", "5",
    "--hidden", "16,16", "--no-progress", "--eval-episodes", "0", "--cost-limit", "1",
    "--multiplier-init", "0.7", "--pid-ki", "0.2", "--pid-kp", "0.5", "--torch-threads", "1",
    "--seed", "3", "--config", "reward=task uav.separation_distance=19",
]  # fmt: skip


def test_a_resumed_mappo_lagrangian_run_is_bit_identical(tmp_path, monkeypatch):
    """skrl's loop killed mid-episode at a checkpoint and resumed: the uninterrupted run."""
    from uasep_env.training import mappo_lagrangian

    def train(extra):
        return mappo_lagrangian.main([*MAPPO_EXACT, *extra])

    rollout = 2 * 3 * 20
    mid, total = 2 * rollout, 4 * rollout
    every = ["--checkpoint-every", str(mid), "--total-timesteps", str(total)]
    full, killed = tmp_path / "full", tmp_path / "killed"
    train([*every, "--out-dir", str(full)])
    put_back = _kill_at(monkeypatch, mid)
    with pytest.raises(_Killed):
        train([*every, "--out-dir", str(killed)])
    put_back()
    ckpt = killed / "checkpoints" / f"step_{mid}"
    train([*every, "--out-dir", str(killed), "--resume", str(ckpt)])

    # The checkpoint falls inside episodes, and the multiplier moves with costs that vary.
    env = np.load(ckpt / "env_state.npz")
    assert (env["env.world.steps"] > 0).all()
    _assert_costs_and_multiplier_vary(full)

    _assert_same_run(killed, full, total)


def test_mappo_checkpoints_fall_at_a_rollouts_end(tmp_path):
    """--checkpoint-every inside a rollout checkpoints at the rollout's end (exact resume)."""
    from uasep_env.training import mappo_lagrangian

    out = tmp_path / "run"
    mappo_lagrangian.main([*MAPPO_EXACT, "--total-timesteps", "240", "--checkpoint-every",
                           "180", "--out-dir", str(out)])  # fmt: skip
    names = sorted(p.name for p in (out / "checkpoints").iterdir() if p.name.startswith("step_"))
    assert names == ["step_240"]  # a rollout is 120 agent-steps: 180 falls inside the second
    assert (out / "checkpoints" / "step_240" / "env_state.npz").exists()


@pytest.mark.parametrize("case", ["no env_state.npz", "--n-envs 3"])
def test_a_mappo_resume_that_cannot_continue_the_episodes_restarts_them(case, tmp_path, capsys):
    """An older checkpoint (no environment state), other environments: said, not refused."""
    from uasep_env.training import mappo_lagrangian

    out = tmp_path / "run"
    every = "120"  # a rollout: 120 agent-steps
    mappo_lagrangian.main([*MAPPO_EXACT, "--total-timesteps", "240", "--checkpoint-every",
                           every, "--out-dir", str(out)])  # fmt: skip
    ckpt = out / "checkpoints" / f"step_{every}"
    assert (ckpt / "env_state.npz").exists()
    if case == "no env_state.npz":
        (ckpt / "env_state.npz").unlink()
    extra = case.split() if case.startswith("--") else []
    capsys.readouterr()
    summary = mappo_lagrangian.main([*MAPPO_EXACT, *extra, "--total-timesteps", "480",
                                     "--out-dir", str(out), "--resume", str(ckpt)])  # fmt: skip
    said = capsys.readouterr().out
    assert "the environments restart their episodes from their seeds" in said, said
    assert summary["training"]["agent_steps"] >= 480
