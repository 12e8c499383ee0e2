"""Typed, frozen, validated configuration."""

import dataclasses

import pytest

from uasep_env.config import EnvConfig, NoiseConfig, make_config


def test_defaults_and_frozen():
    cfg = make_config()
    assert isinstance(cfg, EnvConfig)
    assert cfg.max_steps == 1000
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.n_uavs = 4  # type: ignore[misc]


def test_nested_dicts_and_replace():
    cfg = make_config(n_uavs=5, noise={"accel_std": 0.0}, uav={"max_speed": 12.0})
    assert cfg.noise.accel_std == 0.0 and cfg.noise.position_std == NoiseConfig().position_std
    assert cfg.uav.max_speed == 12.0
    cfg2 = cfg.replace(noise=False)
    assert cfg2.noise.is_off and cfg2.n_uavs == 5
    assert make_config({"scenario": "crossing"}).scenario == "crossing"


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"n_uavz": 3}, "n_uavz"),
        ({"noise": {"acel_std": 1}}, "noise.acel_std"),
        ({"reward": {"colision": 1}}, "reward.colision"),
        ({"n_uavs": 1}, "n_uavs=1"),
        ({"n_uavs": 33}, "n_uavs=33"),
        ({"n_obstacles": 9}, "n_obstacles=9"),
        ({"n_uavs": 2.5}, "n_uavs=2.5"),
        ({"dt": -0.1}, "dt=-0.1"),
        ({"dt": float("nan")}, "dt=nan"),
        ({"scenario": "moon"}, "scenario='moon'"),
        ({"formation": "blob"}, "formation='blob'"),
        ({"formation": ((0, 0, 0),)}, "formation"),
        ({"noise": {"accel_std": -1}}, "noise.accel_std=-1"),
        ({"prediction": {"mode": "sometimes"}}, "prediction.mode='sometimes'"),
        ({"cruise_speed": 50.0}, "cruise_speed=50.0"),
        ({"obstacle": {"wind": (1, 2)}}, "obstacle.wind"),
        ({"render_mode": "ascii"}, "render_mode='ascii'"),
        ({"uav": {"collision_distance": 20.0}}, "separation_distance"),
        ({"reward": {"shared": 1.5}}, "reward.shared=1.5"),
        ({"noise": 3}, "noise=3"),
    ],
)
def test_bad_config_names_the_value(kwargs, match):
    with pytest.raises(ValueError, match=match.replace("(", r"\(").replace(")", r"\)")):
        make_config(**kwargs)


def test_explicit_formation_is_normalised():
    cfg = make_config(n_uavs=2, formation=[[0, 0, 0], [10, 0, 0]])
    assert cfg.formation == ((0.0, 0.0, 0.0), (10.0, 0.0, 0.0))


def test_to_dict_roundtrip():
    cfg = make_config(n_uavs=4, scenario="head_on")
    d = cfg.to_dict()
    assert make_config(d) == cfg
