"""The seeded banks every published result was computed on are pinned (issue 19).

A change to the scenarios (a new family in the ``random`` mix, a different draw) alters the
encounters of the held-out bank, the validation seeds and the paper experiment's runs, and
with them every results file. ``tests/data/banks.json`` is their digest
(``tools/digest_banks.py``); this test samples every bank again (no episode is flown) and
fails, naming the seeds that moved, until the digest and every results file are
regenerated together.
"""

from __future__ import annotations

import json
import runpy

from conftest import ROOT

TOOL = runpy.run_path(str(ROOT / "tools" / "digest_banks.py"))
REGENERATE = (
    "The seeded banks moved, so every published result is stale. If the change is meant: bump "
    "the env ids' version (uasep_env/registration.py ENV_VERSION, CHANGELOG), then run "
    "`python tools/digest_banks.py` and regenerate EVERY results file with it: "
    "`python baselines/paper_experiment.py --workers 2`, "
    "`python baselines/learned_vs_apf.py --workers 2`, "
    "`python baselines/tradeoff.py --workers 2 --fresh`, `python baselines/scaling.py` (the "
    "command in baselines/results/scaling.md, with --force), then `python tools/sync_readme.py`."
)


def test_the_banks_match_their_digest():
    stored = json.loads(TOOL["DIGEST"].read_text())
    fresh = json.loads(TOOL["dumps"](TOOL["digest"]()))
    assert stored["env_version"] == fresh["env_version"], REGENERATE
    assert set(stored["banks"]) == set(fresh["banks"]), REGENERATE
    moved = []
    for name, bank in fresh["banks"].items():
        old = {e[0]: e for e in stored["banks"][name]["entries"]}
        assert bank["seeds"] == stored["banks"][name]["seeds"], (name, REGENERATE)
        moved += [(name, old.get(e[0]), e) for e in bank["entries"] if old.get(e[0]) != e]
    assert not moved, (
        f"{len(moved)} encounters moved, e.g. (bank, stored, now): {moved[:3]}. {REGENERATE}"
    )


def test_the_digest_names_what_moved():
    """A moved draw is caught: perturb one family's generator and the digest differs."""
    from uasep_env.scenarios import FAMILIES

    fam = FAMILIES["head_on"]
    original = fam.generate

    def shifted(rng, config):
        spec = original(rng, config)
        spec.obstacle_pos[0, 0] += 1e-3  # a millimetre, far below the summary's rounding
        return spec

    object.__setattr__(fam, "generate", shifted)
    try:
        fresh = TOOL["digest"]()["banks"]["held_out"]["entries"]
    finally:
        object.__setattr__(fam, "generate", original)
    stored = json.loads(TOOL["DIGEST"].read_text())["banks"]["held_out"]["entries"]
    diff = [(a, b) for a, b in zip(stored, fresh, strict=True) if a != b]
    assert diff and all(a[1] == "head_on" and a[2] != b[2] and a[3:] == b[3:] for a, b in diff)
