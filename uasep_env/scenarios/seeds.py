"""Seed ranges of learned baselines: training, validation and the held-out bank never meet."""

from __future__ import annotations

__all__ = [
    "HELD_OUT_PAPER_SEEDS",
    "HELD_OUT_SEEDS",
    "REAL_TRAFFIC_TEST_SEEDS",
    "SCALING_SEEDS",
    "SEED_RANGES",
    "TRAINING_SEEDS",
    "VALIDATION_SEEDS",
    "check_training_seeds",
]

#: Seeds training environments may be created with (environment ``e`` of a batch seeded
#: ``seed`` starts from ``seed + e`` and then continues its own generator).
TRAINING_SEEDS = range(0, 1_000_000)
#: Seeds of the encounters a training run checks itself on (``random`` scenario).
VALIDATION_SEEDS = range(4_000_000, 4_001_000)
#: The held-out bank: 500 ``random`` encounters, the seeds every controller is compared on
#: and training never draws.
HELD_OUT_SEEDS = range(5_000_000, 5_000_500)
#: The held-out bank's ``paper`` scenario runs (noise and the pilot's late manoeuvres).
HELD_OUT_PAPER_SEEDS = range(5_000_000, 5_000_020)
#: The real-traffic bank: 300 ``real_traffic`` encounters with tracks of the TEST flights
#: only (``obstacle.replay_split="test"``; config:
#: :data:`uasep_env.scenarios.real_traffic.REAL_TRAFFIC_BANK`).
REAL_TRAFFIC_TEST_SEEDS = range(6_000_000, 6_000_300)
#: The size / obstacle-count bank of ``baselines/scaling.py``: ``random`` encounters with
#: 3-32 UAVs and 1-4 obstacles (its own range, so no seed means two banks).
SCALING_SEEDS = range(7_000_000, 7_001_000)
#: Every named range, for the test that they never meet.
SEED_RANGES = {
    "training": TRAINING_SEEDS,
    "validation": VALIDATION_SEEDS,
    "held_out": HELD_OUT_SEEDS,
    "real_traffic_test": REAL_TRAFFIC_TEST_SEEDS,
    "scaling": SCALING_SEEDS,
}


def check_training_seeds(seed: int, n_envs: int) -> None:
    """Raise ``ValueError`` unless ``[seed, seed + n_envs)`` lies in :data:`TRAINING_SEEDS`."""
    if not (
        isinstance(seed, int)
        and seed >= TRAINING_SEEDS.start
        and seed + n_envs <= TRAINING_SEEDS.stop
    ):
        raise ValueError(
            f"seed={seed!r}: training seeds [seed, seed + n_envs) must lie in "
            f"[{TRAINING_SEEDS.start}, {TRAINING_SEEDS.stop}), disjoint from the held-out bank"
        )
