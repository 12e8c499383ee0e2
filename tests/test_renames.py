"""Obstacle quantities are ``obstacle_*``; the old public ``obs_*`` names warn for a version."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from uasep_env import World
from uasep_env.policies.apf import RENAMED_GAINS, APFGains


@pytest.mark.parametrize(("old", "new"), sorted(RENAMED_GAINS.items()))
def test_old_gain_names_warn_and_mean_the_new_ones(old, new):
    with pytest.deprecated_call(match=new):
        g = APFGains(**{old: 7.0})
    assert getattr(g, new) == 7.0
    assert g == APFGains(**{new: 7.0})
    with pytest.deprecated_call(match=new):
        assert getattr(g, old) == 7.0
    with pytest.deprecated_call(match=new):
        scaled = APFGains().scaled((old,), 2.0)
    assert getattr(scaled, new) == 2.0 * getattr(APFGains(), new)
    with pytest.raises(TypeError, match=new), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        APFGains(**{old: 1.0, new: 2.0})


def test_new_gain_names_do_not_warn_and_bad_values_name_the_new_field():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = APFGains(obstacle_safe_min=9.0, obstacle_time=3.0, k_obstacle=40.0)
        assert g.scaled(("obstacle_safe_min",), 2.0).obstacle_safe_min == 18.0
    with pytest.raises(ValueError, match=r"gains\.obstacle_safe_min"), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        APFGains(obs_safe_min=0.0)
    with pytest.raises(AttributeError, match="nope"):
        _ = g.nope


def test_old_world_attribute_names_warn_and_read_the_new_arrays():
    w = World({"n_uavs": 3, "n_obstacles": 2, "scenario": "random"}, 2)
    w.reset(seed=0)
    for old, new in (
        ("obs_est_pos", "obstacle_est_pos"),
        ("obs_est_vel", "obstacle_est_vel"),
        ("min_obs_dist", "min_obstacle_dist"),
    ):
        with pytest.deprecated_call(match=rf"World\.{new}"):
            value = getattr(w, old)
        assert value is getattr(w, new)
    assert np.isfinite(w.min_obstacle_dist).all()
    with pytest.raises(AttributeError, match="obs_nope"):
        _ = w.obs_nope
