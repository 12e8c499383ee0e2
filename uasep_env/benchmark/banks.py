"""The leaderboard's banks: which encounters, with which config, on which seeds.

Each bank is a row of :data:`BANKS` (a new bank is a new row). Seeds come from the named
ranges of :mod:`uasep_env.scenarios.seeds`, so no bank meets the seeds training draws:

* ``held_out``: the 500 ``random`` encounters of :data:`~uasep_env.scenarios.HELD_OUT_SEEDS`;
* ``collision_head_on``, ``collision_crossing``: the collision courses on the first 100
  seeds of the same held-out range (the held-out convention: every comparison plays the
  held-out seeds; another family, so other encounters);
* ``uavs_8``, ``uavs_32``: 8 and 32 UAVs in a square grid, 1 obstacle, as the scaling
  report's cells (:func:`uasep_env.reporting.scaling.cell_config`), on the first 100
  :data:`~uasep_env.scenarios.SCALING_SEEDS`;
* ``real_traffic``: the 300 encounters of :data:`~uasep_env.scenarios.REAL_TRAFFIC_TEST_SEEDS`
  (:data:`~uasep_env.scenarios.real_traffic.REAL_TRAFFIC_BANK`), and ``real_traffic_slow``:
  the same seeds with the tracks slowed x0.2 (``obstacle.replay_speed_scale=0.2``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from uasep_env.config import EnvConfig
from uasep_env.scenarios.seeds import HELD_OUT_SEEDS, REAL_TRAFFIC_TEST_SEEDS, SCALING_SEEDS

__all__ = ["BANKS", "Bank", "bank_config", "check_banks"]


@dataclass(frozen=True, kw_only=True)
class Bank:
    """One bank of the suite.

    Attributes:
        name: Its key (``--banks``).
        title: Its heading in the table and figure.
        seeds: Its seeds, in order (``--episodes N`` plays the first N).
        seed_range: The named range they come from (:data:`~uasep_env.scenarios.SEED_RANGES`).
        config: ``() -> EnvConfig``: the bank's environment, before ``--config`` overrides.
    """

    name: str
    title: str
    seeds: range
    seed_range: str
    config: Callable[[], EnvConfig]


def _scenario(values: Mapping[str, Any]) -> Callable[[], EnvConfig]:
    def build() -> EnvConfig:
        from uasep_env.evaluation.overrides import build_config

        values_ = dict(values)
        return build_config(values_.pop("scenario"), values_)

    return build


def _uavs(n: int) -> Callable[[], EnvConfig]:
    def build() -> EnvConfig:
        from uasep_env.reporting.scaling import cell_config

        return cell_config(n, 1)

    return build


def _real(slow: bool) -> Callable[[], EnvConfig]:
    def build() -> EnvConfig:
        from uasep_env.scenarios.real_traffic import REAL_TRAFFIC_BANK, REAL_TRAFFIC_SLOW_BANK

        return _scenario(REAL_TRAFFIC_SLOW_BANK if slow else REAL_TRAFFIC_BANK)()

    return build


_COURSES = range(HELD_OUT_SEEDS.start, HELD_OUT_SEEDS.start + 100)
_SIZES = range(SCALING_SEEDS.start, SCALING_SEEDS.start + 100)

#: Every bank, in the table's order.
BANKS: dict[str, Bank] = {
    b.name: b
    for b in (
        Bank(
            name="held_out",
            title="held-out bank (random, 3 UAVs)",
            seeds=HELD_OUT_SEEDS,
            seed_range="held_out",
            config=_scenario({"scenario": "random"}),
        ),
        Bank(
            name="collision_head_on",
            title="collision course, head-on",
            seeds=_COURSES,
            seed_range="held_out",
            config=_scenario({"scenario": "collision_head_on"}),
        ),
        Bank(
            name="collision_crossing",
            title="collision course, crossing",
            seeds=_COURSES,
            seed_range="held_out",
            config=_scenario({"scenario": "collision_crossing"}),
        ),
        Bank(
            name="uavs_8",
            title="8 UAVs (grid, 1 obstacle)",
            seeds=_SIZES,
            seed_range="scaling",
            config=_uavs(8),
        ),
        Bank(
            name="uavs_32",
            title="32 UAVs (grid, 1 obstacle)",
            seeds=_SIZES,
            seed_range="scaling",
            config=_uavs(32),
        ),
        Bank(
            name="real_traffic",
            title="real traffic (test flights)",
            seeds=REAL_TRAFFIC_TEST_SEEDS,
            seed_range="real_traffic_test",
            config=_real(False),
        ),
        Bank(
            name="real_traffic_slow",
            title="real traffic slowed x0.2",
            seeds=REAL_TRAFFIC_TEST_SEEDS,
            seed_range="real_traffic_test",
            config=_real(True),
        ),
    )
}


def check_banks(names: Sequence[str]) -> list[str]:
    """``names`` if each is a bank of :data:`BANKS` (``ValueError`` naming one that is not)."""
    for name in names:
        if name not in BANKS:
            raise ValueError(f"unknown bank {name!r}: choose from {', '.join(BANKS)}")
    if not names:
        raise ValueError("no bank given")
    return list(dict.fromkeys(names))


def bank_config(
    name: str, overrides: Mapping[str, Any] | None = None, version: int | None = None
) -> EnvConfig:
    """The environment of bank ``name`` with the suite's ``--config`` overrides applied.

    Args:
        name: The bank.
        overrides: The suite's ``--config`` overrides (applied last).
        version: The env version to play (None: the current one); a learned row plays the
            version it was trained in (:mod:`uasep_env.policies.env_version`).
    """
    from uasep_env.policies.env_version import current_version, version_config

    cfg = BANKS[name].config()
    return version_config(cfg, version or current_version(), overrides or {})
