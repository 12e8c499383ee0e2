"""Every script that judges a rate against the APF's says "met", "not met" or "not shown".

One rule (:func:`uasep_env.metrics.statistics.rate_verdict`) for ``train/seeds.py``,
``baselines/learned_vs_apf.py`` and ``baselines/shielded_vs_apf.py``: a handful of episodes
whose wide intervals overlap the APF's is "not shown", never "met". And each script's
re-render mode gives back its shipped results file from the stored figures alone.
"""

from __future__ import annotations

import shutil
import sys
from types import SimpleNamespace

import pytest
from conftest import ROOT

from uasep_env.metrics.statistics import wilson_interval

sys.path.insert(0, str(ROOT / "baselines"))
sys.path.insert(0, str(ROOT / "train"))

import learned_vs_apf
import seeds
import shielded_vs_apf

RESULTS = ROOT / "baselines" / "results"
RATES = ("episode.collision", "episode.loss_of_separation")


def _wilson(k: int, n: int) -> dict[str, float]:
    low, high = wilson_interval(k, n)
    return {"kind": "rate", "rate": k / n, "ci_low": low, "ci_high": high, "n": n, "n_valid": n}


def _aggregate(k: int, n: int = 5, deviation: float = 30.0) -> dict[str, dict[str, float]]:
    """Both rates at ``k`` of ``n`` episodes, and a mean max deviation."""
    dev = {"kind": "mean", "mean": deviation, "ci_low": deviation - 1, "ci_high": deviation + 1}
    return {**{key: _wilson(k, n) for key in RATES}, "episode.max_deviation": dev}


# 1 of 5 against 0 of 5: [0.5 %, 62 %] against [0 %, 43 %], overlapping: the overlap rule
# alone (no_worse_rate) called it met. And 0 of 5 each: equal, but 5 episodes cannot rule
# out a rate 43 points above the APF's.
WIDE = [(1, "not shown (5 vs 5 episodes)"), (0, "not shown (5 vs 5 episodes)")]


@pytest.mark.parametrize(("k", "verdict"), WIDE)
def test_seeds_never_says_met_on_five_episodes(k, verdict):
    per_seed = {"apf": _aggregate(0), "seed_0": _aggregate(0), "seed_1": _aggregate(k)}
    agg = {"episode.max_deviation": {"iqm": 20.0, "ci_low": 19.0, "ci_high": 21.0,
                                     "apf_iqm": 40.0}}  # fmt: skip
    got = {t.split(":")[0]: (m, v) for t, m, v in seeds.targets("residual_apf", per_seed, agg)}
    for key in ("collision", "loss_of_separation"):
        measured, said = got[key]
        assert said == verdict
        assert measured.startswith(f"worst seed_{1 if k else 0}:")  # the deciding seed
    assert got["mean max deviation at least 25 % below the APF's (IQM over seeds x families, "
               "the APF through the same statistic)"][1] == "met"  # fmt: skip


def test_seeds_every_seed_verdict_is_the_weakest():
    per_seed = {"apf": _aggregate(0, 500), "seed_0": _aggregate(0, 500),
                "seed_1": _aggregate(4, 500), "seed_2": _aggregate(60, 500)}  # fmt: skip
    agg = {"episode.max_deviation": {"iqm": 20.0, "ci_low": 19.0, "ci_high": 21.0,
                                     "apf_iqm": 40.0}}  # fmt: skip
    (_, measured, verdict), *_ = seeds.targets("residual_apf", per_seed, agg)
    assert verdict == "not met (500 vs 500 episodes)" and measured.startswith("worst seed_2:")
    del per_seed["seed_2"]
    (_, measured, verdict), *_ = seeds.targets("residual_apf", per_seed, agg)
    assert verdict == "not shown (500 vs 500 episodes)" and measured.startswith("worst seed_1:")


@pytest.mark.parametrize(("k", "verdict"), WIDE)
def test_learned_vs_apf_never_says_met_on_five_episodes(k, verdict):
    rows = learned_vs_apf._as_safe_and_closer("residual", _aggregate(k), _aggregate(0), 0.25)
    assert [v for _, _, v in rows[:2]] == [verdict, verdict]
    stored = {"apf": _aggregate(0), "ppo_residual_apf": _aggregate(k)}
    bank = SimpleNamespace(results={n: SimpleNamespace(aggregate=a) for n, a in stored.items()})
    got = {t: v for t, _, v in learned_vs_apf.targets(bank, {})}
    assert got["residual: collision rate no worse than the APF's"] == verdict


@pytest.mark.parametrize(("k", "verdict"), WIDE)
def test_shielded_vs_apf_never_says_met_on_five_episodes(k, verdict):
    text = shielded_vs_apf.render(
        {"cbf-qp": _aggregate(k)}, {"apf": _aggregate(0)}, "here", [0, 1, 2, 3, 4], "Made."
    )
    targets = text[text.index("### Targets") :]
    assert f"| {verdict} |" in targets and "| met" not in targets
    assert "| verdict" in targets and "10 percentage points" in targets


def test_seeds_from_json_gives_back_each_shipped_report(tmp_path):
    """``--from-json`` plays nothing; on a shipped report it changes nothing."""
    reports = [p for p in sorted(RESULTS.glob("seeds_*.json")) if "_scaling" not in p.name]
    assert reports
    for path in reports:
        copy = tmp_path / path.name
        shutil.copy(path, copy)
        seeds.main(["--from-json", str(copy)])
        assert copy.read_text() == path.read_text(), path.name
        assert copy.with_suffix(".md").read_text() == path.with_suffix(".md").read_text()
    with pytest.raises(SystemExit, match=r"not a train/seeds\.py report"):
        (tmp_path / "x.json").write_text("[]")
        seeds.main(["--from-json", str(tmp_path / "x.json")])


def test_seeds_needs_recipe_and_out_dir_unless_from_json(capsys):
    with pytest.raises(SystemExit):
        seeds.main(["--out-dir", "/tmp/nowhere"])
    assert "--recipe" in capsys.readouterr().err


def test_learned_and_shielded_render_give_back_the_shipped_files(tmp_path):
    for name in ("learned_vs_apf", "shielded_vs_apf"):
        shutil.copy(RESULTS / f"{name}.json.gz", tmp_path)
        shutil.copy(RESULTS / f"{name}.md", tmp_path)  # the provenance of an old file
    assert (
        learned_vs_apf.main(["--render", "--out", str(tmp_path)])
        == (RESULTS / "learned_vs_apf.md").read_text()
    )
    assert (
        shielded_vs_apf.main(["--render", "--out", str(tmp_path)])
        == (RESULTS / "shielded_vs_apf.md").read_text()
    )
    for name in ("learned_vs_apf", "shielded_vs_apf"):  # render rewrites the .md only
        shipped = (RESULTS / f"{name}.json.gz").read_bytes()
        assert (tmp_path / f"{name}.json.gz").read_bytes() == shipped


def test_a_fixed_limit_is_met_only_when_the_whole_interval_is_within_it():
    from uasep_env.metrics.statistics import MET, NOT_MET, NOT_SHOWN, limit_verdict

    # The pure policy's 4.0 % [2.6 %, 6.1 %] against "at most 5 %": the point is below, the
    # interval straddles the limit.
    assert limit_verdict({"rate": 0.04, "ci_low": 0.026, "ci_high": 0.061}, 0.05) == NOT_SHOWN
    assert limit_verdict({"rate": 0.006, "ci_low": 0.002, "ci_high": 0.017}, 0.05) == MET
    assert limit_verdict({"rate": 0.09, "ci_low": 0.06, "ci_high": 0.12}, 0.05) == NOT_MET
    dev = {"iqm": 31.0, "ci_low": 30.9, "ci_high": 31.2}
    assert limit_verdict(dev, 0.75 * 35.0, key="iqm") == NOT_MET
    assert limit_verdict(dev, 40.0, key="iqm") == MET
    assert limit_verdict(dev, 31.1, key="iqm") == NOT_SHOWN
    assert limit_verdict(dev, 31.1, key="iqm", at_most=False) == NOT_SHOWN
    assert limit_verdict(dev, 20.0, key="iqm", at_most=False) == MET
    with pytest.raises(ValueError, match="limit_verdict"):
        limit_verdict({"rate": 0.1}, 0.05)
