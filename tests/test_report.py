"""Tests of ``uasep-report``'s views: the targets' verdicts and the episode cost columns."""

from __future__ import annotations

import json

import pytest
from conftest import ROOT

from uasep_env.metrics.statistics import wilson_interval
from uasep_env.reporting.scaling import evaluate_cell, parse_policies
from uasep_env.reporting.scaling_views import METRICS, markdown, targets


def _rate(k: int, n: int) -> dict[str, float]:
    low, high = wilson_interval(k, n)
    return {
        "kind": "rate",
        "n": n,
        "n_valid": n,
        "successes": k,
        "rate": k / n,
        "mean": k / n,
        "ci_low": low,
        "ci_high": high,
    }


def _result(collisions: dict[str, tuple[int, int]], n_uavs: int = 32) -> dict:
    """A scaling result with one cell: each policy's collisions ``(k, n)``."""
    rows = [
        {
            "n_uavs": n_uavs,
            "n_obstacles": 1,
            "policy": label,
            "zero_shot": False,
            "formation": "grid",
            "metrics": {"episode.collision": _rate(*kn)},
        }
        for label, kn in collisions.items()
    ]
    return {
        "seeds": {"first": 7_000_000, "count": 5, "bank": "SCALING_SEEDS"},
        "policies": [{"label": lab, "kind": "builtin"} for lab in collisions],
        "cells": [[n_uavs, 1]],
        "rows": rows,
        "held_out": [],
    }


@pytest.mark.parametrize(
    ("mine", "apf", "verdict"),
    [
        ((4, 5), (0, 5), "not shown (5 vs 5 episodes)"),  # 80 % [37.6, 96.4] vs [0, 43.4]
        ((0, 5), (0, 5), "not shown (5 vs 5 episodes)"),  # too few episodes to say "met"
        ((0, 100), (0, 100), "met (100 vs 100 episodes)"),
        ((2, 500), (4, 500), "met (500 vs 500 episodes)"),
        ((40, 50), (0, 50), "not met (50 vs 50 episodes)"),
    ],
)
def test_target_verdicts(mine, apf, verdict):
    (what, measured, got), *rest = targets(_result({"apf": apf, "mine": mine}))
    assert not rest and what.startswith("mine: collisions at 32 UAVs")
    assert got == verdict
    if mine == (4, 5):
        assert measured == "80.0% [37.6%, 96.4%] vs APF 0.0% [0.0%, 43.4%]"


def test_markdown_states_the_rule_and_the_episodes():
    text = markdown(_result({"apf": (0, 5), "mine": (4, 5)}), "uasep-report", 60.0)
    targets_part = text[text.index("## Targets") :]
    assert "| not shown (5 vs 5 episodes) |" in targets_part
    assert "| met" not in targets_part
    assert "10 percentage points" in targets_part and "| verdict" in targets_part


def test_episode_cost_is_a_column_and_older_results_render_without_it():
    """A result with the cost has its columns; one written before (no cost) renders as it was."""
    labels = [label for key, label, _ in METRICS if key in ("episode.cost", "episode.max_uav_cost")]
    assert labels == ["episode cost, team mean", "episode cost, worst UAV"]
    old = json.loads((ROOT / "baselines/results/scaling.json").read_text())
    for r in old["rows"]:  # as written before the cost channel
        for key in ("episode.cost", "episode.max_uav_cost"):
            r["metrics"].pop(key, None)
    text = markdown(old, old["command"], old["elapsed_s"])
    assert "episode cost" not in text and "max deviation" in text
    new = _result({"apf": (0, 5), "mine": (4, 5)})
    for r in new["rows"]:
        r["metrics"]["episode.cost"] = {"mean": 3.5, "ci_low": 2.5, "ci_high": 4.5, "n": 5}
    text = markdown(new, "uasep-report", 60.0)
    assert "episode cost, team mean" in text and "3.50 ± 1.00" in text


def test_a_cell_carries_the_episode_cost():
    """``uasep-report``'s rows hold the cost aggregates, the team mean and the worst UAV."""
    (row,) = evaluate_cell(
        parse_policies(["zero"]), 3, 1, [7_000_000, 7_000_001], episode_duration=20.0
    )
    for key in ("episode.cost", "episode.max_uav_cost"):
        stats = row["metrics"][key]
        assert stats["kind"] == "mean" and stats["n"] == 2 and stats["mean"] >= 0.0
    assert row["metrics"]["episode.max_uav_cost"]["mean"] >= row["metrics"]["episode.cost"]["mean"]


def test_a_policy_trained_at_several_sizes_says_so_and_its_cells_are_not_zero_shot():
    """The shipped set policy trained at 3-8 UAVs: its entry holds the sizes, its cells at
    3-8 UAVs are not zero-shot (16 is), and the table's line says "3-8 UAVs"."""
    from uasep_env.reporting.scaling import _zero_shot
    from uasep_env.reporting.scaling_views import sizes_text

    (entry,) = parse_policies(["ppo_residual_apf_set"])
    assert entry.sizes == (3, 4, 5, 6, 7, 8) and entry.trained == (8, 1)
    assert [_zero_shot(entry, n, 1) for n in (3, 8, 16)] == [False, False, True]
    assert _zero_shot(entry, 3, 2)  # another obstacle count
    (slot,) = parse_policies(["ppo_residual_apf"])  # one size: its own alone
    assert slot.sizes is None and [_zero_shot(slot, n, 1) for n in (3, 8)] == [False, True]
    result = _result({"apf": (0, 5)})
    result["policies"].append({"label": "set", "kind": "checkpoint", "trained": [8, 1],
                               "layout": [7, 1], "sizes": list(entry.sizes)})  # fmt: skip
    assert "`set`: trained with 3-8 UAVs and 1 obstacle(s)" in markdown(result, "r", 1.0)
    assert (sizes_text([8]), sizes_text([3, 5, 8]), sizes_text([4, 3])) == ("8", "3, 5, 8", "3, 4")
