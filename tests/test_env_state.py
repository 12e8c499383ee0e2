"""A batch's state saved as plain arrays and loaded into a fresh one steps on exactly (issue 55).

``World.state_dict`` / ``load_state_dict`` (and the core's and the SB3 view's over them)
are what an SB3 checkpoint keeps of its environments (``env_state.npz``): a view that loads
another's state, through an npz read with ``allow_pickle=False``, must give the same
observations, rewards, ends and infos as the original, bit for bit, and a bad state must be
refused in one line naming the array, before anything is written.
"""

import io

import numpy as np
import pytest

from uasep_env.sim.world import World

#: Episodes with obstacles and noise in loss of separation from the start (the running
#: episodes' safety flags set): the direct ones end at different times (UAVs lost 35 m from
#: their plan), the residual ones fly long enough for their deviations to count (40 s).
CONFIGS = {
    "direct": {"n_uavs": 3, "n_obstacles": 2, "scenario": "random", "episode_duration": 45.0,
               "uav": {"separation_distance": 30.0, "lost_distance": 35.0,
                       "obstacle_separation": 10.0}},
    "residual": {"n_uavs": 2, "n_obstacles": 1, "scenario": "random", "episode_duration": 44.0,
                 "action": {"mode": "residual_apf"}, "uav": {"separation_distance": 30.0}},
    "no obstacle": {"n_uavs": 2, "n_obstacles": 0, "scenario": "crossing",
                    "episode_duration": 6.0},
}  # fmt: skip


def _through_npz(state):
    """``state`` written by ``np.savez`` and read back without pickle (a checkpoint's way)."""
    buf = io.BytesIO()
    np.savez(buf, **state)
    buf.seek(0)
    with np.load(buf, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _same(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    return a == b or (a != a and b != b)  # NaN


@pytest.mark.parametrize("name", list(CONFIGS))
def test_a_loaded_sb3_view_steps_on_as_the_original(name):
    pytest.importorskip("stable_baselines3")
    from uasep_env.envs.sb3 import UAVSharedVecEnv

    config = CONFIGS[name]
    rng = np.random.default_rng(7)
    a = UAVSharedVecEnv(n_envs=3, config=config, seed=11)
    a.reset()
    for _ in range(130):
        a.step(rng.uniform(-1.5, 1.5, (a.num_envs, 3)).astype(np.float32))
    saved = _through_npz(a.state_dict())
    if name == "direct":  # the batch's episodes at different steps
        assert len(set(saved["world.steps"].tolist())) == 3
    b = UAVSharedVecEnv(n_envs=3, config=config, seed=999)  # its seed is not used
    b.load_state_dict(saved)
    assert _same(b.state_dict(), saved)  # every part restored, the running episodes' too
    ends = 0
    for _ in range(160):
        act = rng.uniform(-1.5, 1.5, (a.num_envs, 3)).astype(np.float32)
        out_a, out_b = a.step(act), b.step(act)
        assert _same(out_a, out_b)
        ends += int(out_a[2].sum())
    assert ends  # episodes ended (and reset) after the load, their summaries compared
    assert _same(a.state_dict(), b.state_dict())


def test_a_world_state_is_the_whole_world():
    """Every array attribute of the world and its parts is in the state (none forgotten)."""
    w = World({"n_uavs": 2, "scenario": "random"}, 2)
    w.reset(seed=1)
    state = w.state_dict()
    for prefix, obj in (("", w), ("obstacles.", w.obstacles), ("plan.", w.plan)):
        for attr, value in vars(obj).items():
            if isinstance(value, np.ndarray):
                assert prefix + attr in state
    assert state["noise.generators"].shape == (2, 6)


def _world_and_state():
    w = World({"n_uavs": 2, "scenario": "random"}, 2)
    w.reset(seed=3)
    w.step(np.zeros((2, 2, 3)))
    return w, w.state_dict()


def _set(name, value):
    def change(state):
        state[name] = value(state[name])

    return change


BAD_STATES = {
    "wrong shape": (_set("uav_pos", lambda a: a[:1]), r"^uav_pos: shape \(1, 2, 3\), expected"),
    "wrong dtype": (_set("steps", lambda a: a.astype(float)), r"^steps: dtype float64, expected"),
    "NaN": (_set("est_vel", lambda a: a * np.nan), r"^est_vel: NaN values$"),
    "inf": (_set("time", lambda a: a + np.inf), r"^time: infinite values$"),
    "huge": (_set("uav_pos", lambda a: a + 1e300), r"^uav_pos: values beyond 1e\+12"),
    "negative steps": (_set("steps", lambda a: a - 5), r"^steps: values outside \[0, "),
    "noise position": (_set("noise.buf_pos", lambda a: a + 100), r"^noise.buf_pos: values outs"),
    "generators": (
        _set("noise.generators", lambda a: a.astype(np.int64)),
        r"^noise.generators: int64",
    ),
    "cached half": (
        _set("noise.generators", lambda a: a + np.uint64(7)),
        r"^noise.generators: a cached",
    ),
    "families": (_set("families", lambda a: a[:1]), r"^families: .* expected 2 names"),
    "missing": (lambda s: s.pop("slots"), r"^slots: missing$"),
    "unexpected": (lambda s: s.update(junk=np.zeros(1)), r"^'junk': not part of the state$"),
    "not an array": (_set("time", lambda a: a.tolist()), r"^time: list, not an array$"),
}


@pytest.mark.parametrize("case", sorted(BAD_STATES))
def test_a_bad_world_state_is_refused_naming_the_array_and_changes_nothing(case):
    _, state = _world_and_state()
    change, message = BAD_STATES[case]
    change(state)
    target, _ = _world_and_state()
    target.step(np.ones((2, 2, 3)))  # a state of its own, which a refusal keeps
    before = target.state_dict()
    with pytest.raises(ValueError, match=message) as err:
        target.load_state_dict(state)
    assert "\n" not in str(err.value)
    assert _same(target.state_dict(), before)


def test_a_core_names_the_world_arrays_as_its_state_does():
    from uasep_env.envs.core import EnvCore

    core = EnvCore({"n_uavs": 2}, n_envs=2)
    core.reset(seed=0)
    state = core.state_dict()
    state["world.uav_pos"] = state["world.uav_pos"][:, :1]
    with pytest.raises(ValueError, match=r"^world\.uav_pos: shape"):
        EnvCore({"n_uavs": 2}, n_envs=2).load_state_dict(state)
    state = core.state_dict()
    state["core.obs"] = state["core.obs"].astype(np.float64)
    with pytest.raises(ValueError, match=r"^core\.obs: dtype float64"):
        EnvCore({"n_uavs": 2}, n_envs=2).load_state_dict(state)
