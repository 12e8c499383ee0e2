"""Write the digest of the seeded encounter banks the published results were computed on.

Every results file compares controllers on fixed banks of seeded scenarios: the held-out
bank (``random``, seeds 5,000,000-5,000,499, and its 20 ``paper`` runs), the validation
encounters ``train/select_checkpoint.py`` chooses checkpoints on, the paper experiment's
and trade-off's runs (``paper`` seeds 0-19; ``random`` seeds 100,000-100,199 for the paper
experiment, 4,000,500-4,000,699 of the validation range for the trade-off sweep), the size
and obstacle-count cells of ``baselines/scaling.py`` (seeds 7,000,000-7,000,049) and the
real-traffic banks (``real_traffic`` on the test flights, seeds 6,000,000-6,000,299). The digest
records, per seed, the family drawn, a readable summary of the first obstacle (start
altitude, speed, climb rate) and a hash of every array of the scenario (rounded to 1e-6, so
that last-bit differences of a maths library do not count). ``tests/test_banks.py``
regenerates it and fails if any bank moved: then every results file is stale.

    python tools/digest_banks.py           # rewrite tests/data/banks.json
    python tools/digest_banks.py --check   # exit 1 if a bank moved

After a change that moves a bank (and bumps the env ids' version), regenerate the digest
AND every results file: ``baselines/paper_experiment.py``, ``baselines/learned_vs_apf.py``,
``baselines/tradeoff.py --fresh``, ``baselines/scaling.py`` (the command recorded in
``baselines/results/scaling.md``, with ``--force``), then ``tools/sync_readme.py``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from uasep_env.config import make_config
from uasep_env.registration import ENV_VERSION
from uasep_env.runtime.atomic import atomic_write
from uasep_env.scenarios import (
    HELD_OUT_PAPER_SEEDS,
    HELD_OUT_SEEDS,
    REAL_TRAFFIC_TEST_SEEDS,
    SCALING_SEEDS,
    VALIDATION_SEEDS,
    ScenarioSpec,
    sample_scenario,
)
from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK, REAL_TRAFFIC_SLOW_BANK

ROOT = Path(__file__).resolve().parents[1]
DIGEST = ROOT / "tests" / "data" / "banks.json"

#: Bank name -> (scenario, seeds, where it is used[, further config]).
BANKS: dict[str, tuple[Any, ...]] = {
    "held_out": ("random", HELD_OUT_SEEDS, "baselines/learned_vs_apf.py (held-out bank)"),
    "held_out_paper": ("paper", HELD_OUT_PAPER_SEEDS, "baselines/learned_vs_apf.py"),
    "validation": (
        "random",
        VALIDATION_SEEDS[:100],
        "train/select_checkpoint.py (--episodes 100, the shipped checkpoints' selection)",
    ),
    "paper_runs": ("paper", range(0, 20), "baselines/paper_experiment.py, baselines/tradeoff.py"),
    "random_bank": (
        "random",
        range(100_000, 100_200),
        "baselines/paper_experiment.py",
    ),
    "tradeoff_bank": (
        "random",
        VALIDATION_SEEDS[500:700],
        "baselines/tradeoff.py (the validation bank each controller's knee is read on)",
    ),
    "real_traffic_test": (
        "real_traffic",
        REAL_TRAFFIC_TEST_SEEDS,
        "baselines/real_traffic_eval.py (recorded tracks of the test flights)",
        {k: v for k, v in REAL_TRAFFIC_BANK.items() if k != "scenario"},
    ),
    "real_traffic_test_slow": (
        "real_traffic",
        REAL_TRAFFIC_TEST_SEEDS,
        "baselines/real_traffic_eval.py (the same tracks slowed x0.2)",
        {k: v for k, v in REAL_TRAFFIC_SLOW_BANK.items() if k != "scenario"},
    ),
}
# The size/obstacle-count cells of baselines/scaling.py (its SCALING_SEEDS, 50 per cell;
# formation "auto": the paper's pattern at 3 UAVs, a grid above).
for _n, _m in ((3, 1), (8, 1), (16, 1), (32, 1), (3, 2), (3, 4)):
    BANKS[f"scaling_{_n}x{_m}"] = (
        "random",
        SCALING_SEEDS[:50],
        "baselines/scaling.py (results/scaling.*)",
        {"n_uavs": _n, "n_obstacles": _m, "formation": "paper" if _n == 3 else "grid"},
    )


def spec_hash(spec: ScenarioSpec) -> str:
    """16 hex digits of a SHA-256 of every array of ``spec``, rounded to 1e-6."""
    h = hashlib.sha256(spec.family.encode())
    for name, value in vars(spec).items():
        if name == "family":
            continue
        arr = np.round(np.asarray(value, dtype=float), 6) + 0.0  # + 0.0: no negative zeros
        h.update(name.encode() + arr.tobytes())
    return h.hexdigest()[:16]


def entry(seed: int, spec: ScenarioSpec) -> list[Any]:
    """``[seed, family, hash, alt_m, speed_mps, climb_mps]`` of the first obstacle."""
    if len(spec.obstacle_pos) == 0:
        return [seed, spec.family, spec_hash(spec), None, None, None]
    return [
        seed,
        spec.family,
        spec_hash(spec),
        round(-float(spec.obstacle_pos[0, 2]), 1),
        round(float(spec.obstacle_speed[0]), 2),
        round(float(spec.obstacle_climb_rate[0]), 2),
    ]


def digest() -> dict[str, Any]:
    """The digest of every bank (only scenarios are sampled; no episode is flown)."""
    banks = {}
    for name, (scenario, seeds, used_by, *extra) in BANKS.items():
        cfg = make_config(scenario=scenario, **(extra[0] if extra else {}))
        banks[name] = {
            "scenario": scenario,
            **({"config": extra[0]} if extra else {}),
            "seeds": [seeds.start, seeds.stop],
            "used_by": used_by,
            "columns": ["seed", "family", "hash", "alt_m", "speed_mps", "climb_mps"],
            "entries": [entry(s, sample_scenario(np.random.default_rng(s), cfg)) for s in seeds],
        }
    return {"env_version": ENV_VERSION, "banks": banks}


def dumps(data: dict[str, Any]) -> str:
    """The digest as JSON, one entry a line (readable diffs)."""
    lines = ["{", f'  "env_version": {data["env_version"]},', '  "banks": {']
    names = list(data["banks"])
    for i, name in enumerate(names):
        bank = data["banks"][name]
        head = {k: v for k, v in bank.items() if k != "entries"}
        lines.append(f"    {json.dumps(name)}: {{")
        lines += [f"      {json.dumps(k)}: {json.dumps(v)}," for k, v in head.items()]
        lines.append('      "entries": [')
        rows = [f"        {json.dumps(e)}" for e in bank["entries"]]
        lines.append(",\n".join(rows))
        lines.append("      ]")
        lines.append("    }" + ("," if i < len(names) - 1 else ""))
    lines += ["  }", "}", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Rewrite the digest (or, with ``--check``, say whether a bank moved)."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--check", action="store_true", help="exit 1 if a bank moved")
    args = p.parse_args(argv)
    text = dumps(digest())
    if args.check:
        if not DIGEST.exists() or DIGEST.read_text() != text:
            print(f"a bank moved: {DIGEST} is stale (see this script's help)", file=sys.stderr)
            return 1
        return 0
    atomic_write(DIGEST, text)
    print(f"wrote {DIGEST}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
