"""Partial resets: several environments reset in one call, bit for bit as one at a time."""

import numpy as np
import pytest

from uasep_env import World, make_config


def _state(world: World) -> dict[str, object]:
    """Every array of the world, its obstacles and plan, the families and each generator."""
    out: dict[str, object] = {}
    for prefix, obj in (("", world), ("obstacles.", world.obstacles), ("plan.", world.plan)):
        for name, value in vars(obj).items():
            if isinstance(value, np.ndarray):
                out[prefix + name] = value.copy()
    out["families"] = list(world.families)
    out["noise.buf_pos"] = world._noise.buf_pos.copy()
    out["rngs"] = [rng.bit_generator.state for rng in world._noise.rngs]
    return out


def _assert_same(a: World, b: World) -> None:
    sa, sb = _state(a), _state(b)
    assert sa.keys() == sb.keys()
    for k, v in sa.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(v, sb[k], err_msg=k, strict=True)
        else:
            assert v == sb[k], k
    # The noise already drawn into the buffers, as the environments will read it.
    for buf in ("_normal_buf", "_unif_buf"):
        np.testing.assert_array_equal(getattr(a._noise, buf), getattr(b._noise, buf), err_msg=buf)


def _pair(e: int = 12) -> tuple[World, World, np.random.Generator]:
    # A short noise block, so that the resets' first measurements refill some blocks.
    cfg = make_config(scenario="random", n_obstacles=2)
    a, b = World(cfg, e, noise_block=8), World(cfg, e, noise_block=8)
    a.reset(seed=0)
    b.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(5):
        act = rng.uniform(-2.0, 2.0, (e, cfg.n_uavs, 3))
        a.step(act)
        b.step(act)
    return a, b, rng


def _step_both(a: World, b: World, rng: np.random.Generator, steps: int) -> None:
    for _ in range(steps):
        act = rng.uniform(-2.0, 2.0, (a.n_envs, a.n_uavs, 3))
        a.step(act)
        b.step(act)
        _assert_same(a, b)


def test_batched_partial_reset_equals_one_env_at_a_time():
    a, b, rng = _pair()
    ended = np.array([1, 2, 5, 7, 8, 11])
    mask = np.zeros(a.n_envs, dtype=bool)
    mask[ended] = True
    a.reset(mask=mask)  # several environments end in the same step: one call
    for i in ended[::-1]:  # one at a time, in another order: each env has its own stream
        one = np.zeros(a.n_envs, dtype=bool)
        one[i] = True
        b.reset(mask=one)
    # The ``random`` mix: the environments reset together drew different families.
    assert len({a.families[i] for i in ended}) >= 3, [a.families[i] for i in ended]
    _assert_same(a, b)
    _step_both(a, b, rng, 20)  # their noise streams go on alike, across block refills


def test_batched_partial_reset_with_seeds_equals_fresh_envs():
    a, _, _ = _pair()
    mask = np.zeros(a.n_envs, dtype=bool)
    mask[[0, 3, 4, 9]] = True
    seeds = [100 + i if m else None for i, m in enumerate(mask)]
    a.reset(seed=seeds, mask=mask)
    for i in np.flatnonzero(mask):
        fresh = World(a.config, 1, noise_block=8)
        fresh.reset(seed=100 + int(i))
        for name in ("uav_pos", "uav_vel", "est_pos", "est_vel", "obstacle_est_pos",
                     "obstacle_est_vel", "pred_center", "pred_axes", "pred_heading",
                     "min_uav_dist", "min_obstacle_dist", "slots", "_plan_offsets"):  # fmt: skip
            np.testing.assert_array_equal(
                getattr(a, name)[i], getattr(fresh, name)[0], err_msg=f"{name} env {i}"
            )
        assert a.families[i] == fresh.families[0]
        assert a._noise.rngs[i].bit_generator.state == fresh._noise.rngs[0].bit_generator.state


def test_vector_env_infos_of_reset_rows_are_masked_out_and_zero():
    """NextStep autoreset: the rows reset in a step carry the reset's (empty) info."""
    from uasep_env.envs.vector import FormationVectorEnv

    vec = FormationVectorEnv(4, episode_duration=1.0, n_obstacles=1)  # 5 steps an episode
    vec.reset(seed=3)
    zero = np.zeros(vec.action_space.shape, dtype=np.float32)
    for _ in range(2):
        vec.step(zero)
    vec.reset(options={"reset_mask": np.array([True, True, False, False])})  # out of step
    pending = np.zeros(4, dtype=bool)
    while not pending.any():
        *_, terminated, truncated, _ = vec.step(zero)
        pending = terminated | truncated
    assert not pending.all()
    _, _, _, _, infos = vec.step(zero)  # resets the pending rows
    keys = [k for k in infos if not k.startswith("_")]
    assert "min_uav_distance" in keys
    for k in keys:
        np.testing.assert_array_equal(infos["_" + k], ~pending, err_msg=k)
        assert not np.any(infos[k][pending]), k
    assert np.all(infos["min_uav_distance"][~pending] > 0.0)


def test_a_reset_env_held_still_leaves_the_others_noise_their_own():
    """The vector envs' autoreset: env 0 reset, then held still a step while the others move.

    Its first measurements took a row of its noise, so it is a row ahead of the others; the
    others still read their own rows, before and after their blocks refill, bit for bit as a
    world without env 0 (fails when the held step hands them env 0's row).
    """
    cfg = make_config(scenario="random", n_obstacles=1)
    a, b = World(cfg, 3, noise_block=8), World(cfg, 2, noise_block=8)
    a.reset(seed=[10, 11, 12])
    b.reset(seed=[11, 12])
    rng = np.random.default_rng(2)
    for k in range(20):
        act = rng.uniform(-1.0, 1.0, (3, cfg.n_uavs, 3))
        active = None
        if k in (3, 12):
            a.reset(mask=np.array([True, False, False]))
            active = np.array([False, True, True])
        a.step(act, active=active)
        b.step(act[1:])
        for name in ("uav_pos", "est_pos", "obstacle_est_pos", "pred_center"):
            np.testing.assert_array_equal(getattr(a, name)[1:], getattr(b, name), err_msg=name)


def test_a_partial_reset_updates_the_plan_already_computed():
    """After a partial reset the reset rows of a plan read before it are the new episodes'.

    The world updates those rows only (the vector envs' autoresets); every ``plan_*``
    array equals the plan computed afresh, and what a caller kept before is unchanged.
    """
    a, _, _ = _pair()
    kept = a.plan_pos  # computed now, before the reset
    before = kept.copy()
    mask = np.zeros(a.n_envs, dtype=bool)
    mask[[2, 6, 7]] = True
    a.reset(mask=mask)
    got = (a.plan_center, a.plan_dir, a.plan_pos, a.plan_vel)
    a._refresh_plan()  # stale: the next read recomputes every row
    want = (a.plan_center, a.plan_dir, a.plan_pos, a.plan_vel)
    for g, w, name in zip(got, want, ("center", "dir", "pos", "vel"), strict=True):
        np.testing.assert_array_equal(g, w, err_msg=name, strict=True)
        assert not g.flags.writeable
    assert not np.array_equal(before[mask], got[2][mask])  # the new episodes' plans
    np.testing.assert_array_equal(kept, before)


def test_partial_resets_before_a_read_update_the_plan_in_order():
    """Two partial resets (overlapping rows) before the plan is read again, then a step:
    the rows are applied at the read, the later reset's last, and a step discards them."""
    a, _, _ = _pair()
    _ = a.plan_pos
    first = np.zeros(a.n_envs, dtype=bool)
    first[[1, 2, 6]] = True
    second = np.zeros(a.n_envs, dtype=bool)
    second[[2, 7]] = True
    a.reset(mask=first)
    a.reset(mask=second)
    got = (a.plan_center, a.plan_dir, a.plan_pos, a.plan_vel)
    a._refresh_plan()
    want = (a.plan_center, a.plan_dir, a.plan_pos, a.plan_vel)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w, strict=True)
    a.reset(mask=first)  # then a step before any read: the step's plan, not the reset's
    a.step(np.zeros((a.n_envs, a.n_uavs, 3)))
    stepped = a.plan_pos
    a._refresh_plan()
    np.testing.assert_array_equal(stepped, a.plan_pos, strict=True)


def test_a_reset_inside_the_step_equals_a_reset_then_a_held_step():
    """``World.step(reset=mask)`` (the vector envs' autoresets) gives, bit for bit, what
    ``reset(mask=mask)`` then ``step(active=~mask)`` gives: the reset rows start their new
    episodes and hold still, the others move on their own noise (fails when the reset rows'
    physics draws their noise, or when they are reset before the step and moved).
    """
    replay = {"scenario": "real_traffic", "obstacle": {"model": "replay"}}  # recorded tracks
    configs = (
        make_config(scenario="random", n_obstacles=2),
        make_config({**replay, "episode_duration": 30.0}),
    )
    for cfg in configs:
        a, b = World(cfg, 5, noise_block=8), World(cfg, 5, noise_block=8)
        a.reset(seed=3)
        b.reset(seed=3)
        rng = np.random.default_rng(4)
        for k in range(24):
            act = rng.uniform(-2.0, 2.0, (5, cfg.n_uavs, 3))
            mask = rng.uniform(size=5) < 0.3
            held = np.ones(5, dtype=bool)
            if k % 7 == 6:  # one also held still by the caller (not reset)
                held[np.flatnonzero(~mask)[:1]] = False
            a.reset(mask=mask)
            a.step(act, active=held & ~mask)
            b.step(act, active=held, reset=mask)
            _assert_same(a, b)


def test_a_step_names_a_mask_of_the_wrong_shape():
    cfg = make_config(scenario="random")
    w = World(cfg, 2)
    w.reset(seed=0)
    zero = np.zeros((2, cfg.n_uavs, 3))
    for name in ("active", "reset"):
        with pytest.raises(ValueError, match=rf"{name} must have shape \(2,\), got \(3,\)"):
            w.step(zero, **{name: np.ones(3, dtype=bool)})
