"""PPO-Lagrangian on the lean loop (``uasep-train ppo_lagrangian[_residual] --trainer lean``).

:class:`~uasep_env.training.constraint.LeanCost` shapes the rewards as SB3's
:class:`~uasep_env.training.sb3_lagrangian.LagrangianCallback` does (compared bit for bit on
the same arrays), the lean loop learns from what it returns (the rewards GAE reads), and a
tiny run writes the constraint's files, keeps its state in every checkpoint and continues
its multiplier on ``--resume``.
"""

import csv
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")

from uasep_env.training import ppo_lagrangian, ppo_lean, ppo_shared  # noqa: E402
from uasep_env.training.constraint import COST_FIELDS, LeanCost  # noqa: E402
from uasep_env.training.lagrangian import PIDLagrangian  # noqa: E402
from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS  # noqa: E402
from uasep_env.training.sb3_lagrangian import LagrangianCallback  # noqa: E402

TINY = [
    "--n-envs", "4", "--n-steps", "16", "--batch-size", "192", "--n-epochs", "2",
    "--hidden", "16", "--episode-duration", "4", "--eval-episodes", "2", "--no-progress",
    "--budget-episodes", "2", "--trainer", "lean", "--torch-threads", "1",
]  # fmt: skip
PER_UPDATE = 4 * 16 * 3  # agent-steps an update (the default 3 UAVs)


def _pid(**kw: float) -> PIDLagrangian:
    return PIDLagrangian(0.5, kp=1.0, ki=0.2, ema_p=0.9, init=kw.pop("init", 1.0), **kw)


def test_lean_cost_shapes_and_counts_as_the_sb3_callback_does():
    rng = np.random.default_rng(3)
    e, n = 5, 3
    lean, sb3 = LeanCost(_pid()), LagrangianCallback(_pid())
    lean.start(e * n)
    sb3.tracker.start(e * n)
    for _ in range(40):
        cost = rng.integers(0, 2, (e, n)).astype(np.float64)
        reward = rng.normal(size=e * n).astype(np.float32)
        dones = np.repeat(rng.random(e) < 0.2, n)
        theirs = reward.copy()
        sb3.locals = {"infos": [{"cost": c} for c in cost.reshape(-1).tolist()],
                      "rewards": theirs, "dones": dones}  # fmt: skip
        sb3._on_step()
        mine = lean.shape(SimpleNamespace(cost=cost), reward.copy(), dones)
        assert mine.dtype == np.float32
        np.testing.assert_array_equal(mine, theirs)
        if rng.random() < 0.3:
            lean.rollout_end(0)
            sb3.tracker.end_rollout(0)
            assert lean.lagrangian.multiplier == sb3.lagrangian.multiplier
    assert lean.lagrangian.updates > 0 and lean.lagrangian.multiplier != 1.0
    assert lean.state_dict() == sb3.state_dict()


def test_lean_cost_reads_a_named_cost_term_and_leaves_rewards_at_a_zero_multiplier():
    cost = LeanCost(_pid(init=0.0), cost="separation_uav")
    cost.start(2)
    res = SimpleNamespace(cost=np.full((1, 2), 9.0),
                          cost_terms={"separation_uav": np.array([[1.0, 0.0]])})  # fmt: skip
    reward = np.array([0.5, 0.25], dtype=np.float32)
    assert cost.shape(res, reward, np.array([True, True])) is reward  # lambda = 0
    assert list(cost.tracker.window) == [1.0, 0.0]
    with pytest.raises(ValueError, match=r"cost='bogus'.*not reported"):
        LeanCost(_pid(), cost="bogus")


def test_the_lean_loop_learns_from_the_rewards_its_hooks_shape(monkeypatch):
    from uasep_env.training.args import make_env_config

    args = ppo_shared.parse_args([*TINY[:-6], "--trainer", "lean", "--episode-duration", "60",
                                  "--total-timesteps", str(PER_UPDATE)])  # fmt: skip
    seen: list[np.ndarray] = []
    real_gae = ppo_lean.gae

    def gae(rewards, *rest):
        seen.append(rewards.copy())
        return real_gae(rewards, *rest)

    class Sevens(ppo_lean.Hooks):
        def shape(self, res, reward, dones):
            return np.full_like(reward, 7.0)

    monkeypatch.setattr(ppo_lean, "gae", gae)
    ppo_lean.train(args, make_env_config(args), Sevens())
    assert len(seen) == 1 and (seen[0] == 7.0).all()  # no episode ends: no bootstrap added


def _train(out: Path, *extra: str, total: int) -> dict:
    argv = [*TINY, "--total-timesteps", str(total), "--checkpoint-every", str(2 * PER_UPDATE),
            "--out-dir", str(out), "--cost-limit", "0", *extra]  # fmt: skip
    return ppo_lagrangian.main(argv, RESIDUAL_LAGRANGIAN_DEFAULTS)


def _cost_rows(out: Path) -> list[dict]:
    with (out / "cost_progress.csv").open() as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("lean_lagrangian") / "run"
    _train(out, total=5 * PER_UPDATE)
    return out


def test_a_lean_lagrangian_run_writes_the_constraints_files_and_state(run):
    for name in ("cost_progress.csv", "cost_curves.png", "budget.json", "policy.zip"):
        assert (run / name).is_file(), name
    rows = _cost_rows(run)
    assert tuple(rows[0]) == COST_FIELDS
    assert [int(r["agent_steps"]) for r in rows] == [PER_UPDATE * k for k in range(1, 6)]
    assert all(float(r["cost_limit"]) == 0.0 for r in rows)
    training = json.loads((run / "validation.json").read_text())["training"]
    lag = training["lagrangian"]
    assert lag["cost_limit_option"] == "0" and lag["cost"] == "cost"
    assert lag["multiplier"] == float(rows[-1]["multiplier"])
    assert lag["state"]["episodes"] == int(rows[-1]["agent_episodes"]) > 0
    state = json.loads((run / "checkpoints" / f"step_{2 * PER_UPDATE}" / "state.json").read_text())
    assert state["lagrangian"]["state"]["episodes"] == int(rows[1]["agent_episodes"])


def test_a_lean_lagrangian_run_resumes_its_multiplier_and_rewinds_its_csv(run, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(run, out, symlinks=True)
    ck = out / "checkpoints" / f"step_{2 * PER_UPDATE}"
    saved = json.loads((ck / "state.json").read_text())["lagrangian"]["state"]
    # A multiplier of our own in the checkpoint: the resumed run must start from it.
    saved.update(multiplier=3.5, integral=3.5)
    state = json.loads((ck / "state.json").read_text())
    state["lagrangian"]["state"] = saved
    (ck / "state.json").write_text(json.dumps(state))
    before = _cost_rows(run)
    _train(out, "--resume", str(ck), total=5 * PER_UPDATE)
    rows = _cost_rows(out)
    assert rows[:2] == before[:2]  # rewound to the checkpoint, then three more rollouts
    assert [int(r["agent_steps"]) for r in rows] == [PER_UPDATE * k for k in range(1, 6)]
    assert int(rows[-1]["agent_episodes"]) > saved["episodes"] > 0  # counted on
    assert float(rows[2]["multiplier"]) >= 3.5 - 1.0  # a fresh start would be near 1


def test_mappo_lagrangian_still_refuses_the_lean_trainer(capsys, tmp_path):
    from uasep_env.training import mappo_lagrangian

    with pytest.raises(SystemExit):
        mappo_lagrangian.parse_args(["--trainer", "lean", "--out-dir", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert "argument --trainer: 'lean' is not for this Lagrangian recipe" in err, err
