"""Observations, rewards and feature names pinned to values recorded before a refactor.

The digests were recorded on ``main`` at 4bef8b7, before the observation layout became data
and the reward terms a table (issue 19); ``residual``'s moved with the ``-v2`` ground fix.
A refactor of the observation or reward code must leave them unchanged, with and without
numba. A change that is meant to move the numbers (new dynamics, a new default feature)
adds the new version's numbers here, with a CHANGELOG entry and the env version bump, and
keeps the earlier versions' (their defaults as overrides, ``VERSION_DEFAULTS``): ``-v2``'s
are the numbers recorded before ``-v3`` made the calibrated prediction the default. The APF
that drives the rollouts has the reference gains (``APFGains()``), so that a controller's
default moving does not move the env's numbers.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from uasep_env import _numba, make_config
from uasep_env.config import VERSION_DEFAULTS
from uasep_env.envs.core import EnvCore
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import APF, APFGains

CONFIGS = {
    "paper": {"scenario": "paper"},
    "random": {"n_uavs": 4, "n_obstacles": 3, "scenario": "random", "reward": {"shared": 0.3}},
    "short_range": {
        "n_uavs": 5,
        "n_obstacles": 2,
        "scenario": "random",
        "observation": {"k_uavs": 2, "k_obstacles": 4, "sensing_range": 60.0},
    },
    "no_obstacles": {"n_uavs": 4, "n_obstacles": 0},
    "residual": {
        "n_uavs": 3,
        "n_obstacles": 2,
        "scenario": "random",
        "action": {"mode": "residual_apf"},
    },
}
#: The reward terms when the digests were recorded (a new term, weighted 0 by default, adds
#: an entry to ``terms`` without moving these).
RECORDED_TERMS = (
    "collision",
    "control",
    "deviation",
    "progress",
    "separation_inner",
    "separation_obstacle",
    "separation_region",
    "smoothness",
)
#: name: (digest of 40 steps of observations, rewards and terms; last obs[0, 0, 0];
#: last reward[0, 0]; observation width; digest of the feature names), in ``-v2``.
PINNED_V2 = {
    "paper": ("11d015cec0fb0280", 0.00385141558945179, 0.9350802311468418, 58, "4ad1804379e3ca79"),
    "random": (
        "c54a2cb3f9d14577",
        -0.014026936143636703,
        0.9757481990098025,
        98,
        "f77f57f8b8f6a080",
    ),
    "short_range": (
        "1cd0c42bfd6c554d",
        -0.013831560499966145,
        0.9787620078065938,
        106,
        "61c1e65f43d2b817",
    ),
    "no_obstacles": (
        "950a21c53068ff3e",
        0.0049272882752120495,
        0.9357570556866531,
        66,
        "b7d89c0929ca9f01",
    ),
    "residual": (
        # -v2 (issue 19's ground fix: a climber of seed 7's batch starts higher): was
        # 8127524d7ee71f23, which the ground moved to -1000 m still reproduces.
        "9acf41e463f089b7",
        -0.02903461456298828,
        0.9683772334816598,
        77,
        "ead82f5a5479d5ee",
    ),
}


#: The same in ``-v3`` (recorded when the calibrated prediction became the default): the
#: rollouts whose obstacles are observed moved; ``short_range``'s obstacles stay beyond its
#: 60 m sensing range in these 40 steps and ``no_obstacles`` has none, so theirs did not.
PINNED_V3 = {
    **PINNED_V2,
    "paper": ("0b897ea8b0b3d260", 0.00385141558945179, 0.9350802311468418, 58, "4ad1804379e3ca79"),
    "random": (
        "044efb79ebcb3b3f",
        -0.014026936143636703,
        0.9757481990098025,
        98,
        "f77f57f8b8f6a080",
    ),
    "residual": (
        "215526e5c7d40fd5",
        -0.02903461456298828,
        0.9683772334816598,
        77,
        "ead82f5a5479d5ee",
    ),
}
#: env version -> its pinned numbers.
PINNED = {2: PINNED_V2, 3: PINNED_V3}


def _config(name: str, version: int):
    return make_config(VERSION_DEFAULTS[version], **CONFIGS[name])


def _rollout(name: str, version: int) -> tuple[str, float, float, int]:
    cfg = _config(name, version)
    core = EnvCore(cfg, n_envs=5)
    obs = core.reset(seed=7)
    apf = APF(cfg, APFGains())
    h = hashlib.sha256(obs.tobytes())
    rng = np.random.default_rng(1)
    for _ in range(40):
        if cfg.action.mode == "direct":
            act = apf(obs)
        else:
            act = rng.uniform(-1, 1, size=(*obs.shape[:2], 3))
        res = core.step(act)
        obs = res.obs
        h.update(res.obs.tobytes())
        h.update(res.rewards.tobytes())
        for k in RECORDED_TERMS:
            h.update(res.terms[k].tobytes())
    return h.hexdigest()[:16], float(obs[0, 0, 0]), float(res.rewards[0, 0]), obs.shape[-1]


@pytest.mark.parametrize("version", sorted(PINNED), ids=lambda v: f"v{v}")
@pytest.mark.parametrize("numba", [True, False], ids=["numba", "numpy"])
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_observations_and_rewards_match_the_recorded_numbers(monkeypatch, name, numba, version):
    if numba and not _numba.available():
        pytest.skip("numba not installed or UASEP_NUMBA=0")
    if not numba:
        monkeypatch.setitem(_numba._state, "numba", None)
    digest, first_obs, first_reward, width = _rollout(name, version)
    want = PINNED[version][name]
    assert (first_obs, first_reward, width) == want[1:4]
    assert digest == want[0]


@pytest.mark.parametrize("version", sorted(PINNED), ids=lambda v: f"v{v}")
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_feature_names_match_the_recorded_layout(name, version):
    names = ObservationLayout.from_config(_config(name, version)).feature_names()
    assert len(names) == PINNED[version][name][3]
    assert hashlib.sha256("\n".join(names).encode()).hexdigest()[:16] == PINNED[version][name][4]


def test_the_versions_differ_where_they_should():
    """-v3 moved the rollouts whose obstacles are observed (their predicted region), only."""
    moved = {name for name in CONFIGS if PINNED_V2[name][0] != PINNED_V3[name][0]}
    assert moved == {"paper", "random", "residual"}
