"""A batch of episodes' draws: :func:`uasep_env.scenarios.batched.encounter_draws`.

A partial reset draws each ended episode's scenario from its own generator: a family by
its mix, the layout's uniforms, then per obstacle its kind, meeting time, target UAV and
encounter's uniforms; in Python, a dozen small calls an episode. Here the same draws are
made in the same order from the family's tables (:class:`~uasep_env.scenarios.batched.
DrawTables`), with numpy's own algorithms on the generator's own state (as
:mod:`uasep_env._kernels.noise` draws the noise): ``random()`` is PCG64's ``next_double``,
``uniform(a, b)`` is ``a + (b - a) * next_double`` (where numpy rounds it so,
``batched._FORMULA_IS_EXACT``) and ``integers(n)`` is numpy's bounded Lemire draw from
PCG64's ``next_uint32``, which keeps the other half of a 64-bit output in the state
(``has_uint32``, ``uinteger``) for the next one.

Where a generator is not PCG64 or numpy's state is not laid out as read here (checked once),
:func:`encounter_draws` declines (``NotImplemented``) and Python draws.
"""

from __future__ import annotations

import ctypes

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from uasep_env._kernels.common import _JIT, frozen
from uasep_env._kernels.noise import _NATIVE, _next_double, _pcg64_address, _pcg64_next

_I32 = ir.IntType(32)
#: Offsets in numpy's ``pcg64_state`` of ``has_uint32`` (an int) and ``uinteger`` (a
#: uint32), after the pointer to the 128-bit state.
_HAS_UINT32, _UINTEGER = 8, 12


# Python forms (what NUMBA_DISABLE_JIT runs, through ctypes) with compiled ones (@overload).
def _load_u32(address: int) -> int:
    """The 32-bit word at ``address``, unsigned."""
    return ctypes.c_uint32.from_address(int(address)).value


def _store_u32(address: int, value: int) -> None:
    """Write the 32-bit word ``value`` at ``address``."""
    ctypes.c_uint32.from_address(int(address)).value = int(value)


@intrinsic
def _load_u32_ir(typingctx, address):  # noqa: ANN001, ANN202
    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        word = builder.load(builder.inttoptr(args[0], _I32.as_pointer()), align=4)
        return builder.zext(word, ir.IntType(64))

    return types.uint64(types.intp), codegen


@intrinsic
def _store_u32_ir(typingctx, address, value):  # noqa: ANN001, ANN202
    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        ptr = builder.inttoptr(args[0], _I32.as_pointer())
        builder.store(builder.trunc(args[1], _I32), ptr, align=4)
        return context.get_dummy_value()

    return types.none(types.intp, types.uint64), codegen


@overload(_load_u32, jit_options={"cache": True})
def _load_u32_compiled(address):  # noqa: ANN001, ANN202
    return lambda address: _load_u32_ir(address)


@overload(_store_u32, jit_options={"cache": True})
def _store_u32_compiled(address, value):  # noqa: ANN001, ANN202
    return lambda address, value: _store_u32_ir(address, np.uint64(value))


@numba.njit(inline="always", **_JIT)
def _next_uint32(state, address):  # noqa: ANN001, ANN202
    """PCG64's ``next_uint32``: the half kept from the last 64-bit output, else a new one."""
    if _load_u32(state + _HAS_UINT32) != 0:
        _store_u32(state + _HAS_UINT32, 0)
        return _load_u32(state + _UINTEGER)
    x = _pcg64_next(address)
    _store_u32(state + _HAS_UINT32, 1)
    _store_u32(state + _UINTEGER, x >> np.uint64(32))
    return x & np.uint64(0xFFFFFFFF)


@numba.njit(inline="always", **_JIT)
def _integers(state, address, n):  # noqa: ANN001, ANN202
    """``int(rng.integers(n))`` for ``1 <= n < 2**32``: numpy's buffered Lemire draw."""
    rng = np.uint64(n - 1)
    if rng == 0:  # one value: nothing drawn
        return 0
    excl = rng + np.uint64(1)
    m = _next_uint32(state, address) * excl
    leftover = m & np.uint64(0xFFFFFFFF)
    if leftover < excl:  # rare: reject the low values that would bias the draw
        threshold = (np.uint64(0xFFFFFFFF) - rng) % excl
        while True:
            if leftover >= threshold:
                break
            m = _next_uint32(state, address) * excl
            leftover = m & np.uint64(0xFFFFFFFF)
    return int(m >> np.uint64(32))


@numba.njit(inline="always", **_JIT)
def _pick(state, address, cum):  # noqa: ANN001, ANN202
    """``Mix.draw``: the entry of a cumulative-weight table a draw of ``integers`` falls in."""
    k = _integers(state, address, cum[cum.shape[0] - 1])
    i = 0
    while cum[i] <= k:
        i += 1
    return i


@numba.njit(**_JIT)
def _draw_rows(  # noqa: ANN202
    states, member, n_uavs, cruise_speed, lay_lo, lay_span, meet_lo, meet_span,  # noqa: ANN001
    timeline, member_cum, first, traffic_cum, traffic_kind, low, span, count,  # noqa: ANN001
    flags, heading_offset, members, layout, obstacles, drawn,  # noqa: ANN001
):  # fmt: skip
    """Each episode's draws, in :func:`~uasep_env.scenarios.batched.draw_encounters`' order."""
    n_lay = layout.shape[1]
    m = obstacles.shape[1]
    for b in range(states.shape[0]):
        state = states[b]
        address = _pcg64_address(state)
        k = member if member >= 0 else _pick(state, address, member_cum)
        members[b] = k
        aimed = first[k]
        # The layout's uniforms, and the first obstacle's meeting time with them.
        n_draw = n_lay + 1 if (m > 0 and aimed >= 0) else n_lay
        for i in range(n_draw):
            drawn[i] = lay_lo[i] + lay_span[i] * _next_double(address)
        for i in range(n_lay):
            layout[b, i] = drawn[i]
        for j in range(m):
            row = obstacles[b, j]
            if j == 0 and aimed >= 0:
                e = aimed
                meet = drawn[n_lay]
            else:
                e = traffic_kind[_pick(state, address, traffic_cum)]
                meet = meet_lo + meet_span * _next_double(address)
            row[0] = meet * timeline
            row[1] = float(_integers(state, address, n_uavs))
            for i in range(count[e]):
                drawn[i] = low[e, i] + span[e, i] * _next_double(address)
            speed = drawn[2]
            if flags[e, 0]:  # above the cruise speed
                speed = cruise_speed + speed
            i = 3
            if flags[e, 1]:  # from either side
                side = 1.0 if drawn[i] < 0.5 else -1.0
                turn = side * drawn[i + 1]
                i += 2
            else:
                turn = drawn[i]
                i += 1
            alt = drawn[i]
            i += 1
            climb = np.nan
            if flags[e, 2]:  # climbs or descends at vz_max
                climb = (1.0 if drawn[i] < 0.5 else -1.0) * drawn[1]
                i += 1
            row[2] = drawn[0]
            row[3] = drawn[1]
            row[4] = speed
            row[5] = heading_offset[e]
            row[6] = turn
            row[7] = alt
            row[8] = climb
            row[9] = 1.0 if flags[e, 2] else 0.0
            row[10] = drawn[i]


def _buffer_layout_ok() -> bool:
    """Whether numpy's PCG64 keeps its spare 32 bits where :func:`_next_uint32` reads them."""
    bit_generator = np.random.PCG64(20261204)
    np.random.Generator(bit_generator).integers(5)  # keeps the other half
    state = bit_generator.state
    address = bit_generator.ctypes.state_address
    return (_load_u32(address + _HAS_UINT32), _load_u32(address + _UINTEGER)) == (
        state["has_uint32"],
        state["uinteger"],
    )


# The draws need the state's layout, not the ziggurat's tables (the noise kernel's too).
_BUFFER_OK = _NATIVE and _buffer_layout_ok()


def encounter_draws(
    rngs: list[np.random.Generator],
    config: object,
    tables: tuple,
    member: int,
    *,
    exact: bool,
    layout_bounds: object,
    meet_range: tuple[float, float],
    timeline: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compiled :func:`uasep_env.scenarios.batched.encounter_draws` (may decline).

    ``exact``: numpy's uniform is ``low + span * next_double`` unfused;
    ``layout_bounds``: ``(n_uavs, with_meet) -> (low, high, span)`` of the layout's draws;
    ``meet_range``: the meeting time's range (a fraction of ``timeline``, s).
    """
    n, m = int(config.n_uavs), int(config.n_obstacles)  # type: ignore[attr-defined]
    pcg64 = all([type(g.bit_generator) is np.random.PCG64 for g in rngs])
    if not (bool(exact) & _BUFFER_OK & pcg64):
        return NotImplemented
    # The layout's bounds with the meeting time's last (drawn where slot 0 is aimed).
    lay_lo, _, lay_span = layout_bounds(n, True)  # type: ignore[operator]
    n_lay = len(lay_lo) - 1
    b = len(rngs)
    members = np.empty(b, dtype=np.int64)
    layout, obstacles = np.empty((b, n_lay)), np.empty((b, m, 11))
    states = np.array([g.bit_generator.ctypes.state_address for g in rngs], dtype=np.intp)
    meet_span = float(meet_range[1]) - float(meet_range[0])  # numpy's uniform: high - low
    _draw_rows(states, int(member), n, float(config.cruise_speed),  # type: ignore[attr-defined]
               frozen(lay_lo), frozen(lay_span), float(meet_range[0]), float(meet_span),
               float(timeline), *(frozen(a) for a in tables[:9]),
               members, layout, obstacles,
               np.empty(max(n_lay + 1, tables.low.shape[1])))  # fmt: skip
    return members, layout, obstacles
