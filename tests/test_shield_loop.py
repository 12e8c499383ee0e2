"""Training under the shield (``--shield cbf``): the CBF filter in the lean loop.

The core steps with the filtered actions (the loop's wiring, seen failing with the hook
skipped), the filter is the evaluation shield's (the same numbers), its interventions are the
``--cost shield`` of the PPO-Lagrangian recipes, a run validates (and the seed studies
evaluate) its checkpoints shielded, and the flags that cannot work are refused in one line.
"""

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from uasep_env import make_config  # noqa: E402
from uasep_env.envs.core import EnvCore  # noqa: E402
from uasep_env.policies import APF, APFGains, Shielded, load_policy  # noqa: E402
from uasep_env.training import ppo_lagrangian, ppo_lean, ppo_shared  # noqa: E402
from uasep_env.training.ppo_lagrangian import RESIDUAL_LAGRANGIAN_DEFAULTS  # noqa: E402
from uasep_env.training.shield_loop import ShieldInLoop, deployed  # noqa: E402

TINY = [
    "--n-envs", "4", "--n-steps", "16", "--batch-size", "192", "--n-epochs", "1",
    "--hidden", "16", "--eval-episodes", "2", "--no-progress", "--trainer", "lean",
    "--torch-threads", "1",
]  # fmt: skip
PER_UPDATE = 4 * 16 * 3


def test_the_loop_filter_is_the_evaluation_shield_and_counts_its_interventions():
    # A collision course flown by an APF that does not avoid: the shield must act.
    cfg = make_config(scenario="collision_head_on")
    plan_only = APF(cfg, APFGains(k_obstacle=0.0))
    shield, loop = Shielded(plan_only, cfg), ShieldInLoop(cfg)
    core = EnvCore(cfg, 2)
    obs = core.reset(seed=4)
    changed = 0
    for _ in range(300):
        wanted = plan_only(obs)
        flown = loop.act(np.clip(wanted, -1.0, 1.0), obs)
        np.testing.assert_array_equal(flown, shield(obs))  # the deployed shield's numbers
        moved = np.abs(flown - wanted).max(axis=-1) > 1e-3
        np.testing.assert_array_equal(loop.interventions, moved.reshape(-1).astype(float))
        changed += int(moved.sum())
        obs = core.step(flown).obs
    assert changed > 0 and loop.count == changed and loop.rate() == changed / (300 * 2 * 3)


def test_the_lean_loop_steps_the_core_with_what_its_hook_returns(monkeypatch):
    from uasep_env.training.args import make_env_config

    args = ppo_shared.parse_args([*TINY, "--episode-duration", "60",
                                  "--total-timesteps", str(PER_UPDATE)])  # fmt: skip
    stepped: list[np.ndarray] = []
    real_step = EnvCore.step

    def step(self, actions, *a, **kw):
        stepped.append(np.array(actions))
        return real_step(self, actions, *a, **kw)

    seen: list[np.ndarray] = []

    class Halve(ppo_lean.Hooks):
        def act(self, actions, observations):
            seen.append(observations.copy())
            return (actions * 0.5).astype(np.float32) + 0.25

    monkeypatch.setattr(EnvCore, "step", step)
    ppo_lean.train(args, make_env_config(args), Halve())
    assert len(stepped) == 16 and len(seen) == 16
    # What the hook returned was flown: in [-0.25, 0.75], never a sampled action's -1.
    assert all(s.min() >= -0.25 - 1e-6 and s.max() <= 0.75 + 1e-6 for s in stepped)
    # The hook reads the raw observations (not normalised): the formation's own slot.
    cfg = make_env_config(args)
    fresh = EnvCore(cfg, args.n_envs).reset(seed=args.seed)
    np.testing.assert_array_equal(seen[0], fresh)


@pytest.fixture(scope="module")
def shielded_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("shield_loop") / "run"
    argv = [*TINY, "--episode-duration", "4", "--total-timesteps", str(3 * PER_UPDATE),
            "--checkpoint-every", str(2 * PER_UPDATE),
            "--out-dir", str(out), "--shield", "cbf", "--cost", "shield",
            "--cost-limit", "1"]  # fmt: skip
    ppo_lagrangian.main(argv, RESIDUAL_LAGRANGIAN_DEFAULTS)
    return out


def test_a_shielded_lagrangian_run_constrains_the_interventions(shielded_run):
    training = json.loads((shielded_run / "validation.json").read_text())["training"]
    assert training["lagrangian"]["cost"] == "shield"
    rate = training["shield"]["interventions_per_agent_step"]
    assert 0.0 < rate <= 1.0  # the residual APF's formation binds the barriers at times
    rows = (shielded_run / "cost_progress.csv").read_text().splitlines()[1:]
    costs = [float(r.split(",")[2]) for r in rows if r.split(",")[2] != "nan"]
    assert costs and max(costs) > 1.0  # episode costs are intervention counts
    # Validated and deployed shielded.
    policy = shielded_run / "policy.zip"
    assert deployed(policy) == f"{policy}+cbf"
    assert (
        deployed(Path(__file__).parents[1] / "baselines/checkpoints/ppo_residual_apf.zip")[-4:]
        != "+cbf"
    )
    assert load_policy(policy).meta.info["args"]["shield"] == "cbf"
    # validation.json holds the shielded policy's figures on its encounters, not the bare one's.
    from uasep_env.evaluation import evaluate
    from uasep_env.scenarios import VALIDATION_SEEDS

    seen = json.loads((shielded_run / "validation.json").read_text())["validation"]["learned"]
    cfg = load_policy(policy).config
    seeds = list(VALIDATION_SEEDS)[:2]
    played = evaluate({"s": f"{policy}+cbf", "b": str(policy)}, cfg, seeds).results
    dev = {k: r.aggregate["episode.max_deviation"]["mean"] for k, r in played.items()}
    assert dev["s"] != dev["b"]  # the shield moves these episodes: the check can tell
    assert seen["max_deviation"] == pytest.approx(dev["s"], rel=1e-12)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--shield", "cbf"], "argument --shield: 'cbf' trains with --trainer lean only"),
        (
            ["--trainer", "lean", "--cost", "shield"],
            "'shield' counts the shield's interventions; add --shield cbf",
        ),
        (
            ["--trainer", "lean", "--shield", "cbf", "--cost", "shield"],
            "argument --cost-limit: 'apf'",
        ),
        (["--cost", "bogus"], "cost 'bogus' is not reported"),
    ],
)
def test_shield_flags_that_cannot_work_are_refused_in_one_line(capsys, tmp_path, flags, message):
    with pytest.raises(SystemExit):
        ppo_lagrangian.parse_args([*flags, "--out-dir", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1], err
    with pytest.raises(SystemExit):
        ppo_shared.parse_args(["--shield", "cbf", "--out-dir", str(tmp_path / "r")])
    assert "--trainer lean only" in capsys.readouterr().err


def test_a_shielded_run_resumes_under_the_shield(shielded_run, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(shielded_run, out, symlinks=True)
    ck = out / "checkpoints" / f"step_{2 * PER_UPDATE}"
    assert ck.is_dir()
    argv = [*TINY, "--episode-duration", "4", "--total-timesteps", str(4 * PER_UPDATE),
            "--out-dir", str(out), "--shield", "cbf", "--cost", "shield", "--cost-limit", "1",
            "--resume", str(ck)]  # fmt: skip
    ppo_lagrangian.main(argv, RESIDUAL_LAGRANGIAN_DEFAULTS)
    training = json.loads((out / "validation.json").read_text())["training"]
    assert training["agent_steps"] == 4 * PER_UPDATE
    assert training["shield"]["interventions_per_agent_step"] > 0.0  # still shielded
    assert training["lagrangian"]["cost"] == "shield"
