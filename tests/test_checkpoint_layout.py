"""Checkpoint format v2: the observation layout is recorded, and loading checks it."""

import itertools
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import CheckpointError, checkpoint_config, load_policy
from uasep_env.policies.learned import CHECKPOINT_FORMAT, PolicyCheckpoint, save_policy

CHECKPOINTS = Path(__file__).resolve().parents[1] / "baselines" / "checkpoints"


def _checkpoint(path, cfg, seed=0):
    rng = np.random.default_rng(seed)
    dim = ObservationLayout.from_config(cfg).dim
    sizes = [dim, 16, 3]
    weights = [
        (rng.normal(0, 0.3, (o, i)).astype(np.float32), rng.normal(0, 0.1, o).astype(np.float32))
        for i, o in itertools.pairwise(sizes)
    ]
    meta = PolicyCheckpoint(
        config=cfg.to_dict(), obs_dim=dim, activation="tanh", hidden=(16,), obs_norm=False
    )
    return save_policy(path, meta, weights)


def _fly(policy, cfg, steps=40):
    env = EnvCore(cfg, 1)
    obs = env.reset(seed=11)
    for _ in range(steps):
        obs = env.step(policy(obs)).obs
    return env.world.uav_pos


def test_a_fixed_k_checkpoint_trained_on_3_uavs_flies_8(tmp_path):
    cfg3 = make_config(scenario="random", observation={"k_uavs": 2, "k_obstacles": 1})
    path = _checkpoint(tmp_path / "k.zip", cfg3)
    with zipfile.ZipFile(path) as z:
        desc = json.loads(z.read("uasep_policy.json"))
    assert desc["format"] == CHECKPOINT_FORMAT == "uasep-policy/2"
    assert desc["layout"]["k_uavs"] == 2 and desc["layout"]["k_obstacles"] == 1
    assert desc["layout"]["features"][0] == ["slot_offset", 3]
    assert sum(w for _, w in desc["layout"]["features"]) == desc["obs_dim"]
    cfg8 = checkpoint_config(path, n_uavs=8, n_obstacles=2)
    assert (cfg8.n_uavs, cfg8.n_obstacles, cfg8.observation.k_uavs) == (8, 2, 2)
    policy = load_policy(path, cfg8)
    pos = _fly(policy, cfg8)
    assert pos.shape == (1, 8, 3) and np.isfinite(pos).all()
    # Without K fixed, the 8-UAV env observes 6 neighbours: refused, with the fix named.
    with pytest.raises(
        CheckpointError,
        match=r"k_uavs: .* reads the 2 nearest UAVs, this "
        r"env gives 6 \(set observation.k_uavs=2",
    ):
        load_policy(path, make_config(scenario="random", n_uavs=8))
    with pytest.raises(CheckpointError, match="k_uavs"):
        checkpoint_config(path, n_uavs=2)  # too few UAVs for 2 neighbours


@pytest.mark.parametrize("name", ["ppo_shared", "ppo_residual_apf"])
def test_shipped_v1_checkpoints_fly_8_uavs_zero_shot(name):
    path = CHECKPOINTS / f"{name}.zip"
    cfg = checkpoint_config(path, n_uavs=8, scenario="random")
    assert (cfg.observation.k_uavs, cfg.observation.k_obstacles) == (2, 1)
    assert np.isfinite(_fly(load_policy(path, cfg), cfg, steps=20)).all()


def test_a_reordered_layout_of_the_same_width_is_refused_naming_the_feature(tmp_path):
    cfg = make_config(scenario="random")
    path = _checkpoint(tmp_path / "p.zip", cfg)
    with zipfile.ZipFile(path) as z:
        desc = json.loads(z.read("uasep_policy.json"))
        raw = z.read("weights.npz")
    feats = desc["layout"]["features"]
    assert feats[2] == ["velocity", 3] and feats[3] == ["plan_velocity", 3]
    feats[2], feats[3] = feats[3], feats[2]
    with zipfile.ZipFile(tmp_path / "r.zip", "w") as z:
        z.writestr("uasep_policy.json", json.dumps(desc))
        z.writestr("weights.npz", raw)
    with pytest.raises(
        CheckpointError,
        match=r"observation feature 2 \(column 6\): the network reads 'plan_velocity' \(3 wide\), "
        r"this env gives 'velocity'",
    ):
        load_policy(tmp_path / "r.zip", cfg)
