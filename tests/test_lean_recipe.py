"""``--trainer lean``: the PPO recipes trained by the lean loop write an SB3 run's folder.

Tiny runs (4 environments of 3 UAVs, 16 steps a rollout: 192 agent-steps an update; 4 s
episodes, so episodes end inside every run) of :mod:`uasep_env.training.lean_recipe`,
compared with the same runs under SB3; ``--resume`` across trainers; the flags refused at
parse time; :class:`~uasep_env.envs.episode_safety.EpisodeSafety` and the lean rollout's
finished episodes against the SB3 view's.
"""

import csv
import json
import math
import os
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")

from uasep_env.config import VERSION_DEFAULTS  # noqa: E402
from uasep_env.envs.episode_safety import EpisodeSafety  # noqa: E402
from uasep_env.policies import load_policy  # noqa: E402
from uasep_env.policies.learned import read_checkpoint  # noqa: E402
from uasep_env.rollout import DEFAULT_SETTLE_TIME_S  # noqa: E402
from uasep_env.training import (  # noqa: E402
    lean_recipe,
    mappo,
    mappo_lagrangian,
    ppo_lagrangian,
    ppo_lean,
    ppo_shared,
)
from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS  # noqa: E402
from uasep_env.training.ppo_residual_apf import RESIDUAL_DEFAULTS  # noqa: E402
from uasep_env.training.rundir import CHECKPOINT_FILES, ENV_STATE_FILE, RunError  # noqa: E402

TINY = [
    "--n-envs", "4", "--n-steps", "16", "--batch-size", "192", "--n-epochs", "2",
    "--hidden", "16", "--episode-duration", "4", "--eval-episodes", "2", "--no-progress",
]  # fmt: skip
PER_UPDATE = 4 * 16 * 3  # agent-steps an update (the default 3 UAVs)
TOTAL, EVERY = 5 * PER_UPDATE, 2 * PER_UPDATE  # 960 agent-steps, a checkpoint every 384
FIGURES = ppo_shared.CSV_FIELDS[3:]  # the window's figures (empty before any episode ends)


def _train(out: Path, *extra: str, total: int = TOTAL, defaults: object = None) -> dict:
    argv = [*TINY, "--total-timesteps", str(total), "--checkpoint-every", str(EVERY),
            "--out-dir", str(out), *extra]  # fmt: skip
    return ppo_shared.main(argv, defaults)


def _rows(out: Path) -> list[dict]:
    with (out / "progress.csv").open() as f:
        return list(csv.DictReader(f))


def _state(checkpoint: Path) -> dict:
    return json.loads((checkpoint / "state.json").read_text())


def _weights(path: Path) -> tuple:
    """A policy checkpoint's actor weights and observation statistics."""
    meta, weights, mean, var = read_checkpoint(path)
    return meta, [a for layer in weights for a in layer], mean, var


def _same_weights(a: Path, b: Path) -> bool:
    wa, wb = _weights(a)[1], _weights(b)[1]
    return all(np.array_equal(x, y) for x, y in zip(wa, wb, strict=True))


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def _snapshot(root: Path) -> dict:
    """Every file's bytes and every link's target under ``root``."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p.relative_to(root))] = os.readlink(p)
        elif p.is_file():
            out[str(p.relative_to(root))] = p.read_bytes()
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """An equally tiny run of each trainer (read only: tests that change a run copy it)."""
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("runs")
    summaries = {
        "lean": _train(root / "lean", "--trainer", "lean"),
        "sb3": _train(root / "sb3"),
    }
    return {"lean": root / "lean", "sb3": root / "sb3", "summaries": summaries}


# 1. The run folder.


def test_a_lean_run_writes_an_sb3_runs_files(runs):
    lean, sb3 = runs["lean"], runs["sb3"]
    steps = list(range(PER_UPDATE, TOTAL + 1, PER_UPDATE))
    saved = [f"step_{s}" for s in (EVERY, 2 * EVERY, TOTAL)]  # every 384, and the final one
    # SB3's checkpoints also keep their environments' state (env_state.npz: its exact resume).
    assert _files(lean) == {f for f in _files(sb3) if not f.endswith(f"/{ENV_STATE_FILE}")}
    assert sorted(p.name for p in (lean / "checkpoints").iterdir()) == sorted([*saved, "latest"])
    for name in saved:
        assert {p.name for p in (lean / "checkpoints" / name).iterdir()} == set(CHECKPOINT_FILES)
    assert os.readlink(lean / "checkpoints" / "latest") == f"step_{TOTAL}"

    # progress.csv: SB3's columns, one row per update.
    with (lean / "progress.csv").open() as f:
        assert next(csv.reader(f)) == list(ppo_shared.CSV_FIELDS)
    rows = _rows(lean)
    assert (
        [int(r["agent_steps"]) for r in rows]
        == steps
        == [int(r["agent_steps"]) for r in _rows(sb3)]
    )
    episodes = [int(r["episodes"]) for r in rows]
    assert episodes == sorted(episodes) and episodes[-1] > 0  # 4 s episodes end
    for r in rows:  # the window's figures once an episode has ended, blank before
        if int(r["episodes"]):
            assert all(math.isfinite(float(r[k])) for k in FIGURES), r
        else:
            assert all(r[k] == "" for k in FIGURES), r
    assert float(rows[-1]["episode_length_mean"]) == 20.0  # 4 s of 0.2 s steps

    # Each checkpoint's counters are the run's at its step; the window is its figures'.
    sb3_keys = set(_state(sb3 / "checkpoints" / "latest"))
    for name in saved:
        state = _state(lean / "checkpoints" / name)
        step = int(name.removeprefix("step_"))
        row = next(r for r in rows if int(r["agent_steps"]) == step)
        assert sb3_keys <= set(state)
        assert state["agent_steps"] == step and state["updates"] == step // PER_UPDATE
        assert state["episodes"] == int(row["episodes"]) > 0
        assert state["args"]["trainer"] == "lean" and state["wall_s"] > 0
        window = np.array(state["window"])
        assert window.shape == (min(state["episodes"], 200), 5)
        assert state["return_mean"] == pytest.approx(window[:, 0].mean())
        assert state["episode_length_mean"] == pytest.approx(window[:, 4].mean())
        assert float(row["return_mean"]) == pytest.approx(state["return_mean"])

    # The final policy: loadable, the lean loop's, the last checkpoint's weights.
    policy = load_policy(lean / "policy.zip")
    assert policy.meta.info["implementation"] == "uasep_env.training.ppo_lean"
    assert policy.meta.info["agent_steps"] == TOTAL
    assert policy.meta.info["env_version"] == max(VERSION_DEFAULTS)  # the recipe's env version
    assert _same_weights(lean / "policy.zip", lean / "checkpoints" / "latest" / "policy.zip")
    first = lean / "checkpoints" / f"step_{EVERY}" / "policy.zip"
    assert not _same_weights(lean / "policy.zip", first)  # it trained
    validation = json.loads((lean / "validation.json").read_text())
    assert validation["training"]["agent_steps"] == TOTAL
    assert validation["training"]["updates"] == TOTAL // PER_UPDATE
    assert set(validation["validation"]) == {"learned", "apf"}
    assert "implementation" not in _weights(sb3 / "policy.zip")[0].info


# 2. --resume.


def test_resume_rewinds_the_run_and_continues_its_counters(runs, tmp_path, monkeypatch):
    out = tmp_path / "run"
    shutil.copytree(runs["lean"], out, symlinks=True)
    before = _rows(out)
    ck = out / "checkpoints" / f"step_{EVERY}"
    at = _state(ck)
    old_768 = _state(out / "checkpoints" / f"step_{2 * EVERY}")
    seen = []  # the update count each update is given (the critic warm-up reads it)
    real = ppo_lean._update

    def update(nets, opt, args, updates, *rest):
        seen.append(updates)
        return real(nets, opt, args, updates, *rest)

    monkeypatch.setattr(ppo_lean, "_update", update)
    total = 7 * PER_UPDATE
    _train(out, "--trainer", "lean", "--resume", str(ck), total=total)

    assert seen == list(range(EVERY // PER_UPDATE, 7))
    rows = _rows(out)
    steps = [int(r["agent_steps"]) for r in rows]
    assert steps == list(range(PER_UPDATE, total + 1, PER_UPDATE))  # no row twice, in order
    assert (out / "progress.csv").read_text().count("agent_steps") == 1
    # Up to the checkpoint: the first run's rows, as they were; then continued.
    assert rows[: EVERY // PER_UPDATE] == before[: EVERY // PER_UPDATE]
    episodes = [int(r["episodes"]) for r in rows]
    assert episodes == sorted(episodes) and episodes[-1] > at["episodes"]
    saved = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert saved == sorted(["latest", *(f"step_{s}" for s in (EVERY, 2 * EVERY, 3 * EVERY, total))])
    assert os.readlink(out / "checkpoints" / "latest") == f"step_{total}"
    assert _state(ck) == at  # the checkpoint resumed from is kept as it was
    redone = _state(out / "checkpoints" / f"step_{2 * EVERY}")  # the continuation's own
    assert redone["updates"] == old_768["updates"] and redone["wall_s"] != old_768["wall_s"]
    final = _state(out / "checkpoints" / "latest")
    assert final["agent_steps"] == total and final["updates"] == 7
    assert final["episodes"] == episodes[-1]
    assert len(final["window"]) == min(final["episodes"], 200)
    assert final["window"][: len(at["window"])] == at["window"]  # the window goes on
    assert final["wall_s"] > at["wall_s"]
    summary = json.loads((out / "validation.json").read_text())["training"]
    assert (summary["agent_steps"], summary["updates"]) == (total, 7)
    assert not list(out.rglob(".*.tmp*"))


def _resumed_at_the_end(runs: dict, out: Path, trainer: str) -> tuple[Path, dict]:
    """Resume the run of ``trainer`` at its mid checkpoint and stop there at once."""
    ck = runs[trainer] / "checkpoints" / f"step_{2 * EVERY}"
    extra = ["--trainer", "lean"] if trainer == "lean" else []
    return ck, _train(out, *extra, "--resume", str(ck), total=2 * EVERY)


def test_resuming_at_a_checkpoints_end_exports_its_weights(runs, tmp_path):
    """Resumed and stopped at once: the final policy's weights are the checkpoint's."""
    ck, summary = _resumed_at_the_end(runs, tmp_path / "again", "lean")
    final = tmp_path / "again" / "policy.zip"
    assert _same_weights(final, ck / "policy.zip")
    # ... and not merely what any checkpoint of the run holds.
    assert not _same_weights(final, runs["lean"] / "policy.zip")
    meta = _weights(final)[0]
    assert meta.info["agent_steps"] == 2 * EVERY and meta.info["updates"] == 4
    assert meta.info["implementation"] == "uasep_env.training.ppo_lean"
    assert summary["training"]["agent_steps"] == 2 * EVERY


@pytest.mark.parametrize("trainer", ["sb3", "lean"])
def test_resuming_at_a_checkpoints_end_exports_its_normalisation(runs, tmp_path, trainer):
    ck, _ = _resumed_at_the_end(runs, tmp_path / "again", trainer)
    _, _, mean, var = _weights(tmp_path / "again" / "policy.zip")
    _, _, mean_ck, var_ck = _weights(ck / "policy.zip")
    np.testing.assert_array_equal(mean, mean_ck)
    np.testing.assert_array_equal(var, var_ck)


def test_the_critic_warmup_goes_on_where_the_checkpoint_left_it(tmp_path):
    # The residual recipe, a warm-up of 4: updates 0-2 train the critic only (the SB3 count),
    # so the checkpoint after 2 holds the initial actor, and the resumed run's first update
    # (its third) must leave it as it is, its second (the fourth) train it.
    warm = ["--trainer", "lean", "--critic-warmup", "4"]
    first = tmp_path / "first"
    _train(first, *warm, total=EVERY, defaults=RESIDUAL_DEFAULTS)
    ck = first / "checkpoints" / f"step_{EVERY}"
    assert _state(ck)["updates"] == 2
    one, two = tmp_path / "one", tmp_path / "two"
    _train(one, *warm, "--resume", str(ck), total=EVERY + PER_UPDATE, defaults=RESIDUAL_DEFAULTS)
    _train(two, *warm, "--resume", str(ck), total=EVERY + 2 * PER_UPDATE,
           defaults=RESIDUAL_DEFAULTS)  # fmt: skip
    assert _same_weights(one / "policy.zip", ck / "policy.zip")
    assert not _same_weights(two / "policy.zip", ck / "policy.zip")
    assert _state(two / "checkpoints" / "latest")["updates"] == 4


def test_a_run_whose_budget_ends_before_its_first_update_still_exports(tmp_path):
    # SB3's path writes policy.zip and validation.json for such a run.
    _train(tmp_path / "run", "--trainer", "lean", "--max-minutes", "1e-9", "--eval-episodes", "0")
    assert (tmp_path / "run" / "policy.zip").is_file()
    assert (tmp_path / "run" / "validation.json").is_file()


# 3. The checkpoint's round trip.


class _Keep(ppo_lean.Hooks):
    def update_end(self, state):
        self.state = state


def _fresh_state(args, config, central=False):
    """A new run's State, built as ``ppo_lean.train`` builds it (MAPPO's under ``central``)."""
    from uasep_env.envs.core import EnvCore
    from uasep_env.interface.observation import state_dim

    core = EnvCore(config, n_envs=args.n_envs)
    rows = args.n_envs * config.n_uavs
    width = state_dim(config) + core.obs_dim if central else None
    nets = ppo_lean._ActorCritic(core.obs_dim, args, width)
    opt = torch.optim.Adam(nets.params, lr=args.learning_rate, eps=1e-5)
    norm = ppo_lean.Normaliser(core.obs_dim, rows, norm_obs=args.norm_obs,
                               norm_reward=args.norm_reward, gamma=args.gamma)  # fmt: skip
    state = ppo_lean.State(nets=nets, learner=nets, opt=opt, norm=norm)
    if central:
        state.critic_norm = ppo_lean.Normaliser(width, rows, norm_obs=True, norm_reward=False,
                                                gamma=args.gamma)  # fmt: skip
        state.value_scale = ppo_lean.ValueScale()
    return state


def test_a_checkpoint_restores_weights_adam_normalisation_rng_and_counters(tmp_path):
    argv = [*TINY, "--total-timesteps", str(3 * PER_UPDATE), "--trainer", "lean",
            "--norm-reward", "--out-dir", str(tmp_path / "unused")]  # fmt: skip
    args = ppo_shared.parse_args(argv)
    config = ppo_shared.make_env_config(args)
    hooks = _Keep()
    ppo_lean.train(args, config, hooks)
    state = hooks.state
    assert state.updates == 3 and state.episodes > 0
    info = {"agent_steps": state.agent_steps, "updates": state.updates,
            "episodes": state.episodes, "wall_s": state.wall_s, "window": []}  # fmt: skip
    ck = tmp_path / "ck"
    rng = torch.get_rng_state()
    lean_recipe.save_checkpoint(state, config, args, ck, info)
    assert {p.name for p in ck.iterdir()} == set(CHECKPOINT_FILES)

    torch.manual_seed(12345)  # another random state, which the load must replace
    fresh = _fresh_state(args, config)
    assert not torch.equal(torch.get_rng_state(), rng)
    got = lean_recipe.load_checkpoint(fresh, ck, args)
    assert got["updates"] == 3 and got["args"]["trainer"] == "lean"
    for name in ("agent_steps", "updates", "episodes", "wall_s"):
        assert getattr(fresh, name) == getattr(state, name), name
    assert torch.equal(torch.get_rng_state(), rng)
    for a, b in zip(fresh.learner.params, state.learner.params, strict=True):
        assert torch.equal(a, b)
    # Adam's moments and step counts, parameter by parameter.
    mine, theirs = fresh.opt.state_dict(), state.opt.state_dict()
    assert len(theirs["state"]) == len(state.learner.params)  # every parameter has moved
    assert mine["state"].keys() == theirs["state"].keys()
    for k, s in theirs["state"].items():
        for key in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(mine["state"][k][key], s[key]), (k, key)
    assert mine["param_groups"] == theirs["param_groups"]
    for rms in ("obs_rms", "ret_rms"):
        a, b = getattr(fresh.norm, rms), getattr(state.norm, rms)
        np.testing.assert_array_equal(a.mean, b.mean)
        np.testing.assert_array_equal(a.var, b.var)
        assert a.count == b.count
    assert state.norm.ret_rms.count > 1  # --norm-reward: the return's statistics moved
    # The policy in the checkpoint is the state's actor.
    _, weights, mean, _ = _weights(ck / "policy.zip")
    want = [p.detach().numpy() for m in state.nets.linears() for p in (m.weight, m.bias)]
    assert all(np.array_equal(a, b) for a, b in zip(weights, want, strict=True))
    np.testing.assert_array_equal(mean, state.norm.obs_rms.mean)


# 4. A checkpoint of the other trainer.


def _refused_resume(checkpoint: Path, out: Path, *extra: str) -> str:
    with pytest.raises(SystemExit) as info:
        _train(out, "--resume", str(checkpoint), *extra)
    assert isinstance(info.value, RunError)
    message = str(info.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize(("theirs", "mine"), [("sb3", "lean"), ("lean", "default")])
def test_a_checkpoint_of_the_other_trainer_is_refused_before_anything_is_written(
    runs, tmp_path, theirs, mine
):
    ck = runs[theirs] / "checkpoints" / "latest"
    written = "lean" if theirs == "lean" else "default"
    want = f"a checkpoint of --trainer {written}; resume it with --trainer {written}"
    extra = ["--trainer", "lean"] if mine == "lean" else []
    # Into a new folder: none is made.
    assert want in _refused_resume(ck, tmp_path / "new", *extra)
    assert not (tmp_path / "new").exists()
    # Into its own run's folder: nothing rewound, nothing written.
    out = tmp_path / "own"
    shutil.copytree(runs[theirs], out, symlinks=True)
    before = _snapshot(out)
    ck = out / "checkpoints" / f"step_{EVERY}"
    assert want in _refused_resume(ck, out, *extra)
    assert _snapshot(out) == before


def test_the_command_line_refuses_it_in_one_line(runs, tmp_path, capsys):
    from uasep_env.training.cli import main

    ck = runs["sb3"] / "checkpoints" / "latest"
    argv = ["--trainer", "lean", "--resume", str(ck), "--out-dir", str(tmp_path / "r")]
    assert main(["ppo_residual_apf", *argv]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "resume it with --trainer default" in err, err
    assert not (tmp_path / "r").exists()


def test_load_checkpoint_refuses_an_sb3_checkpoint(runs):
    args = ppo_shared.parse_args([*TINY, "--trainer", "lean", "--out-dir", "unused"])
    state = _fresh_state(args, ppo_shared.make_env_config(args))
    before = [p.detach().clone() for p in state.learner.params]
    with pytest.raises(RunError, match="a checkpoint of --trainer default"):
        lean_recipe.load_checkpoint(state, runs["sb3"] / "checkpoints" / "latest", args)
    assert all(torch.equal(a, b) for a, b in zip(before, state.learner.params, strict=True))
    assert state.agent_steps == state.updates == 0


# 5. Refused at parse time.

PARSERS = {
    "ppo_shared": ppo_shared.parse_args,
    "ppo_residual_apf": lambda argv: ppo_shared.parse_args(argv, RESIDUAL_DEFAULTS),
    "mappo": mappo.parse_args,
    "mappo_lagrangian": mappo_lagrangian.parse_args,
    "ppo_lagrangian": ppo_lagrangian.parse_args,
    "ppo_lagrangian_residual": lambda argv: ppo_lagrangian.parse_args(
        argv, RESIDUAL_LAGRANGIAN_DEFAULTS
    ),
}
REFUSED = [
    *((r, ["--trainer", "bogus"], "argument --trainer: must be one of default, lean, got 'bogus'")
      for r in PARSERS),
    ("ppo_shared", ["--trainer", "lean", "--tensorboard"], "argument --tensorboard: SB3's"),
    ("ppo_residual_apf", ["--tensorboard", "--trainer", "lean"], "argument --tensorboard: SB3's"),
    ("mappo", ["--trainer", "lean", "--norm-reward"],
     "argument --norm-reward: not supported by the MAPPO recipe"),
    ("mappo", ["--critic-warmup", "2", "--trainer", "lean"],
     "argument --critic-warmup: not supported by the MAPPO recipe"),
    ("mappo", ["--batch-size", "100"], "argument --batch-size: 100 must divide"),
    ("mappo_lagrangian", ["--trainer", "lean"],
     "argument --trainer: 'lean' is not for this Lagrangian recipe"),
]  # fmt: skip


@pytest.mark.parametrize(("recipe", "flags", "message"), REFUSED)
def test_the_recipes_refuse_what_the_lean_trainer_cannot_do(recipe, flags, message, capsys,
                                                            tmp_path):  # fmt: skip
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as info:
        PARSERS[recipe]([*flags, "--out-dir", str(out)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not out.exists()


def test_uasep_train_refuses_tensorboard_with_the_lean_trainer(capsys, tmp_path):
    from uasep_env.training.cli import main

    out = tmp_path / "run"
    argv = ["--trainer", "lean", "--tensorboard", "--out-dir", str(out)]
    assert main(["ppo_residual_apf", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "uasep-train ppo_residual_apf: error: argument --tensorboard" in err
    assert not out.exists()


@pytest.mark.parametrize("recipe", ["ppo_shared", "ppo_residual_apf", "mappo", "ppo_lagrangian",
                                    "ppo_lagrangian_residual"])  # fmt: skip
def test_the_ppo_recipes_and_mappo_take_the_lean_trainer(recipe, tmp_path):
    args = PARSERS[recipe](["--trainer", "lean", "--out-dir", str(tmp_path)])
    assert args.trainer == "lean"
    assert PARSERS[recipe](["--out-dir", str(tmp_path)]).trainer == "default"


# 6. MAPPO on the lean loop.


def _train_mappo(out: Path, *extra: str, total: int = TOTAL) -> dict:
    argv = [*TINY, "--trainer", "lean", "--total-timesteps", str(total),
            "--checkpoint-every", str(EVERY), "--out-dir", str(out), *extra]  # fmt: skip
    return mappo.main(argv)


@pytest.fixture(scope="module")
def mappo_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("mappo") / "run"
    _train_mappo(out)
    return out


def test_a_lean_mappo_run_writes_a_runs_files_and_a_mappo_policy(mappo_run, runs):
    assert _files(mappo_run) == _files(runs["lean"])
    rows = _rows(mappo_run)
    assert [int(r["agent_steps"]) for r in rows] == list(range(PER_UPDATE, TOTAL + 1, PER_UPDATE))
    assert int(rows[-1]["episodes"]) > 0
    policy = load_policy(mappo_run / "policy.zip")
    assert policy.meta.algorithm == "MAPPO"
    assert policy.meta.info["implementation"] == "uasep_env.training.ppo_lean (centralised critic)"
    assert _same_weights(mappo_run / "policy.zip", mappo_run / "checkpoints/latest/policy.zip")
    assert json.loads((mappo_run / "validation.json").read_text())["training"]["updates"] == 5
    # The critic's statistics are in the checkpoint (a PPO run's has none).
    saved = torch.load(mappo_run / "checkpoints/latest/state.pt", weights_only=True)
    assert saved["central"]["value_count"] > 1 and saved["central"]["critic_count"] > 1
    assert "central" not in torch.load(runs["lean"] / "checkpoints/latest/state.pt",
                                       weights_only=True)  # fmt: skip


def test_a_mappo_checkpoint_restores_the_critics_statistics(mappo_run, tmp_path):
    from uasep_env.interface.observation import state_dim

    args = mappo.parse_args([*TINY, "--trainer", "lean", "--out-dir", "unused"])
    config = ppo_shared.make_env_config(args)
    ck = mappo_run / "checkpoints" / f"step_{EVERY}"
    state = _fresh_state(args, config, central=True)
    assert lean_recipe.load_checkpoint(state, ck, args)["updates"] == 2
    saved = torch.load(ck / "state.pt", weights_only=True)["central"]
    for prefix, rms in (("critic_", state.critic_norm.obs_rms), ("value_", state.value_scale.rms)):
        np.testing.assert_array_equal(rms.mean, saved[prefix + "mean"].numpy())
        np.testing.assert_array_equal(rms.var, saved[prefix + "var"].numpy())
        assert rms.count == float(saved[prefix + "count"]) > 1
    width = state_dim(config) + state.norm.obs_rms.mean.shape[0]
    assert state.critic_norm.obs_rms.mean.shape == (width,)
    # Saved again, the same statistics.
    again = tmp_path / "again"
    info = {k: v for k, v in _state(ck).items() if k != "args"}
    lean_recipe.save_checkpoint(state, config, args, again, info)
    twice = torch.load(again / "state.pt", weights_only=True)["central"]
    assert twice.keys() == saved.keys()
    assert all(torch.equal(twice[k], saved[k]) for k in saved)


def test_a_mappo_run_resumes_its_own_checkpoints_only(mappo_run, runs, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(mappo_run, out, symlinks=True)
    _train_mappo(out, "--resume", str(out / "checkpoints" / f"step_{EVERY}"), total=6 * PER_UPDATE)
    assert _state(out / "checkpoints" / "latest")["updates"] == 6
    for ck, extra, want in (
        (runs["lean"], ("--trainer", "lean"), "a PPO checkpoint, not MAPPO's"),
        (
            mappo_run,
            ("--batch-size", "64"),  # skrl's MAPPO
            "a checkpoint of --trainer lean; resume it with --trainer lean",
        ),
    ):
        argv = [*TINY, *extra, "--resume", str(ck / "checkpoints/latest"),
                "--out-dir", str(tmp_path / "new"), "--total-timesteps", str(TOTAL)]  # fmt: skip
        with pytest.raises((SystemExit, RunError), match=want):
            mappo.main(argv)
        assert not (tmp_path / "new").exists()
    # Nor under the other value normalisation: its statistics are there or not.
    argv = [*TINY, "--trainer", "lean", "--no-value-norm", "--out-dir", str(tmp_path / "new"),
            "--resume", str(mappo_run / "checkpoints/latest"),
            "--total-timesteps", str(TOTAL + PER_UPDATE)]  # fmt: skip
    want = "a checkpoint of --value-norm; resume it with --value-norm"
    with pytest.raises((SystemExit, RunError), match=want):
        mappo.main(argv)
    assert not (tmp_path / "new").exists()
    with pytest.raises((SystemExit, RunError), match="a MAPPO checkpoint, not PPO's"):
        _train(tmp_path / "new", "--trainer", "lean", "--resume",
               str(mappo_run / "checkpoints/latest"))  # fmt: skip
    assert not (tmp_path / "new").exists()


def test_value_norm_off_trains_raw_returns_and_resumes(tmp_path):
    out = tmp_path / "run"
    _train_mappo(out, "--no-value-norm", total=2 * PER_UPDATE)
    saved = torch.load(out / "checkpoints/latest/state.pt", weights_only=True)["central"]
    assert {k.split("_")[0] for k in saved} == {"critic"}  # no value statistics to keep
    ck = out / "checkpoints" / "latest"
    _train_mappo(out, "--no-value-norm", "--resume", str(ck), total=3 * PER_UPDATE)
    assert _state(out / "checkpoints" / "latest")["updates"] == 3


def test_skrls_mappo_resumes_under_its_checkpoints_value_norm_only(mappo_run, tmp_path):
    # A checkpoint of skrl's trainer (here a lean one relabelled: refused before it is read).
    ck = tmp_path / "ck"
    shutil.copytree(mappo_run / "checkpoints" / "latest", ck)
    state = _state(ck)
    state["args"]["trainer"] = "default"
    (ck / "state.json").write_text(json.dumps(state))
    argv = [*TINY, "--batch-size", "64", "--no-value-norm", "--resume", str(ck),
            "--out-dir", str(tmp_path / "new")]  # fmt: skip
    want = "a checkpoint of --value-norm; resume it with --value-norm"
    with pytest.raises((SystemExit, RunError), match=want):
        mappo.main(argv)
    assert not (tmp_path / "new").exists()


def test_value_norm_off_is_skrls_mappo_without_its_value_preprocessor(tmp_path):
    pytest.importorskip("skrl")
    flags = [*TINY, "--batch-size", "64", "--out-dir", str(tmp_path)]
    for extra, kept in (([], True), (["--no-value-norm"], False)):
        args = mappo.parse_args([*flags, *extra])
        _, env, agent = mappo.build(args, ppo_shared.make_env_config(args))
        for uid in env.possible_agents:
            assert ("value_preprocessor" in agent.checkpoint_modules[uid]) == kept


# 7. EpisodeSafety.


def _world(pos: list, time: list) -> SimpleNamespace:
    """A batch of 3 environments of 2 UAVs, UAV 1 of each at ``pos`` (planned at the origin)."""
    uav = np.zeros((3, 2, 3))
    uav[:, 1, 0] = pos
    return SimpleNamespace(uav_pos=uav, plan_pos=np.zeros((3, 2, 3)), time=np.array(time))


def _flags(collision=(), los_uav=(), los_obstacle=()) -> dict:
    """A step's safety figures: the listed ``(env, uav)`` entries set."""
    out = {}
    for key, hits in (("collision", collision), ("loss_of_separation_uav", los_uav),
                      ("loss_of_separation_obstacle", los_obstacle)):  # fmt: skip
        a = np.zeros((3, 2), dtype=bool)
        for e, i in hits:
            a[e, i] = True
        out[key] = a
    return out


def test_episode_safety_folds_flags_with_or_and_deviation_with_max_once_settled():
    s = EpisodeSafety(3)
    early, late = DEFAULT_SETTLE_TIME_S - 0.2, DEFAULT_SETTLE_TIME_S
    # Before the formation has formed up a deviation does not count.
    s.track(_world([50.0, 60.0, 70.0], [early] * 3), _flags(collision=[(0, 1)]))
    assert s.summary(0) == {"collision": True, "loss_of_separation": False, "max_deviation": 0.0}
    assert s.summary(1)["max_deviation"] == 0.0
    # Environment 2 has settled (each its own clock), 0 and 1 not yet.
    s.track(_world([5.0, 6.0, 7.0], [early, early, late]), _flags(los_uav=[(1, 0)]))
    s.track(_world([3.0, 4.0, 2.0], [late] * 3), _flags(los_obstacle=[(2, 1)]))
    s.track(_world([1.0, 9.0, 1.0], [late + 0.2] * 3), _flags())  # clean steps leave flags set
    assert s.summary(0) == {"collision": True, "loss_of_separation": False, "max_deviation": 3.0}
    assert s.summary(1) == {"collision": False, "loss_of_separation": True, "max_deviation": 9.0}
    assert s.summary(2) == {"collision": False, "loss_of_separation": True, "max_deviation": 7.0}
    # The deviation is the largest over the UAVs, in 3-D.
    w = _world([0.0, 0.0, 0.0], [late] * 3)
    w.uav_pos[1, 0] = [3.0, 4.0, 12.0]
    s.track(w, _flags())
    assert s.summary(1)["max_deviation"] == 13.0
    # A mask clears its environments only.
    s.clear(np.array([False, True, False]))
    assert s.summary(1) == {"collision": False, "loss_of_separation": False, "max_deviation": 0.0}
    assert s.summary(0)["collision"] and s.summary(0)["max_deviation"] == 3.0
    assert s.summary(2)["loss_of_separation"] and s.summary(2)["max_deviation"] == 7.0
    s.clear()
    for e in range(3):
        assert s.summary(e) == {"collision": False, "loss_of_separation": False,
                                "max_deviation": 0.0}  # fmt: skip
    assert type(s.summary(0)["collision"]) is bool
    assert type(s.summary(0)["max_deviation"]) is float


# 8. The lean rollout's finished episodes are the SB3 view's.


def test_the_lean_rollouts_finished_episodes_are_the_sb3_views():
    """Zero actions in both, the same seeds: the same episodes, figure for figure.

    60 s episodes (300 steps) of the pure policy: zero actions drift, so the episodes
    differ (one ends in a collision, some lose separation, each deviates its own way after
    the formation has formed up), and a second episode runs in the environment that ended.
    """
    from stable_baselines3.common.vec_env import VecMonitor

    from uasep_env.envs.core import EnvCore
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    args = ppo_shared.parse_args(["--out-dir", "unused", "--n-envs", "4", "--n-steps", "400",
                                  "--episode-duration", "60"])  # fmt: skip
    config = ppo_shared.make_env_config(args)
    core = EnvCore(config, n_envs=args.n_envs)
    nets = ppo_lean._ActorCritic(core.obs_dim, args)
    with torch.no_grad():  # a mean of zero and no noise: zero actions, exactly
        nets.mu.weight.zero_()
        nets.mu.bias.zero_()
        nets.log_std.fill_(-math.inf)
    norm = ppo_lean.Normaliser(core.obs_dim, args.n_envs * config.n_uavs, norm_obs=True,
                               norm_reward=False, gamma=args.gamma)  # fmt: skip
    state = ppo_lean.State(nets=nets, learner=nets, opt=None, norm=norm)
    roll = ppo_lean._Rollout(core, state, args.n_steps)
    roll.reset(args.seed)
    roll.collect(args.gamma)
    assert not roll.act.any()

    venv = VecMonitor(UAVSharedVecEnv(n_envs=args.n_envs, config=config, seed=args.seed))
    venv.reset()
    n, want = config.n_uavs, []
    for _ in range(args.n_steps):
        _, _, _, infos = venv.step(np.zeros((venv.num_envs, 3), np.float32))
        for k, info in enumerate(infos):
            if k % n == 0 and "episode_safety" in info:  # the first UAV's, as the callback
                s, ep = info["episode_safety"], info["episode"]
                want.append((ep["r"], s["collision"], s["loss_of_separation"],
                             s["max_deviation"], ep["l"]))  # fmt: skip
    got = state.finished
    assert len(got) == len(want) == state.episodes == 5
    for mine, theirs in zip(got, want, strict=True):
        assert mine[0] == pytest.approx(float(theirs[0]), rel=1e-5)  # float32 in VecMonitor
        assert mine[1:4] == tuple(theirs[1:4])
        assert mine[4] == int(theirs[4])
    # Not a vacuous comparison: the flags and the deviations vary.
    assert {e[1] for e in got} == {e[2] for e in got} == {True, False}
    assert min(e[3] for e in got) == 0.0 < max(e[3] for e in got)
    assert len({e[4] for e in got}) > 1
