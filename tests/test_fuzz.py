"""Fuzz suite: hostile actions, seeds, reset options and configs against every view.

For each generated example the outcome is either an exception of the documented type whose
message names the bad value, or a finite, in-space result (issue 13). The episode lifecycle
rules are checked in every view too. Bounded (few examples, no deadline) to keep the suite
fast; ``HYPOTHESIS_PROFILE=soak`` runs many more examples.
"""

from __future__ import annotations

import math
import numbers
import os
import re

import gymnasium
import numpy as np
import pytest

pytest.importorskip("hypothesis")  # every test here is a property test (the dev extra)

from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import uasep_env
from uasep_env.config import FORMATION_PATTERNS, SCENARIOS, make_config

settings.register_profile(
    "ci",
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    derandomize=True,
)
settings.register_profile("soak", parent=settings.get_profile("ci"), max_examples=2000)
FUZZ = settings.get_profile("soak" if os.environ.get("HYPOTHESIS_PROFILE") == "soak" else "ci")

SHORT = {"episode_duration": 2.0, "n_obstacles": 2}

# --------------------------------------------------------------------------------------------
# The views, each driven through one interface: reset(seed, options) and step(action)
# --------------------------------------------------------------------------------------------


class View:
    """One environment view with a uniform step: ``step(action) -> (obs, rewards, info)``."""

    name = "?"
    action_shape: tuple[int, ...] = ()
    batched = False  # accepts a sequence of seeds

    def __init__(self, **cfg):
        self.cfg = {**SHORT, **cfg}
        self.make()
        self.done = True

    def ensure_live(self):
        if self.done:
            self.reset(seed=0)

    def reset(self, seed=None, options=None):
        obs = self._reset(seed, options)
        self.done = False
        return obs


class PettingZooView(View):
    name = "pettingzoo"
    action_shape = (3,)

    def make(self):
        self.env = uasep_env.parallel_env(**self.cfg)

    def _reset(self, seed, options):
        obs, _ = self.env.reset(seed=seed, options=options)
        return np.stack([obs[a] for a in self.env.possible_agents])

    def step(self, action):
        acts = {a: np.zeros(3, np.float32) for a in self.env.agents}
        acts["uav_1"] = action
        obs, rew, _, _, infos = self.env.step(acts)
        self.done = not self.env.agents
        obs = np.stack([obs[a] for a in self.env.possible_agents])
        clipped = np.array([infos["uav_1"]["clipped_actions"]])
        return obs, np.array(list(rew.values())), clipped

    def in_space(self, obs):
        return all(
            self.env.observation_space(a).contains(o)
            for a, o in zip(self.env.possible_agents, obs, strict=True)
        )


class GymView(View):
    action_shape = (9,)

    def __init__(self, env_id, **cfg):
        self.env_id = env_id
        self.name = env_id
        super().__init__(**cfg)

    def make(self):
        self.env = gymnasium.make(self.env_id, **self.cfg)

    def _reset(self, seed, options):
        return self.env.reset(seed=seed, options=options)[0]

    def step(self, action):
        obs, rew, term, trunc, info = self.env.step(action)
        self.done = term or trunc
        return obs, np.array([rew]), info["clipped_actions"]

    def in_space(self, obs):
        return self.env.observation_space.contains(obs)


class VectorView(View):
    name = "make_vec"
    action_shape = (2, 9)
    batched = True

    def make(self):
        # SameStep: every row steps with its action each step (NextStep ignores the action
        # of a row being reset, and that row's infos are the reset's, as in SyncVectorEnv).
        self.env = gymnasium.make_vec(
            "uasep/Formation-v3", num_envs=2, autoreset_mode="SameStep", **self.cfg
        )

    def _reset(self, seed, options):
        return self.env.reset(seed=seed, options=options)[0]

    def step(self, action):
        obs, rew, _, _, info = self.env.step(action)
        self.done = False  # autoreset: stepping goes on
        clipped = np.zeros((2, 3), dtype=np.int64)
        for part in (info, info.get("final_info", {})):  # the ended rows' infos are final
            if "clipped_actions" in part:
                rows = part["_clipped_actions"][:, None]
                clipped = np.where(rows, part["clipped_actions"], clipped)
        return obs, rew, clipped

    def in_space(self, obs):
        return self.env.observation_space.contains(obs)


class SB3View(View):
    name = "sb3"
    action_shape = (6, 3)

    def make(self):
        from uasep_env.envs.sb3 import UAVSharedVecEnv

        self.env = UAVSharedVecEnv(n_envs=2, **self.cfg)

    def _reset(self, seed, options):
        assert options is None
        self.env.seed(seed)
        return self.env.reset()

    def step(self, action):
        self.env.step_async(action)
        obs, rew, _, infos = self.env.step_wait()
        self.done = False  # same-step autoreset
        return obs, rew, np.array([i["clipped_actions"] for i in infos])

    def in_space(self, obs):
        return all(self.env.observation_space.contains(o) for o in obs)


def _views():
    views = [
        PettingZooView(),
        GymView("uasep/Formation-v3"),
        GymView("uasep/PaperEncounter-v3"),
        VectorView(),
    ]
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:  # pragma: no cover - sb3 is in the train extra
        return views
    return [*views, SB3View()]


VIEWS = _views()
VIEW_IDS = [v.name for v in VIEWS]

# --------------------------------------------------------------------------------------------
# Hostile actions
# --------------------------------------------------------------------------------------------

_ELEMENTS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1.0, 1.0),
    st.floats(-3.0, 3.0),
    st.integers(-3, 3),
    st.integers(-(2**80), 2**80),
    st.booleans(),
    st.none(),
    st.complex_numbers(max_magnitude=2),
    st.text(max_size=3),
    st.binary(max_size=3),
    st.sampled_from([np.float32(0.5), np.int8(-1), np.bool_(True), np.datetime64(1, "s")]),
)
_DTYPES = st.sampled_from(
    ["f8", "f4", "f2", "i8", "i1", "u2", "?", "c16", "M8[s]", "m8[s]", "U3", "S3"]
)


def _arrays(shape):
    shapes = st.one_of(st.just(shape), hnp.array_shapes(min_dims=0, max_dims=3, max_side=4))
    return st.one_of(
        hnp.arrays(np.float64, st.just(shape), elements=st.floats(-1.5, 1.5)),
        hnp.arrays(_DTYPES, shapes),
        hnp.arrays(np.float64, shapes, elements=st.floats(allow_nan=True, allow_infinity=True)),
    )


def _nested_lists(shape):
    if len(shape) == 1:
        return st.lists(_ELEMENTS, min_size=shape[0] - 1, max_size=shape[0] + 1)
    return st.lists(_nested_lists(shape[1:]), min_size=shape[0] - 1, max_size=shape[0] + 1)


def hostile_actions(shape):
    """Arrays of every dtype and shape, (ragged) lists of anything, scalars, objects."""
    return st.one_of(
        _arrays(shape),
        _nested_lists(shape),
        _ELEMENTS,
        st.dictionaries(st.text(max_size=2), st.floats(), max_size=2),
    )


def _is_real(x):
    if isinstance(x, (bool, np.bool_)):
        return False
    return isinstance(x, (numbers.Real, np.integer, np.floating))


def expected_action_outcome(action, shape):
    """``("type" | "shape" | "nonfinite", None)`` or ``("ok", number of out-of-box values)``."""
    if isinstance(action, np.ndarray):
        if action.dtype.kind not in "fiu":
            return "type", None
        arr = action.astype(float)
    else:

        def walk(x):
            if isinstance(x, list):
                return [walk(y) for y in x]
            if not _is_real(x):
                raise TypeError
            return max(-2, min(2, x)) if isinstance(x, int) else float(x)

        try:
            values = walk(action)
        except TypeError:
            return "type", None
        try:
            arr = np.array(values, dtype=float)
        except ValueError:  # ragged
            return "type", None
    if arr.shape != shape:
        return "shape", None
    if not np.isfinite(arr).all():
        return "nonfinite", None
    return "ok", int((np.abs(arr) > 1.0).sum())


@pytest.mark.parametrize("view", VIEWS, ids=VIEW_IDS)
@FUZZ
@given(data=st.data())
def test_hostile_actions(view, data):
    action = data.draw(hostile_actions(view.action_shape), label="action")
    kind, n_clipped = expected_action_outcome(action, view.action_shape)
    view.ensure_live()
    if kind == "ok":
        obs, rewards, clipped = view.step(action)
        assert view.in_space(obs)
        assert np.isfinite(rewards).all()
        assert int(np.sum(clipped)) == n_clipped
        return
    with pytest.raises((TypeError, ValueError)) as info:
        view.step(action)
    msg = str(info.value)
    if kind == "type":
        assert isinstance(info.value, TypeError), msg
        assert "must be real numbers" in msg or "rectangular" in msg, msg
    elif kind == "shape":
        assert f"must have shape {view.action_shape}" in msg, msg
    else:
        assert re.search(r"non-finite value (nan|inf|-inf) at index", msg), msg


_STRICT: dict = {}


@pytest.mark.parametrize("view", VIEWS, ids=VIEW_IDS)
@FUZZ
@given(scale=st.floats(1.0, 1e300), sign=st.sampled_from([-1.0, 1.0]))
def test_strict_mode_raises_where_default_clips(view, scale, sign):
    assume(scale > 1.0 + 1e-6)
    if view.name not in _STRICT:
        args = (view.env_id,) if isinstance(view, GymView) else ()
        _STRICT[view.name] = type(view)(*args, action={"strict": True})
    strict = _STRICT[view.name]
    strict.ensure_live()
    action = np.zeros(view.action_shape)
    action.flat[-1] = sign * scale
    with pytest.raises(ValueError, match=re.escape(f"value {sign * scale}")):
        strict.step(action)
    view.ensure_live()
    *_, clipped = view.step(action)
    assert int(np.sum(clipped)) == 1


# --------------------------------------------------------------------------------------------
# Seeds and reset options
# --------------------------------------------------------------------------------------------

_SEED_ITEMS = st.one_of(
    st.none(),
    st.integers(-5, 2**70),
    st.booleans(),
    st.floats(-2, 10),
    st.text(max_size=3),
    st.sampled_from([np.int64(3), np.uint8(4), np.float64(2.0), np.bool_(False)]),
)
HOSTILE_SEEDS = st.one_of(
    _SEED_ITEMS,
    st.binary(max_size=3),
    st.lists(_SEED_ITEMS, max_size=3),
    st.tuples(_SEED_ITEMS, _SEED_ITEMS),
    st.builds(lambda xs: np.array(xs), st.lists(st.integers(-3, 9), min_size=2, max_size=2)),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=2),
)


def _int_seed(x):
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_)) and x >= 0


def seed_ok(seed, batched, n=2):
    if seed is None or _int_seed(seed):
        return True
    if batched and isinstance(seed, (list, tuple, np.ndarray)) and len(seed) == n:
        return all(s is None or _int_seed(s) for s in seed)
    return False


@pytest.mark.parametrize("view", VIEWS, ids=VIEW_IDS)
@FUZZ
@given(seed=HOSTILE_SEEDS)
def test_hostile_seeds(view, seed):
    if seed_ok(seed, view.batched):
        assert view.in_space(view.reset(seed=seed))
        return
    with pytest.raises((TypeError, ValueError)) as info:
        view.reset(seed=seed)
    msg = str(info.value)
    assert "seed" in msg, msg
    items = list(seed) if isinstance(seed, (list, tuple, np.ndarray)) else []
    assert any(repr(x) in msg for x in [seed, *items]), msg


_OPTION_VALUES = st.one_of(st.none(), st.integers(), st.text(max_size=3), st.lists(st.integers()))
HOSTILE_OPTIONS = st.one_of(
    st.none(),
    st.just({}),
    _OPTION_VALUES,
    st.dictionaries(
        st.sampled_from(["reset_mask", "bogus", "seed", "x"]), _OPTION_VALUES, max_size=2
    ),
)


@pytest.mark.parametrize(
    "view",
    [v for v in VIEWS if not isinstance(v, SB3View)],
    ids=[v.name for v in VIEWS if not isinstance(v, SB3View)],
)
@FUZZ
@given(options=HOSTILE_OPTIONS)
def test_hostile_reset_options(view, options):
    if isinstance(view, PettingZooView):  # unknown keys ignored (PettingZoo's API test)
        ok = options is None or isinstance(options, dict)
    elif isinstance(view, VectorView):
        ok = options is None or options == {}
    else:
        ok = options is None or options == {}
    if ok:
        unknown = [k for k in options or () if k != "config"]
        if isinstance(view, PettingZooView) and unknown:  # ignored, with a warning naming them
            with pytest.warns(UserWarning, match=re.escape(repr(unknown))):
                assert view.in_space(view.reset(seed=1, options=options))
            return
        assert view.in_space(view.reset(seed=1, options=options))
        return
    with pytest.raises((TypeError, ValueError)) as info:
        view.reset(seed=1, options=options)
    if not isinstance(options, dict):
        assert isinstance(info.value, TypeError)
        assert "options must be a dict or None, got" in str(info.value)
    elif isinstance(view, VectorView) and set(options) == {"reset_mask"}:
        assert "reset_mask" in str(info.value)
    else:
        bad = [k for k in options if k != "reset_mask" or not isinstance(view, VectorView)]
        assert any(repr(k) in str(info.value) for k in bad), str(info.value)


# --------------------------------------------------------------------------------------------
# Configs
# --------------------------------------------------------------------------------------------

_NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(0.0, 30.0),
    st.floats(0.0, 2e6),
    st.integers(-3, 40),
    st.sampled_from([1e39, 1e154, 1e300, -1e308, 5000.0]),
)
_ANY = st.one_of(
    _NUMBERS,
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.lists(st.floats(-50, 50), max_size=4),
    st.lists(st.text(max_size=2), min_size=3, max_size=3),
    st.just({}),
)
_FIELDS = {
    "n_uavs": st.one_of(st.integers(-1, 34), _ANY),
    "n_obstacles": st.one_of(st.integers(-1, 9), _ANY),
    "scenario": st.one_of(st.sampled_from([*SCENARIOS, "moon"]), _ANY),
    "formation": st.one_of(
        st.sampled_from([*FORMATION_PATTERNS, "blob"]),
        st.lists(st.lists(st.floats(-100, 100), min_size=3, max_size=3), min_size=3, max_size=3),
        _ANY,
    ),
    "formation_spacing": _NUMBERS,
    "cruise_speed": _NUMBERS,
    "dt": st.one_of(st.floats(0.01, 5.0), _NUMBERS),
    "decision_interval": st.one_of(st.integers(0, 4), _ANY),
    "episode_duration": _NUMBERS,
    "uav.max_speed": _NUMBERS,
    "uav.max_accel": _NUMBERS,
    "uav.collision_distance": _NUMBERS,
    "uav.separation_distance": _NUMBERS,
    "noise.accel_std": _NUMBERS,
    "noise.position_std": _NUMBERS,
    "noise.obstacle_velocity_std": _NUMBERS,
    "noise": st.one_of(st.booleans(), _ANY),
    "obstacle.speed": _NUMBERS,
    "obstacle.max_turn_rate": st.one_of(st.floats(0, 7), _NUMBERS),
    "obstacle.max_climb_rate": _NUMBERS,
    "obstacle.radius": _NUMBERS,
    "obstacle.mean_switch_time": _NUMBERS,
    "obstacle.straight_probability": st.one_of(st.floats(0, 1), _NUMBERS),
    "obstacle.wind": st.one_of(st.lists(st.floats(-300, 300), min_size=3, max_size=3), _ANY),
    "obstacle": _ANY,
    "prediction.horizon": st.one_of(st.floats(0.1, 700), _NUMBERS),
    "prediction.mode": st.one_of(st.sampled_from(["swept", "terminal"]), _ANY),
    "prediction.kalman": _ANY,
    "observation.k_uavs": st.one_of(st.integers(0, 32), _ANY),
    "observation.k_obstacles": st.one_of(st.integers(0, 9), _ANY),
    "observation.position_scale": _NUMBERS,
    "observation.clip": _NUMBERS,
    "observation.sensing_range": _NUMBERS,
    "reward.collision": _NUMBERS,
    "reward.deviation": _NUMBERS,
    "reward.shared": st.one_of(st.floats(0, 1), _NUMBERS),
    "action.strict": _ANY,
    "render_mode": _ANY,
}
_UNKNOWN_KEYS = st.sampled_from(
    [
        "n_uavz",
        "noise.acel_std",
        "reward.colision",
        "action.mode_x",
        "observation.range",
        "uav.speed",
    ]
)


def _nest(flat):
    out: dict = {}
    for key, value in flat.items():
        head, _, tail = key.partition(".")
        if tail:
            node = out.get(head)
            if not isinstance(node, dict):
                node = out[head] = {}
            node[tail] = value
        else:
            out[head] = value
    return out


CONFIGS = st.dictionaries(
    st.sampled_from(sorted(_FIELDS)), st.none(), min_size=1, max_size=3
).flatmap(lambda d: st.fixed_dictionaries({k: _FIELDS[k] for k in d}))


def _named(msg, flat):
    return any(re.search(rf"\b{re.escape(k)}\b", msg) or k.split(".")[0] in msg for k in flat)


@FUZZ
@given(flat=CONFIGS, unknown=st.one_of(st.none(), _UNKNOWN_KEYS))
def test_hostile_configs(flat, unknown):
    """Every config is a named TypeError (unknown key), a named ValueError, or simulates."""
    if unknown is not None:
        flat = {**flat, unknown: 1}
    config = _nest(flat)
    try:
        cfg = make_config(config)
    except TypeError as err:
        assert unknown is not None, err
        assert unknown.split(".")[-1] in str(err)
        return
    except ValueError as err:
        assert "invalid config value" in str(err), err
        assert _named(str(err), flat), err
        return
    assert unknown is None
    # A config that validates must simulate: finite rewards and in-space observations.
    cfg = cfg.replace(episode_duration=min(cfg.episode_duration, 3 * cfg.step_duration))
    env = uasep_env.parallel_env(cfg)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        if not env.agents:
            break
        acts = {a: rng.uniform(-1.2, 1.2, 3) for a in env.agents}
        obs, rew, *_ = env.step(acts)
        assert all(math.isfinite(r) for r in rew.values()), rew
        for a, o in obs.items():
            assert env.observation_space(a).contains(o), a


# Every view rejects an unknown keyword with a TypeError naming it.
@pytest.mark.parametrize(
    "build",
    [
        lambda kw: uasep_env.parallel_env(**kw),
        lambda kw: make_config(**kw),
        lambda kw: gymnasium.make("uasep/Formation-v3", **kw),
        lambda kw: gymnasium.make("uasep/PaperEncounter-v3", **kw),
        lambda kw: gymnasium.make_vec("uasep/Formation-v3", num_envs=2, **kw),
        lambda kw: pytest.importorskip("uasep_env.envs.sb3").UAVSharedVecEnv(n_envs=1, **kw),
    ],
    ids=["pettingzoo", "make_config", "gym-formation", "gym-paper", "make_vec", "sb3"],
)
@FUZZ
@given(key=st.from_regex(r"[a-z][a-z_]{0,12}", fullmatch=True))
def test_unknown_keyword_is_a_type_error_in_every_view(build, key):
    assume(key not in _FIELDS and key not in ("num_envs", "n_envs", "config", "seed"))
    assume(key not in ("uav", "noise", "obstacle", "prediction", "observation", "reward"))
    assume(key not in ("autoreset_mode", "vectorization_mode", "vector_kwargs", "wrappers"))
    assume(key not in ("render_mode", "max_episode_steps", "disable_env_checker", "kwargs"))
    assume(key not in ("apply_api_compatibility", "action"))
    with pytest.raises(TypeError, match=re.escape(key)):
        build({key: 1})


# --------------------------------------------------------------------------------------------
# Lifecycle
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("view", VIEWS, ids=VIEW_IDS)
@FUZZ
@given(steps=st.integers(1, 25), seed=st.integers(0, 2**32), scale=st.floats(0, 1.5))
def test_lifecycle_rules(view, steps, seed, scale):
    """Single views refuse to step a finished episode; vector views autoreset."""
    view.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        action = rng.uniform(-scale, scale, view.action_shape)
        if view.done:
            assert isinstance(view, (PettingZooView, GymView))
            with pytest.raises(RuntimeError, match="reset"):
                view.step(action)
            view.reset()
            continue
        obs, rewards, _ = view.step(action)
        assert view.in_space(obs) and np.isfinite(rewards).all()
