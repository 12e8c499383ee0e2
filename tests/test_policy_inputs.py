"""Every policy refuses an observation that is not finite, the same way (issue 55, item 3).

Without the check one NaN in an obstacle's relative position came out of the APFs, the
CBF-QP and every ``+cbf`` shield as NaN actions. Every registered name (and its shielded
variant, and the shipped learned policies) is played here, so a new controller inherits the
test; the check itself is :mod:`uasep_env.policies.guard`, applied by the registry.
"""

import re

import numpy as np
import pytest

from uasep_env import make_config
from uasep_env.envs.core import EnvCore
from uasep_env.interface.observation import ObservationLayout
from uasep_env.policies import REGISTRY, SHIELDS, Shielded, make_policy, shipped_policies
from uasep_env.policies.guard import check_finite_observations

CONFIG = make_config(scenario="random", n_obstacles=1, n_uavs=3)  # the shipped ones fit
NAMES = (
    sorted(REGISTRY)
    + [f"{name}+{shield}" for name in sorted(REGISTRY) for shield in SHIELDS]
    + sorted(shipped_policies())
)
# (entry name in the layout, agent row, bad value): an obstacle's relative position (the
# issue's case), the own velocity, a neighbour UAV's relative velocity, the last entry.
BAD = [
    ("obstacle0.rel_pos[1]", (1, 2), np.nan),
    ("velocity[0]", (0, 0), np.inf),
    ("uav1.rel_vel[2]", (2, 2), -np.inf),
    ("obstacle0.rel_vel[0]", (1, 1), np.nan),
]


@pytest.fixture(scope="module")
def observations():
    obs = EnvCore(CONFIG, n_envs=3).reset(seed=0)
    assert np.isfinite(obs).all()
    return obs


@pytest.mark.parametrize("name", NAMES)
def test_every_policy_refuses_a_non_finite_observation(name, observations):
    names = ObservationLayout.from_config(CONFIG).feature_names()
    policy = make_policy(name, CONFIG)
    assert np.isfinite(policy(observations)).all()  # finite in: finite out, no error
    for entry, row, value in BAD:
        obs = observations.copy()
        obs[(*row, names.index(entry))] = value
        message = re.escape(f"observation entry {entry!r} (column {names.index(entry)}) ")
        with pytest.raises(ValueError, match=message + r".* is not finite: -?(nan|inf)$"):
            policy(obs)
        with pytest.raises(ValueError, match=message):  # one agent's vector alike
            policy(obs[row])


def test_a_shielded_policy_of_your_own_refuses_it(observations):
    """The shield checks its input itself: a wrapped object of your own is not checked."""
    plan_only = lambda obs: np.zeros((*np.shape(obs)[:-1], 3), np.float32)  # noqa: E731
    shielded = Shielded(plan_only, CONFIG)
    obs = observations.copy()
    obs[0, 0, -1] = np.nan
    with pytest.raises(ValueError, match="is not finite: nan"):
        shielded(obs)


def test_the_entry_is_named_by_index_without_a_config():
    with pytest.raises(ValueError, match=r"^observation entry column 2 of row \(1,\) is not "):
        check_finite_observations(np.array([[0.0, 1.0, 2.0], [0.0, 1.0, np.inf]]))
    check_finite_observations(np.zeros((2, 3), dtype=np.int64))  # integers are finite
