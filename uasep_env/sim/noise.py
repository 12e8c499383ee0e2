"""Per-environment random streams, their noise drawn in blocks (on threads for large batches).

Each environment of a :class:`~uasep_env.sim.world.World` owns a
:class:`numpy.random.Generator`. :class:`NoiseStreams` draws from it ``noise_block``
physics steps of noise at once (Gaussian noise, already scaled, and uniforms), per
environment, so that environment ``i`` of a batch reads exactly the numbers a single
environment with the same seed reads, bit for bit, whatever the batch and whichever
environments take part in a step. The refills (:func:`refill_noise`; compiled, numpy's
numbers drawn about three times sooner, :mod:`uasep_env._kernels.noise`) are split over a
thread pool for large batches (:func:`_run_chunked`), each generator used by one task only.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from uasep_env._numba import compiled_twin
from uasep_env.runtime.cores import process_share

__all__ = ["REFILL_CHUNK", "NoiseStreams", "refill_noise"]

#: Environments refilled per task when noise is drawn on several threads (below twice
#: this, one thread does it all: a task costs more than it saves), and per chunk moved
#: into the step-major buffers at once (:meth:`NoiseStreams._refill`).
REFILL_CHUNK = 256
_pool: list[ThreadPoolExecutor] = []
# A forked child has the pool object but none of its threads: it makes its own.
os.register_at_fork(after_in_child=_pool.clear)


def _run_chunked(fn: Callable[[np.ndarray], None], envs: np.ndarray) -> None:
    """``fn(envs)``, split over the cores when ``envs`` is long.

    Drawing noise is a large item of a large batch's step, and both numpy's generators and
    the compiled refill release the GIL while they draw. Each environment's generator is
    used by one task only, in order, so the numbers are the same as one thread's, bit for
    bit.
    """
    share = process_share()  # never more threads than this process's share of the cores
    workers = min(share, len(envs) // REFILL_CHUNK)
    if workers < 2:
        fn(envs)
        return
    if not _pool:
        _pool.append(ThreadPoolExecutor(share, thread_name_prefix="uasep-noise"))
    for future in [_pool[0].submit(fn, part) for part in np.array_split(envs, workers)]:
        future.result()


class NoiseStreams:
    """The random streams of ``n_envs`` environments and their buffered noise.

    Args:
        n_envs: Number of environments ``E``.
        noise_block: Physics steps of noise drawn at once per environment.
        normal_std: ``(K,)`` standard deviation of each Gaussian column; the buffers hold
            the noise itself, scaled once per refill rather than once per use.
        n_uniform: Uniforms per environment and physics step.

    Attributes:
        rngs: Each environment's generator (fresh entropy until :meth:`reseed`).
        buf_pos: ``(E,)`` each environment's next row in its noise block (``noise_block``:
            the block is used up, the next draw refills it).
    """

    def __init__(
        self, n_envs: int, noise_block: int, normal_std: np.ndarray, n_uniform: int
    ) -> None:
        self.n_envs = n_envs
        self.noise_block = noise_block
        self._normal_std = normal_std
        self._n_normal = len(normal_std)
        self._n_unif = n_uniform
        self.rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n_envs)]
        # Step-major: one physics step's noise for the whole batch is one contiguous slab.
        self._normal_buf = np.zeros((noise_block, n_envs, self._n_normal))
        self._unif_buf = np.zeros((noise_block, n_envs, self._n_unif))
        self.buf_pos = np.full(n_envs, noise_block, dtype=np.int64)
        self._sync_lockstep()

    def reseed(self, env: int, seed: int) -> None:
        """Restart environment ``env``'s stream from ``seed``, dropping noise already drawn."""
        self.rngs[env] = np.random.default_rng(int(seed))
        self.buf_pos[env] = self.noise_block  # drop noise drawn from the old stream
        self._lockstep = False  # until the next masked draw checks again

    def state_arrays(self) -> dict[str, np.ndarray]:
        """The live arrays of the streams' state: the buffered noise and each position in it.

        With the generators' states (:func:`uasep_env.sim.snapshot.generator_states`), what a
        world's :meth:`~uasep_env.sim.world.World.state_dict` keeps of its noise.
        """
        return {"normal_buf": self._normal_buf, "unif_buf": self._unif_buf,
                "buf_pos": self.buf_pos}  # fmt: skip

    def set_generators(self, rngs: list[np.random.Generator]) -> None:
        """Replace every environment's generator (a restored state; buffers restored apart)."""
        if len(rngs) != self.n_envs:
            raise ValueError(f"{len(rngs)} generators for {self.n_envs} environments")
        self.rngs = list(rngs)
        self._sync_lockstep()

    def draw(self, active: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """This physics step's Gaussian noise (scaled by ``normal_std``) and uniforms.

        Environments outside ``active`` consume nothing; their rows hold noise of some
        other step or environment, to be discarded.

        Returns:
            ``(normals, uniforms)``, ``(E, K)`` and ``(E, n_uniform)``; possibly views of
            the buffers, valid until the next draw.
        """
        if active is None and self._lockstep:
            # Every environment at the same place in its block (the usual case): a view,
            # and no array checks (they show at small batches).
            at = self._lock_pos
            if at >= self.noise_block:
                _run_chunked(self._refill, np.arange(self.n_envs))
                self.buf_pos[:] = at = 0
            self._lock_pos = at + 1
            self.buf_pos += 1
            return self._normal_buf[at], self._unif_buf[at]
        due = self.buf_pos >= self.noise_block
        if active is not None:
            due &= active
        refill = np.flatnonzero(due)
        if len(refill):
            _run_chunked(self._refill, refill)
            self.buf_pos[refill] = 0
        at = np.minimum(self.buf_pos, self.noise_block - 1)
        live = at if active is None else at[active]
        if not len(live) or (live == live[0]).all():
            # Every environment that draws at the same place (the usual case after the
            # vector envs' autoresets, which leave the reset ones a row ahead): a view. The
            # others' rows hold some other step's noise, which they discard.
            row = live[0] if len(live) else at[0]
            normals = self._normal_buf[row]
            unifs = self._unif_buf[row]
        else:
            rows = np.arange(self.n_envs)
            normals = self._normal_buf[at, rows]
            unifs = self._unif_buf[at, rows]
        if active is None:
            self.buf_pos += 1
        else:
            self.buf_pos += active
        self._sync_lockstep()
        return normals, unifs

    def draw_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The next physics step's noise of the environments ``rows`` only.

        The same numbers as ``draw(active)`` with ``active`` true at ``rows`` gives in those
        rows, without gathering the whole batch (a partial reset's first measurements).

        Args:
            rows: Index array of the environments that draw, ascending.

        Returns:
            ``(normals, uniforms)``, ``(len(rows), K)`` and ``(len(rows), n_uniform)``.
        """
        refill = rows[self.buf_pos[rows] >= self.noise_block]
        if len(refill):
            _run_chunked(self._refill, refill)
            self.buf_pos[refill] = 0
        at = self.buf_pos[rows]
        normals = self._normal_buf[at, rows]
        unifs = self._unif_buf[at, rows]
        self.buf_pos[rows] = at + 1
        self._lockstep = False  # until the next masked draw checks again
        return normals, unifs

    def _sync_lockstep(self) -> None:
        """Note whether every environment is at the same place in its noise block."""
        self._lockstep = bool((self.buf_pos == self.buf_pos[0]).all())
        self._lock_pos = int(self.buf_pos[0])

    def _refill(self, envs: np.ndarray) -> None:
        """Draw the next ``noise_block`` physics steps of noise for each of ``envs``."""
        refill_noise(self.rngs, envs, self._normal_std, self._normal_buf, self._unif_buf)


@compiled_twin("refill_noise")
def refill_noise(
    rngs: list[np.random.Generator],
    envs: np.ndarray,
    normal_std: np.ndarray,
    normal_buf: np.ndarray,
    unif_buf: np.ndarray,
) -> None:
    """Draw the next block of noise of each of ``envs`` into the step-major buffers.

    Each generator fills its own contiguous block (its Gaussians, then its uniforms: the
    same numbers, in the same order, as drawing it into the buffer directly), then a chunk
    of environments is scaled and moved into the step-major buffers at once, rather than
    each environment's rows written straight into them (``block`` pages apart): the refill
    of 4096 environments in 0.85-0.95 of the time, and a little more of it off the GIL.
    The compiled twin draws numpy's numbers itself, about three times sooner
    (:mod:`uasep_env._kernels.noise`).

    Args:
        rngs: Every environment's generator; those of ``envs`` advance by one block.
        envs: Index array of the environments to refill.
        normal_std: ``(K,)`` each Gaussian column's standard deviation.
        normal_buf: ``(block, E, K)`` the scaled Gaussians, written at the columns ``envs``.
        unif_buf: ``(block, E, U)`` the uniforms, likewise.
    """
    block, n_normal, n_unif = normal_buf.shape[0], normal_buf.shape[2], unif_buf.shape[2]
    for start in range(0, len(envs), REFILL_CHUNK):
        part = envs[start : start + REFILL_CHUNK]
        normals = np.empty((len(part), block, n_normal))
        unifs = np.empty((len(part), block, n_unif))
        for k, i in enumerate(part.tolist()):
            rng = rngs[i]
            rng.standard_normal(out=normals[k])
            rng.random(out=unifs[k])
        normals *= normal_std
        normal_buf[:, part] = normals.transpose(1, 0, 2)
        unif_buf[:, part] = unifs.transpose(1, 0, 2)
