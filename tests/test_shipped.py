"""The shipped checkpoints and the APFs still fly their published figures (issue 19).

Each ``baselines/checkpoints/*.zip`` and each APF flies a few held-out encounters, and every
per-episode figure is compared with the record published in
``baselines/results/learned_vs_apf.json.gz``. A change to the observation, the actions, the
dynamics, the APF or the scenarios that moves what a policy does fails here, instead of
leaving the published tables silently stale. The figures are reproduced bit for bit on the
machine that made them; the tolerance leaves room only for a maths library's last bits.

The file is of ``-v3``, the env the shipped checkpoints were trained in: the encounters are
flown with the current defaults and the APFs at their registered (knee) margins. ``-v2``'s
episodes are pinned by ``tests/test_pinned_numbers.py``; its checkpoints, kept in
``baselines/seeds/``, by ``tests/test_env_versions.py``.
"""

from __future__ import annotations

import gzip
import json
import math
from typing import Any

import pytest
from conftest import ROOT

from uasep_env.config import make_config
from uasep_env.evaluation import evaluate

RESULTS = ROOT / "baselines" / "results" / "learned_vs_apf.json.gz"
CHECKPOINTS = sorted((ROOT / "baselines" / "checkpoints").glob("*.zip"))
#: Held-out encounters: an overtaking, a climber started at the ground margin (moved by the
#: -v2 ground fix) and a multi-obstacle one.
SEEDS = [5_000_000, 5_000_008, 5_000_011]
RTOL = 1e-6
#: The controllers flown beside the checkpoints, at their registered defaults.
CONTROLLERS = ("apf", "motion-state-apf", "traditional-apf")
STALE = (
    "moved from the figures published in baselines/results/learned_vs_apf.json.gz. If the change "
    "is meant, bump the env ids' version and regenerate every results file "
    "(python baselines/learned_vs_apf.py --workers 2, baselines/paper_experiment.py, "
    "baselines/tradeoff.py --fresh, baselines/scaling.py, tools/digest_banks.py, "
    "tools/sync_readme.py), and say in "
    "CHANGELOG.md how the shipped policies' figures moved."
)


def _leaves(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_leaves(v, f"{prefix}{k}."))
        elif v is None or isinstance(v, (bool, int, float, str)):
            out[prefix + k] = v
    return out


def _figures(episode: dict[str, Any]) -> dict[str, Any]:
    keep = {k: episode[k] for k in ("seed", "family", "steps", "terminated", "episode_return")}
    return keep | _leaves(episode["metrics"]["episode"], "episode.")


def _differences(now: dict[str, Any], published: dict[str, Any]) -> list[str]:
    """Every published figure that moved or is gone; a figure newer than the file (a metric
    added since, e.g. the episode cost) has nothing to compare with."""
    bad = []
    for key in sorted(published):
        a, b = now.get(key), published.get(key)
        if isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
            same = (math.isnan(a) and math.isnan(b)) or math.isclose(
                a, b, rel_tol=RTOL, abs_tol=1e-9
            )
        else:
            same = a == b
        if not same:
            bad.append(f"{key}: {a!r} (published {b!r})")
    return bad


@pytest.fixture(scope="module")
def published() -> dict[str, Any]:
    with gzip.open(RESULTS, "rt") as fh:
        return json.load(fh)["random"]["results"]


@pytest.fixture(scope="module")
def flown() -> dict[str, Any]:
    cfg = make_config(scenario="random")
    policies: dict[str, Any] = {name: name for name in CONTROLLERS}
    policies |= {p.stem: str(p) for p in CHECKPOINTS}
    result = evaluate(policies, cfg, SEEDS, batch_size=len(SEEDS))
    return json.loads(result.to_json())["results"]


def test_the_shipped_checkpoints():
    shipped = {"ppo_shared", "ppo_residual_apf", "ppo_residual_apf_set", "mappo", "ppo_lagrangian",
               "ppo_lagrangian_deviation"}  # fmt: skip
    assert {p.stem for p in CHECKPOINTS} == shipped


@pytest.mark.parametrize(
    "policy",
    [*CONTROLLERS, *(p.stem for p in CHECKPOINTS)],
)
def test_policies_fly_their_published_figures(policy, flown, published):
    stored = {e["seed"]: e for e in published[policy]["episodes"]}
    for episode in flown[policy]["episodes"]:
        bad = _differences(_figures(episode), _figures(stored[episode["seed"]]))
        assert not bad, f"{policy}, seed {episode['seed']}: {bad[:4]} {STALE}"


def test_a_moved_figure_is_caught():
    """The comparison is strict: a relative change of 1e-5 in one figure fails it."""
    a = {"episode.max_deviation": 10.0, "episode.collision": False, "family": "crossing"}
    assert not _differences(a, dict(a))
    assert _differences(a | {"episode.max_deviation": 10.0001}, a)
    assert _differences(a | {"episode.collision": True}, a)
    assert _differences(a | {"family": "climbing"}, a)
    assert _differences({k: v for k, v in a.items() if k != "family"}, a)  # a figure gone
    assert not _differences(a | {"episode.cost": 3.0}, a)  # a metric newer than the file
