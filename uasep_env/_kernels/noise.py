"""The noise blocks: :func:`uasep_env.sim.noise.refill_noise`, numpy's own draws compiled.

Each environment's :class:`numpy.random.Generator` is a PCG64 bit generator. numpy draws
a Gaussian by its ziggurat (``random_standard_normal`` in numpy's ``distributions.c``)
and a uniform as ``(next_uint64 >> 11) / 2**53``, each number a call through the bit
generator's function pointer. Here the same PCG64 step (the 128-bit LCG and its XSL-RR
output) and the same ziggurat, with numpy's own tables (numba's copy of them), are
compiled inline and advance the generator's state in its own memory, read through the
address numpy publishes for it (``bit_generator.ctypes.state_address``). So every number
and the generator's state afterwards are numpy's, bit for bit, about three times sooner.

Where the generators' memory is not laid out as this code reads it (a numpy build without
a native 128-bit integer; checked once, when the kernels load, by :func:`_native_pcg64`),
where numba no longer ships numpy's tables where this module reads them, or where a
generator is not PCG64, :func:`refill_noise` declines (``NotImplemented``) and numpy draws.
"""

from __future__ import annotations

import ctypes
import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from uasep_env._kernels.common import _JIT, frozen

try:  # numba's copy of numpy's ziggurat tables (a private module: it may move)
    from numba.np.random._constants import (
        fi_double,
        ki_double,
        wi_double,
        ziggurat_nor_inv_r,
        ziggurat_nor_r,
    )

    _TABLES = True
except ImportError:  # pragma: no cover - depends on numba's version; then numpy draws
    ki_double = np.zeros(256, dtype=np.uint64)
    wi_double = fi_double = np.zeros(256)
    ziggurat_nor_r = ziggurat_nor_inv_r = 0.0
    _TABLES = False

#: PCG64's multiplier (numpy's ``PCG_DEFAULT_MULTIPLIER_128``).
_MULTIPLIER = (2549297995355413924 << 64) + 4865540595714422341
_MASK64 = (1 << 64) - 1
_MASK128 = (1 << 128) - 1
# The ziggurat's tables (numpy's, as numba ships them), frozen into the kernels.
_KI = frozen(np.array(ki_double, dtype=np.uint64))
_WI = frozen(np.array(wi_double, dtype=np.float64))
_FI = frozen(np.array(fi_double, dtype=np.float64))
_R = float(ziggurat_nor_r)
_INV_R = float(ziggurat_nor_inv_r)
#: Environments drawn into the scratch block before they are moved into the step-major
#: buffers at once (the buffers' rows of one environment are pages apart).
_CHUNK = 64
_I64 = ir.IntType(64)
_I128 = ir.IntType(128)


# The two memory accesses are Python functions (what NUMBA_DISABLE_JIT runs, through
# ctypes) with compiled forms (@overload, LLVM's 128-bit arithmetic): numba has no 128-bit
# integer of its own.
def _pcg64_address(state_address: int) -> int:
    """The address of a PCG64's ``pcg64_random_t`` (the first field of numpy's state)."""
    return ctypes.c_void_p.from_address(int(state_address)).value


def _pcg64_next(address: int) -> np.uint64:
    """PCG64's next 64-bit output, advancing the state at ``address`` (numpy's step)."""
    words = (ctypes.c_uint64 * 4).from_address(int(address))
    state = (words[0] | words[1] << 64) * _MULTIPLIER + (words[2] | words[3] << 64)
    state &= _MASK128
    words[0], words[1] = state & _MASK64, state >> 64
    x, rot = (state >> 64) ^ (state & _MASK64), state >> 122
    return np.uint64((x >> rot | x << (-rot & 63)) & _MASK64)


@intrinsic
def _load_word(typingctx, address):  # noqa: ANN001, ANN202
    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        return builder.load(builder.inttoptr(args[0], _I64.as_pointer()), align=8)

    return types.intp(types.intp), codegen


@intrinsic
def _pcg64_step(typingctx, address):  # noqa: ANN001, ANN202
    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        ptr = builder.inttoptr(args[0], _I128.as_pointer())
        inc = builder.load(builder.gep(ptr, [ir.Constant(ir.IntType(32), 1)]), align=8)
        state = builder.load(ptr, align=8)
        state = builder.add(builder.mul(state, ir.Constant(_I128, _MULTIPLIER)), inc)
        builder.store(state, ptr, align=8)
        high = builder.trunc(builder.lshr(state, ir.Constant(_I128, 64)), _I64)
        x = builder.xor(high, builder.trunc(state, _I64))
        rot = builder.trunc(builder.lshr(state, ir.Constant(_I128, 122)), _I64)
        left = builder.and_(builder.neg(rot), ir.Constant(_I64, 63))
        return builder.or_(builder.lshr(x, rot), builder.shl(x, left))

    return types.uint64(types.intp), codegen


@overload(_pcg64_address, jit_options={"cache": True})
def _pcg64_address_compiled(state_address):  # noqa: ANN001, ANN202
    return lambda state_address: _load_word(state_address)


@overload(_pcg64_next, jit_options={"cache": True})
def _pcg64_next_compiled(address):  # noqa: ANN001, ANN202
    return lambda address: _pcg64_step(address)


@numba.njit(inline="always", **_JIT)
def _next_double(address):  # noqa: ANN001, ANN202
    """PCG64's ``next_double`` as numpy makes it: the top 53 bits over ``2**53``."""
    return (_pcg64_next(address) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(inline="always", **_JIT)
def _standard_normal(address):  # noqa: ANN001, ANN202
    """A Gaussian as numpy's ``random_standard_normal`` draws it (ziggurat, tail, wedges)."""
    while True:
        r = _pcg64_next(address)
        idx = r & np.uint64(0xFF)
        r >>= np.uint64(8)
        rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = rabs * _WI[idx]
        if r & np.uint64(1):
            x = -x
        if rabs < _KI[idx]:
            return x  # most draws
        if idx == 0:  # the tail beyond the base strip
            while True:
                xx = -_INV_R * math.log1p(-_next_double(address))
                yy = -math.log1p(-_next_double(address))
                if yy + yy > xx * xx:
                    tail = _R + xx
                    return -tail if (rabs >> np.uint64(8)) & np.uint64(1) else tail
        else:  # a wedge: under the density or drawn again
            low, high = _FI[idx], _FI[idx - np.uint64(1)]
            if (high - low) * _next_double(address) + low < math.exp(-0.5 * x * x):
                return x


@numba.njit(**_JIT)
def _refill_rows(states, envs, normal_std, normal_buf, unif_buf, normals, unifs):  # noqa: ANN001, ANN202
    """Each of ``envs``' next block from the generator state at ``states[k]``, in numpy's order.

    Per environment, its normals (``block x K``, row by row), then its uniforms, into the
    scratch ``normals``/``unifs`` (``_CHUNK`` environments at a time); then the chunk's
    normals times their column's ``normal_std`` into the step-major buffers.
    """
    block, n_normal, n_unif = normal_buf.shape[0], normal_buf.shape[2], unif_buf.shape[2]
    chunk = normals.shape[0]
    for c0 in range(0, envs.shape[0], chunk):
        c1 = min(c0 + chunk, envs.shape[0])
        for k in range(c0, c1):
            address = _pcg64_address(states[k])
            for s in range(block):
                for j in range(n_normal):
                    normals[k - c0, s, j] = _standard_normal(address)
            for s in range(block):
                for j in range(n_unif):
                    unifs[k - c0, s, j] = _next_double(address)
        for s in range(block):
            for k in range(c0, c1):
                e = envs[k]
                for j in range(n_normal):
                    normal_buf[s, e, j] = normals[k - c0, s, j] * normal_std[j]
                for j in range(n_unif):
                    unif_buf[s, e, j] = unifs[k - c0, s, j]


def _native_pcg64() -> bool:
    """Whether numpy's PCG64 state is laid out as this module reads it.

    numpy's state struct starts with a pointer to ``{state, inc}``, two 128-bit integers,
    each stored low word first where the compiler has a native 128-bit integer (GCC, Clang;
    MSVC builds store them high word first). Read, never written, on a generator made here.
    """
    bit_generator = np.random.PCG64(0x0123456789ABCDEF_FEDCBA9876543210)
    want = bit_generator.state["state"]
    words = (ctypes.c_uint64 * 4).from_address(_pcg64_address(bit_generator.ctypes.state_address))
    return {"state": words[0] | words[1] << 64, "inc": words[2] | words[3] << 64} == want


#: Whether numpy's PCG64 state reads as this module reads it (checked once, when the
#: kernels load).
_NATIVE = _native_pcg64()
#: The bit generators the kernel draws from: PCG64 where its memory reads as expected and
#: numba has numpy's tables, else none (numpy draws, the reference).
_DRAWS_FROM = (np.random.PCG64,) if _TABLES and _NATIVE else ()


def refill_noise(
    rngs: list[np.random.Generator],
    envs: np.ndarray,
    normal_std: np.ndarray,
    normal_buf: np.ndarray,
    unif_buf: np.ndarray,
) -> None:
    """Compiled :func:`uasep_env.sim.noise.refill_noise` (declines with ``NotImplemented``).

    Args:
        rngs: Every environment's generator.
        envs: The environments to refill, as an index array.
        normal_std: ``(K,)`` each Gaussian column's standard deviation.
        normal_buf: ``(block, E, K)`` float64, written at the columns ``envs``.
        unif_buf: ``(block, E, U)`` float64, likewise.

    Returns:
        None, or ``NotImplemented`` where a generator is not PCG64 or numpy's PCG64 state is
        not laid out as expected (then numpy draws, the reference).
    """
    gens = [rngs[i] for i in envs.tolist()]
    if any(type(g.bit_generator) not in _DRAWS_FROM for g in gens):
        return NotImplemented
    # The published address of each generator's state (made on first use, then kept).
    states = np.array([g.bit_generator.ctypes.state_address for g in gens], dtype=np.intp)
    block = normal_buf.shape[0]
    normals = np.empty((min(_CHUNK, len(gens)), block, normal_buf.shape[2]))
    unifs = np.empty((normals.shape[0], block, unif_buf.shape[2]))
    _refill_rows(states, frozen(envs), frozen(normal_std), normal_buf, unif_buf, normals, unifs)
    return None
