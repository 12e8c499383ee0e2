"""Typed, frozen, validated configuration."""

import dataclasses
import re

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
        ({"n_uavs": 1}, "n_uavs=1"),
        ({"n_uavs": 65}, "n_uavs=65"),
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
        # Wrong types name the dotted field, not numpy's conversion error.
        ({"formation": {}}, "formation={}"),
        ({"formation": (("a", "b", "c"),) * 3}, "formation[0]=('a', 'b', 'c')"),
        ({"formation": (("1", "2", "3"),) * 3}, "formation[0]=('1', '2', '3')"),
        ({"obstacle": {"wind": 5}}, "obstacle.wind=5"),
        ({"obstacle": {"wind": None}}, "obstacle.wind=None"),
        ({"obstacle": {"wind": "abc"}}, "obstacle.wind='abc'"),
        ({"obstacle": None}, "obstacle=None"),
        ({"scenario": ["paper"]}, "scenario=['paper']"),
        ({"n_uavs": True}, "n_uavs=True"),
        ({"dt": True}, "dt=True"),
        ({"action": {"strict": 1}}, "action.strict=1"),
        # Values that used to validate and then fail (overflow, gymnasium's Box, -inf reward).
        ({"observation": {"clip": 1e39}}, "observation.clip=1e+39"),
        ({"noise": {"accel_std": 1e154}}, "noise.accel_std=1e+154"),
        ({"noise": {"obstacle_velocity_std": 1e154}}, "noise.obstacle_velocity_std=1e+154"),
        ({"obstacle": {"speed": 1e154}}, "obstacle.speed=1e+154"),
        ({"obstacle": {"max_turn_rate": 1e154}}, "obstacle.max_turn_rate=1e+154"),
        ({"obstacle": {"wind": (1e300, 0, 0)}}, "obstacle.wind=(1e+300, 0, 0)"),
        ({"reward": {"collision": 1e308}}, "reward.collision=1e+308"),
        ({"reward": {"deviation": -1e308}}, "reward.deviation=-1e+308"),
        ({"uav": {"max_accel": 1e200}}, "uav.max_accel=1e+200"),
        ({"episode_duration": 1e300}, "episode_duration=1e+300"),
        # Sensing beyond what an observation can express (clip * position_scale).
        ({"observation": {"sensing_range": 5000.0}}, "observation.sensing_range=5000.0"),
        (
            {"observation": {"sensing_range": 300.0, "clip": 2.0}},
            "observation.sensing_range=300.0",
        ),
    ],
)
def test_bad_config_names_the_value(kwargs, match):
    with pytest.raises(ValueError, match=re.escape(match)):
        make_config(**kwargs)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"n_uavz": 3}, "n_uavz"),
        ({"noise": {"acel_std": 1}}, "noise.acel_std"),
        ({"reward": {"colision": 1}}, "reward.colision"),
        ({"action": {"strikt": True}}, "action.strikt"),
    ],
)
def test_unknown_config_key_is_a_type_error_naming_it(kwargs, match):
    with pytest.raises(TypeError, match=match):
        make_config(**kwargs)
    with pytest.raises(TypeError, match=match):
        make_config(kwargs)


def test_action_group_defaults_to_clipping():
    assert make_config().action.strict is False
    assert make_config(action={"strict": True}).action.strict is True


def test_explicit_formation_is_normalised():
    cfg = make_config(n_uavs=2, formation=[[0, 0, 0], [10, 0, 0]])
    assert cfg.formation == ((0.0, 0.0, 0.0), (10.0, 0.0, 0.0))


def test_to_dict_roundtrip():
    cfg = make_config(n_uavs=4, scenario="head_on")
    d = cfg.to_dict()
    assert make_config(d) == cfg


def test_as_published_runs_the_papers_prediction():
    """AS_PUBLISHED selects the terminal set and the paper's ellipsoid; the world uses them."""
    import numpy as np

    from uasep_env import reachable
    from uasep_env.config import AS_PUBLISHED
    from uasep_env.sim.world import World

    cfg = make_config(AS_PUBLISHED, scenario="paper")
    assert (cfg.prediction.mode, cfg.prediction.fit) == ("terminal", "paper")
    world = World(cfg, n_envs=1)
    world.reset(seed=0)
    axes = world.pred_axes[0, 0]
    assert axes[1] == axes[2]  # a circular section across the heading
    default = World(make_config(scenario="paper"), n_envs=1)
    default.reset(seed=0)
    assert np.all(default.pred_axes[0, 0] > axes)  # the enclosing one is larger everywhere
    _, ref = reachable.ellipsoid(4.0, 0.013, 0.5, 10.0, 3.0, mode="terminal", fit="paper")
    assert ref[1] == ref[2]
    with pytest.raises(ValueError, match=r"prediction\.fit"):
        make_config(prediction={"fit": "tight"})


def test_any_sequence_is_a_formation_or_vector():
    """Issue 23 item 8: OmegaConf's ListConfig (Hydra, BenchMARL YAML) is a sequence too."""
    omegaconf = pytest.importorskip("omegaconf")
    yaml = omegaconf.OmegaConf.create(
        {"formation": [[-20, 0, 0], [20, 0, 0], [0, 0, 0]], "obstacle": {"wind": [1, 0, 0]}}
    )
    cfg = make_config(formation=yaml.formation, obstacle={"wind": yaml.obstacle.wind})
    assert cfg.formation == ((-20.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert cfg.obstacle.wind == (1.0, 0.0, 0.0)
    assert make_config(yaml) == cfg  # a whole DictConfig
    with pytest.raises(ValueError, match=r"formation.*shape \(3, 3\)"):
        make_config(formation=omegaconf.OmegaConf.create([[0, 0, 0]]))
    with pytest.raises(ValueError, match="formation"):
        make_config(formation=b"abc")  # bytes are not a sequence of slots


# --- keyword-only dataclasses: a field added out of place cannot shift the others -----------


def _package_dataclasses() -> list[type]:
    """Every frozen dataclass defined in ``uasep_env`` (found by importing each module).

    A module that needs an optional dependency this installation lacks is skipped (the
    floors job has none); the full job imports them all.
    """
    import importlib
    import inspect
    import pkgutil

    import uasep_env

    found = {}
    for info in pkgutil.walk_packages(uasep_env.__path__, "uasep_env."):
        if info.name.endswith("__main__"):
            continue
        try:
            module = importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if (err.name or "").split(".")[0] == "uasep_env":
                raise
            continue
        for obj in vars(module).values():
            if (
                inspect.isclass(obj)
                and dataclasses.is_dataclass(obj)
                and obj.__module__ == info.name
                and obj.__dataclass_params__.frozen
            ):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return [found[k] for k in sorted(found)]


def test_the_discovery_finds_the_config_dataclasses():
    from uasep_env.config import RewardWeights
    from uasep_env.policies import APFGains
    from uasep_env.policies.checkpoint_reader import CheckpointLimits

    found = set(_package_dataclasses())
    assert {EnvConfig, NoiseConfig, RewardWeights, APFGains, CheckpointLimits} <= found
    groups = {type(v) for v in vars(make_config()).values() if dataclasses.is_dataclass(v)}
    assert len(groups) >= 7 and groups <= found  # every config group


@pytest.mark.parametrize("cls", _package_dataclasses(), ids=lambda c: c.__qualname__)
def test_every_frozen_dataclass_takes_keywords_only(cls):
    """``RewardWeights(...)`` with positional values once set a new weight where ``shared``
    was meant; keyword-only fields make any positional construction a TypeError."""
    assert all(f.kw_only for f in dataclasses.fields(cls) if f.init), cls
    with pytest.raises(TypeError, match="takes 1 positional argument but 2 were given"):
        cls(object())


def test_the_scripts_frozen_dataclasses_take_keywords_only():
    """baselines/ and train/ are scripts (not imported here): their decorators are read."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    seen, positional = [], []
    for path in sorted([*root.glob("baselines/*.py"), *root.glob("train/*.py")]):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            for dec in node.decorator_list:
                if not (isinstance(dec, ast.Call) and ast.unparse(dec.func).endswith("dataclass")):
                    continue
                kw = {k.arg: ast.unparse(k.value) for k in dec.keywords}
                if kw.get("frozen") == "True":
                    seen.append(node.name)
                    if kw.get("kw_only") != "True":
                        positional.append(f"{path.name}:{node.name}")
    # Method (the trade-off sweep's table) and scaling.PolicyEntry moved into the package
    # (checked above); the scripts that still declare frozen dataclasses take keywords only.
    assert not positional, positional
