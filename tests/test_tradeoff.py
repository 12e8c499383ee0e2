"""Tests of baselines/tradeoff.py: Pareto fronts, the knee rule, and a resumable small sweep."""

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest

BASELINES = Path(__file__).resolve().parents[1] / "baselines"
sys.path.insert(0, str(BASELINES))

import tradeoff  # noqa: E402

import uasep_env.benchmark.tradeoff as tradeoff_impl  # noqa: E402  (the sweep's code)


def test_pareto_keeps_only_undominated_settings():
    dist = np.array([10.0, 12.0, 11.0, 20.0, 20.0])
    dev = np.array([5.0, 6.0, 7.0, 9.0, 10.0])
    # 11 m at 7 m is beaten by 12 m at 6 m; 20 m at 10 m by 20 m at 9 m.
    np.testing.assert_array_equal(
        tradeoff.pareto(dist, dev, True), [True, True, False, True, False]
    )
    # For a rate, lower is safer.
    rate = np.array([0.1, 0.0, 0.0])
    np.testing.assert_array_equal(
        tradeoff.pareto(rate, np.array([1.0, 2.0, 3.0]), False), [True, True, False]
    )


def _row(value, dist, dev, coll=0.0, lo=0.0, hi=0.02):
    return {"value": value, "min_obstacle_distance": dist, "max_deviation": dev,
            "collision": coll, "collision_lo": lo, "collision_hi": hi}  # fmt: skip


def test_knee_is_where_distance_starts_to_cost_more():
    # Deviation grows slowly up to 20 m, then steeply: the knee is the 20 m setting.
    rows = [_row(v, d, c) for v, d, c in
            [(0.5, 10, 5), (1.0, 15, 6), (1.5, 20, 7), (2.0, 25, 15), (3.0, 30, 30)]]  # fmt: skip
    assert tradeoff.knee(rows)["value"] == 1.5
    # A setting that collides more often than the safest one is never the knee.
    rows[2] = _row(1.5, 20, 7, coll=0.3, lo=0.2, hi=0.4)
    assert tradeoff.knee(rows)["value"] != 1.5


def test_margin_scale_one_is_the_default_gains():
    from uasep_env.policies import APFGains

    assert tradeoff._scaled(tradeoff.APF.margin_gains, 1.0) == APFGains()
    scaled = tradeoff._scaled(tradeoff.APF.margin_gains, 2.0)
    assert scaled.obstacle_safe_min == 2 * APFGains().obstacle_safe_min
    assert scaled.k_obstacle == APFGains().k_obstacle
    for m in tradeoff.METHODS:  # the horizons: the calibrated prediction's six
        assert len(m.values) >= (6 if m.knob.startswith("prediction horizon") else 8), m.name


def test_small_sweep_writes_csv_and_figures_and_resumes(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    args = ["--methods", "apf,apf-published,traditional-apf", "--paper-episodes", "1",
            "--bank-episodes", "1", "--workers", "1", "--out", str(tmp_path)]  # fmt: skip
    tradeoff.main(args)
    with (tmp_path / "tradeoff.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3 * 9 * 2
    assert {r["dataset"] for r in rows} == {"paper", "bank"}
    for name in ("tradeoff_paper.png", "tradeoff_bank.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    # The default setting on paper seed 0 is the paper experiment's APF episode.
    default = format(tradeoff.METHODS[0].default, "g")
    apf = next(r for r in rows if r["method"] == "apf" and r["value"] == default and
               r["dataset"] == "paper")  # fmt: skip
    paper = json.loads((BASELINES / "results" / "paper.json").read_text())
    ep0 = paper["results"]["apf"]["episodes"][0]["metrics"]["episode"]
    assert float(apf["min_obstacle_distance"]) == pytest.approx(ep0["min_obstacle_distance"],
                                                                rel=1e-5)  # fmt: skip
    # The published prediction changes the APF's flight; the traditional APF ignores it.
    pub = next(r for r in rows if r["method"] == "apf-published" and r["value"] == default and
               r["dataset"] == "paper")  # fmt: skip
    assert pub["max_deviation"] != apf["max_deviation"]

    # Resumed: nothing is evaluated again, the CSV is unchanged.
    def no_eval(*_a, **_k):
        raise AssertionError("a finished setting was evaluated again")

    before = (tmp_path / "tradeoff.csv").read_text()
    monkeypatch.setattr(tradeoff_impl, "evaluate", no_eval)  # where the sweep runs
    tradeoff.main(args)
    assert (tmp_path / "tradeoff.csv").read_text() == before
    with pytest.raises(SystemExit):
        tradeoff.main(["--methods", "apf,fastest", "--out", str(tmp_path)])


@pytest.mark.parametrize("flag", ["--workers", "--paper-episodes", "--bank-episodes"])
@pytest.mark.parametrize("bad", ["0", "-3", "two"])
def test_bad_counts_are_named(flag, bad, capsys):
    with pytest.raises(SystemExit):
        tradeoff.main([flag, bad])
    err = capsys.readouterr().err
    assert f"argument {flag}: invalid positive_int value: '{bad}'" in err


#: The methods tradeoff.py names by hand: every one has its full sweep in the shipped CSV.
HAND_WRITTEN = ("apf", "apf-published", "motion-state-apf", "traditional-apf", "ppo-residual",
                "ppo-shared", "mappo")  # fmt: skip


def test_registered_controllers_are_swept():
    """Every registered reference controller has a method (its margin_scale), none twice."""
    from uasep_env.policies import reference_controllers

    names = [m.name for m in tradeoff.METHODS]
    assert len(names) == len(set(names)) and set(reference_controllers()) <= set(names)
    assert [m.name for m in tradeoff.METHODS[: len(HAND_WRITTEN)]] == list(HAND_WRITTEN)
    mvp = {m.name: m for m in tradeoff.METHODS}["mvp"]
    assert mvp.policy(tradeoff.make_config(), 1.5).params.margin_scale == 1.5


def _collision_course_observations():
    """Observations of head-on and crossing encounters, every 4 s until the conflict is over."""
    from uasep_env import make_config
    from uasep_env.envs.core import EnvCore
    from uasep_env.policies import APF, APFGains

    out = []
    for scenario in ("collision_head_on", "collision_crossing"):
        cfg = make_config(scenario=scenario)
        core = EnvCore(cfg, n_envs=3)
        obs = core.reset(seed=11)
        plan_only = APF(cfg, APFGains(k_obstacle=0.0))  # flies into the obstacle
        for step in range(800):
            if step % 20 == 0:
                out.append(obs)
            obs = core.step(plan_only(obs)).obs
    return cfg, np.concatenate(out)


def test_every_registered_controllers_default_is_the_knee_of_its_front():
    """Each reference controller's default is the knee of its own front on the -v3 bank.

    The front is the shipped sweep (``docs/figures/tradeoff.csv``, 200 encounters of the
    validation range, never the held-out bank); a controller registered later fails here
    until its sweep is run (``python baselines/tradeoff.py --methods NAME``) and its default
    set to its knee. The default policy must be the sweep's at that scale: its actions on
    collision-course observations are the same.
    """
    from uasep_env.policies import REGISTRY

    rows = tradeoff._read(tradeoff.FIGURES / "tradeoff.csv")
    cfg, obs = _collision_course_observations()
    checked = []
    for entry in REGISTRY.values():
        if not entry.reference or entry.margin is None:
            continue
        bank = [r for r in rows if r["method"] == entry.name and r["dataset"] == "bank"]
        assert len(bank) == len(tradeoff.SCALES), f"{entry.name}: no full sweep in the CSV"
        assert {r["n"] for r in bank} == {200.0}, entry.name
        # The knee, or a tie with it (chord distances within 2 %: a nearly straight front).
        dist = {r["value"]: d for r, d in tradeoff.knee_distances(bank)}
        assert dist.get(entry.default_margin, -1.0) >= 0.98 * max(dist.values()), (
            entry.name,
            entry.default_margin,
            tradeoff.knee(bank)["value"],
        )
        default = entry.factory(cfg)(obs)
        np.testing.assert_array_equal(default, entry.margin(cfg, entry.default_margin)(obs))
        checked.append(entry.name)
    assert {"apf", "motion-state-apf", "traditional-apf", "cbf-qp", "mvp", "orca"} <= set(
        checked
    )


def test_the_paper_prediction_apf_shares_the_apf_default():
    by_name = {m.name: m for m in tradeoff.METHODS}
    assert by_name["apf-published"].default == by_name["apf"].default


def test_the_shields_margin_is_cbf_qps_knee():
    """The shield is CBF-QP's filter over another policy: its default margin is that knee."""
    from uasep_env import make_config
    from uasep_env.policies import REGISTRY, Shielded, make_policy

    shield = Shielded(make_policy("apf", make_config()), make_config())
    assert shield.params.margin_scale == REGISTRY["cbf-qp"].default_margin
    assert make_policy("orca+cbf", make_config()).params.margin_scale == shield.params.margin_scale
