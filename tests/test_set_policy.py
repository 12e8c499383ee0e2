"""The permutation-invariant policy (``--arch set``): invariance, any K, training, checkpoints."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

from uasep_env import make_config  # noqa: E402
from uasep_env.envs.core import EnvCore  # noqa: E402
from uasep_env.policies import checkpoint_config, load_policy, observed_config  # noqa: E402
from uasep_env.policies.checkpoint import META, WEIGHTS, CheckpointError, StoredLayout  # noqa: E402
from uasep_env.policies.checkpoint_reader import read_checkpoint  # noqa: E402
from uasep_env.policies.set_network import split_layout, tensor_shapes  # noqa: E402
from uasep_env.training import mappo, ppo_lean, ppo_shared  # noqa: E402
from uasep_env.training.args import Args, make_env_config  # noqa: E402
from uasep_env.training.lean_networks import _ActorCritic  # noqa: E402
from uasep_env.training.rundir import RunError  # noqa: E402

# 5 UAVs and 2 obstacles, 4 UAV and 2 obstacle slots: neighbours to reorder.
ARGS = {"n_uavs": 5, "k_uavs": 4, "n_obstacles": 2, "k_obstacles": 2, "hidden": "16,16"}


def _export(tmp: Path, arch: str) -> tuple[Path, object, object, object]:
    """An untrained but non-trivial network of ``arch`` and its tied statistics, exported."""
    torch.manual_seed(1)
    args = Args(arch=arch, **ARGS)
    config = make_env_config(args)
    layout = StoredLayout.from_config(config)
    nets = _ActorCritic(EnvCore(config, n_envs=1).obs_dim, args, None, layout)
    torch.nn.init.orthogonal_(nets.mu.weight, gain=1.0)  # actions well away from 0
    tied = split_layout(layout) if arch == "set" else None
    norm = ppo_lean.Normaliser(
        nets_dim(config), 5, norm_obs=True, norm_reward=False, gamma=0.99, tied=tied
    )
    for seed in range(3):
        norm.observe(_obs(config, seed), update=True)
    path = ppo_lean.export_policy(nets, norm, config, args, tmp / f"{arch}.zip", {})
    return path, nets, norm, config


def nets_dim(config: object) -> int:
    return EnvCore(config, n_envs=1).obs_dim


def _obs(config: object, seed: int, steps: int = 20) -> np.ndarray:
    """Observations a few steps into an encounter (neighbours and obstacles in view)."""
    core = EnvCore(config.replace(action={"mode": "direct"}), n_envs=2)
    obs = core.reset(seed=seed)
    for _ in range(steps):
        obs = core.step(np.zeros((2, core.n_uavs, 3), np.float32)).obs
    return obs.reshape(-1, core.obs_dim)


@pytest.fixture(scope="module")
def policies(tmp_path_factory: pytest.TempPathFactory) -> dict:
    tmp = tmp_path_factory.mktemp("set")
    return {arch: _export(tmp, arch) for arch in ("set", "mlp")}


def _permuted(config: object, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``obs`` with each row's UAV slots and obstacle slots in another order (masks along)."""
    split = split_layout(StoredLayout.from_config(config.replace(action={"mode": "direct"})))
    out = obs.copy()
    for s in split.slots.values():
        end = s.start + s.k * s.width
        for row in out:
            blocks = row[s.start : end].reshape(s.k, s.width).copy()
            row[s.start : end] = blocks[rng.permutation(s.k)[::-1]].reshape(-1)
    return out


# (a) Permutation invariance; the slot MLP is not.


def test_the_action_does_not_depend_on_the_order_of_the_neighbours(policies):
    rng = np.random.default_rng(0)
    path, _, _, config = policies["set"]
    cfg = config.replace(action={"mode": "direct"})
    obs = _obs(config, 7)
    shuffled = _permuted(config, obs, rng)
    assert not np.array_equal(obs, shuffled)  # neighbours were there to reorder
    policy = load_policy(path, cfg)
    np.testing.assert_allclose(policy.network(shuffled), policy.network(obs), atol=1e-5)
    # The slot MLP reads slots, not neighbours: the same reordering changes its action.
    mlp = load_policy(policies["mlp"][0], cfg)
    assert np.abs(mlp.network(shuffled) - mlp.network(obs)).max() > 1e-3


def test_unobserved_slots_are_left_out(policies):
    path, _, _, config = policies["set"]
    cfg = config.replace(action={"mode": "direct"})
    obs = _obs(config, 3)
    split = split_layout(StoredLayout.from_config(cfg))
    s = split.slots["uav"]
    last = s.start + (s.k - 1) * s.width  # the farthest UAV slot: made absent, then noise
    obs[:, last : last + s.width] = 0.0
    noisy = obs.copy()
    noise = np.random.default_rng(1).normal(size=(len(obs), s.width)).astype(np.float32)
    noise[:, s.mask] = 0.0
    noisy[:, last : last + s.width] = noise
    policy = load_policy(path, cfg)
    np.testing.assert_array_equal(policy.network(noisy), policy.network(obs))


def test_torch_and_numpy_forward_passes_agree(policies):
    path, nets, norm, config = policies["set"]
    obs = _obs(config, 5)
    with torch.no_grad():
        want = nets.mu(nets.pi(torch.from_numpy(norm.normalise(obs)))).numpy()
    got = load_policy(path, config.replace(action={"mode": "direct"})).network(obs)
    np.testing.assert_allclose(got, want, atol=1e-6)


# (b) Any K: the set network zero-shot, the slot MLP refused.


@pytest.mark.parametrize(("n_uavs", "k_uavs"), [(3, 2), (16, 7)])
def test_one_checkpoint_acts_with_any_number_of_neighbour_slots(policies, n_uavs, k_uavs):
    path = policies["set"][0]
    cfg = make_config(n_uavs=n_uavs, n_obstacles=2, observation={"k_uavs": k_uavs})
    assert observed_config(path, cfg).observation.k_uavs == k_uavs  # the env's K kept
    built = checkpoint_config(path, n_uavs=n_uavs, observation={"k_uavs": k_uavs})
    assert built.observation.k_uavs == k_uavs
    policy = load_policy(path, built)
    obs = _obs(built, 2, steps=3)
    act = policy(obs)
    assert act.shape == (len(obs), 3) and np.isfinite(act).all()


def test_the_slot_mlp_refuses_another_k_in_one_line(policies):
    path = policies["mlp"][0]
    cfg = make_config(n_uavs=16, n_obstacles=2, observation={"k_uavs": 7, "k_obstacles": 2})
    with pytest.raises(CheckpointError) as info:
        load_policy(path, cfg)
    message = str(info.value)
    assert "\n" not in message and "k_uavs" in message and "4 nearest UAVs" in message
    assert observed_config(path, cfg).observation.k_uavs == 4  # its own K, as before


# (c) A tiny training run.

TINY = [
    "--n-envs", "2", "--n-steps", "16", "--batch-size", "96", "--n-epochs", "1",
    "--hidden", "16", "--episode-duration", "4", "--eval-episodes", "1", "--no-progress",
    "--trainer", "lean", "--arch", "set", "--total-timesteps", "2000",
]  # fmt: skip


@pytest.mark.parametrize("recipe", ["ppo_shared", "mappo"])
def test_a_tiny_set_run_writes_a_checkpoint_that_loads_and_evaluates(recipe, tmp_path):
    from uasep_env.evaluation import evaluate

    main = {"ppo_shared": ppo_shared.main, "mappo": mappo.main}[recipe]
    out = tmp_path / "run"
    main([*TINY, "--out-dir", str(out)])
    meta, weights, _, _ = read_checkpoint(out / "policy.zip")
    assert meta.architecture == "set" and meta.info["args"]["arch"] == "set"
    assert len(weights) == len(tensor_shapes(meta.observation_layout, meta.hidden))
    with zipfile.ZipFile(out / "policy.zip") as z:  # JSON and plain arrays, nothing else
        assert sorted(z.namelist()) == sorted([META, WEIGHTS])
    cfg = make_config(n_uavs=5, episode_duration=4.0, observation={"k_uavs": 4})
    result = evaluate({"set": load_policy(out / "policy.zip", cfg)}, cfg, [0])
    assert result.results["set"].aggregate
    if recipe == "ppo_shared":  # a resume under the other --arch is refused in one line
        with pytest.raises(SystemExit) as info:
            ppo_shared.main([*TINY[:-4], "--out-dir", str(tmp_path / "r"),
                             "--resume", str(out / "checkpoints" / "latest")])  # fmt: skip
        assert isinstance(info.value, RunError)
        assert "resume it with --arch set" in str(info.value)


def test_sb3_refuses_arch_set_in_one_line(capsys):
    with pytest.raises(SystemExit):
        ppo_shared.parse_args(["--arch", "set"])
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--arch" in err and "--trainer lean" in err


# (d) A tampered set checkpoint.


def _tampered(path: Path, tmp: Path, change) -> Path:
    with zipfile.ZipFile(path) as z:
        desc = json.loads(z.read(META))
        with np.load(io.BytesIO(z.read(WEIGHTS))) as npz:
            arrays = dict(npz)
    change(desc, arrays)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    out = tmp / "tampered.zip"
    with zipfile.ZipFile(out, "w") as z:
        z.writestr(META, json.dumps(desc))
        z.writestr(WEIGHTS, buf.getvalue())
    return out


def _wrong_shape(desc: dict, a: dict) -> None:
    a["uav.key.weight"] = a["uav.key.weight"][:, :-1]


def _nan(desc: dict, a: dict) -> None:
    a["head0.bias"][0] = np.nan


def _missing(desc: dict, a: dict) -> None:
    del a["obstacle.encoder.weight"]


def _untied(desc: dict, a: dict) -> None:
    w = 8  # one UAV slot: the second slot's statistics moved
    start = [n for n, _ in desc["layout"]["features"]].index("uav1.rel_pos")
    col = sum(width for _, width in desc["layout"]["features"][:start])
    a["obs_mean"][col] += 1.0
    assert w == sum(width for n, width in desc["layout"]["features"] if n.startswith("uav0."))


def _unknown_arch(desc: dict, a: dict) -> None:
    desc["architecture"] = "transformer"


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (_wrong_shape, "uav.key.weight.npy: shape"),
        (_nan, "head0.bias.npy: non-finite"),
        (_missing, "obstacle.encoder.weight.npy"),
        (_untied, "slot uav1's statistics differ from uav0's"),
        (_unknown_arch, "architecture must be one of"),
    ],
)
def test_a_tampered_set_checkpoint_is_refused_in_one_line(policies, tmp_path, change, named):
    bad = _tampered(policies["set"][0], tmp_path, change)
    with pytest.raises(CheckpointError) as info:
        read_checkpoint(bad)
    message = str(info.value)
    assert "\n" not in message and named in message, message


def test_a_set_run_resumes_from_its_checkpoints(tmp_path):
    """Resumed at its end, a set run exports the same weights; from mid-run it trains on."""
    import shutil

    out = tmp_path / "run"
    ppo_shared.main([*TINY, "--checkpoint-every", "500", "--out-dir", str(out)])
    copy = tmp_path / "copy"
    shutil.copytree(out, copy, symlinks=True)
    (copy / "policy.zip").unlink()
    ppo_shared.main([*TINY, "--out-dir", str(copy),
                     "--resume", str(copy / "checkpoints" / "latest")])  # fmt: skip
    theirs, mine = read_checkpoint(out / "policy.zip"), read_checkpoint(copy / "policy.zip")
    assert mine[0].architecture == "set"
    for a, b in zip(theirs[1], mine[1], strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    first = min((out / "checkpoints").glob("step_*"), key=lambda p: int(p.name[5:]))
    again = tmp_path / "again"
    shutil.copytree(out, again, symlinks=True)
    summary = ppo_shared.main([*TINY, "--out-dir", str(again), "--resume",
                               str(again / "checkpoints" / first.name)])  # fmt: skip
    assert summary["training"]["agent_steps"] >= 2000
    assert read_checkpoint(again / "policy.zip")[0].architecture == "set"


# (e) Trained at several formation sizes (--formation-sizes).


def test_a_smaller_formations_padded_observation_acts_as_its_own(policies):
    """3 UAVs observe 2 UAV slots; padded to the trained 4 (zeros, masks 0), the action is
    the one the policy takes on the 3 UAVs' own observation, bit for bit."""
    path, _, _, config = policies["set"]
    small = config.replace(n_uavs=3, action={"mode": "direct"})
    full = config.replace(action={"mode": "direct"})
    obs = _obs(small, 4)
    pad = ppo_lean._padding(small, full)
    padded = pad(obs)
    assert padded.shape == (len(obs), nets_dim(full)) and obs.shape[1] < padded.shape[1]
    mine = load_policy(path, small).network(obs)
    np.testing.assert_array_equal(load_policy(path, full).network(padded), mine)
    # The slots past the formation's own are absent: a present one would change the action.
    s = split_layout(StoredLayout.from_config(full)).slots["uav"]
    padded[:, s.start + 3 * s.width + s.mask] = 1.0
    assert np.abs(load_policy(path, full).network(padded) - mine).max() > 1e-3
    assert ppo_lean._padding(full, full) is None  # the same width: nothing to pad


SIZES = [*TINY, "--n-uavs", "5", "--k-uavs", "4", "--n-obstacles", "2", "--k-obstacles", "2"]


def test_a_run_of_several_formation_sizes_trains_them_in_turn(tmp_path):
    out = tmp_path / "run"
    ppo_shared.main([*SIZES, "--formation-sizes", "3,5", "--out-dir", str(out)])
    rows = (out / "progress.csv").read_text().splitlines()[1:]
    steps = [int(r.split(",")[0]) for r in rows]
    per = [b - a for a, b in zip([0, *steps], steps, strict=False)]
    # Rollouts of 2 environments x 16 steps: 5 UAVs (--n-uavs, first), then 3, in turn.
    assert per == [2 * 16 * (5 if k % 2 == 0 else 3) for k in range(len(per))]
    assert len(per) >= 3
    meta = read_checkpoint(out / "policy.zip")[0]
    assert meta.info["args"]["formation_sizes"] == "3,5"
    assert meta.env_config.n_uavs == 5 and meta.observation_layout.k_uavs == 4
    # A resumed run goes on with the size its updates have reached.
    again = tmp_path / "again"
    first = min((out / "checkpoints").glob("step_*"), key=lambda p: int(p.name[5:]))
    import shutil

    shutil.copytree(out, again, symlinks=True)
    ppo_shared.main([*SIZES, "--formation-sizes", "3,5", "--out-dir", str(again),
                     "--resume", str(again / "checkpoints" / first.name)])  # fmt: skip
    resumed = [int(r.split(",")[0]) for r in (again / "progress.csv").read_text().splitlines()[1:]]
    assert resumed == steps


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--trainer", "default", "--arch", "mlp", "--k-uavs", "2"], "--trainer lean only"),
        (["--formation-sizes", "3,4"], "the largest --n-uavs (5)"),
        (["--formation-sizes", "3,5,5"], "distinct"),
        (["--arch", "mlp"], "--arch set reads any number"),
        (["--norm-reward"], "--norm-reward"),
        (["--shield", "cbf"], "--shield"),
        (["--formation-sizes", "1,5"], "each 2-64"),
    ],
)
def test_bad_formation_sizes_are_refused_in_one_line(flags, named, capsys):
    argv = [*SIZES, "--formation-sizes", "3,5", *flags]
    with pytest.raises(SystemExit):
        ppo_shared.parse_args(argv)
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--formation-sizes" in err and named in err


@pytest.mark.parametrize("recipe", ["mappo", "ppo_lagrangian"])
def test_recipes_of_one_formation_size_refuse_several(recipe, capsys):
    from uasep_env.training import ppo_lagrangian

    parse = {"mappo": mappo.parse_args, "ppo_lagrangian": ppo_lagrangian.parse_args}[recipe]
    with pytest.raises(SystemExit):
        parse([*SIZES, "--formation-sizes", "3,5"])
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--formation-sizes" in err and "one formation size" in err
