"""Shared test helpers and fixtures.

Plain helpers (import them: ``from conftest import make_record``) where module-level test
helpers need them too; fixtures for what tests take as arguments.
"""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from uasep_env.metrics import EpisodeRecord

#: The repository root (the tests run scripts and read results files from it).
ROOT = Path(__file__).resolve().parents[1]

#: Seconds a test waits on a subprocess (or a worker) before calling it hung. A guard against
#: hangs only, never a speed check: a loaded machine runs the suite many times slower (a
#: 3-minute suite took an hour on a busy 2-core runner); speed lives in benchmarks/.
HANG_GUARD_S = 30 * 60

# Property tests import hypothesis's names from here (``from conftest import given, st``):
# hypothesis is the dev extra, and a plain ``pytest`` without it (an sdist, the floors) must
# still collect every file. Without it, ``@given`` skips the test it decorates and the
# strategies it was given are never built.
try:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays
except ModuleNotFoundError:

    class _StandIn:
        """A strategy expression's value without hypothesis: any attribute or call is itself."""

        def __getattr__(self, name: str) -> _StandIn:
            return self

        def __call__(self, *args: Any, **kwargs: Any) -> _StandIn:
            return self

    st = arrays = HealthCheck = _StandIn()

    def given(*args: Any, **kwargs: Any) -> pytest.MarkDecorator:
        """Skip the property test (it needs hypothesis)."""
        return pytest.mark.skip(reason="a property test: needs hypothesis (the dev extra)")

    def settings(*args: Any, **kwargs: Any) -> Any:
        """Leave the test as it is (``given`` skips it)."""
        return lambda test: test

else:
    # No per-example deadline anywhere (hypothesis's default is 200 ms): under load an
    # example takes many times longer, and a slow example is not a failure.
    settings.register_profile("uasep-default", deadline=None)
    settings.load_profile("uasep-default")


class _FullDisk:
    """A file whose writes fail with ENOSPC after ``room`` bytes (a disk filling up)."""

    def __init__(self, fh: Any, room: int) -> None:
        self._fh, self._room = fh, room

    def write(self, data: Any) -> int:
        if len(data) > self._room:
            self._fh.write(data[: self._room])
            self._room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._room -= len(data)
        return self._fh.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._fh, name)

    def __enter__(self) -> _FullDisk:
        return self

    def __exit__(self, *exc: object) -> None:
        self._fh.close()


def fill_disk(monkeypatch: pytest.MonkeyPatch, room: int = 0) -> None:
    """From now on, every file ``uasep_env.runtime.atomic`` opens runs out of space after ``room``
    bytes."""
    from uasep_env.runtime import atomic

    real = open
    monkeypatch.setattr(
        atomic, "_open", lambda path, mode="r", **kw: _FullDisk(real(path, mode, **kw), room)
    )


def same_bits(a: Any, b: Any) -> bool:
    """``a`` and ``b`` equal bit for bit (nested dicts, lists, torch tensors, numbers)."""
    if isinstance(a, dict):
        return (
            isinstance(b, dict) and a.keys() == b.keys() and all(same_bits(a[k], b[k]) for k in a)
        )
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same_bits(x, y) for x, y in zip(a, b, strict=True))
    if type(a).__module__.startswith("torch"):  # torch imported only where a tensor is
        import torch

        return isinstance(b, torch.Tensor) and torch.equal(a, b)
    return a == b


def run_in_repo(*args: str, timeout: float = HANG_GUARD_S) -> subprocess.CompletedProcess:
    """``python *args`` in the repository, headless (Agg), importing this checkout."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def run_python(code: str, timeout: float = HANG_GUARD_S) -> subprocess.CompletedProcess:
    """``python -c code`` (dedented) in the repository, headless."""
    return run_in_repo("-c", textwrap.dedent(code), timeout=timeout)


def make_record(
    pos: Any,
    dt: float,
    *,
    planned: Any = None,
    vel: Any = None,
    acc: Any = None,
    obstacle_pos: Any = None,
    active: Any = None,
    region: Any = None,
    t0: float = 0.0,
    collision_distance: float = 5.0,
    uav_separation: float = 10.0,
    obstacle_separation: float = 20.0,
    **kwargs: Any,
) -> EpisodeRecord:
    """An :class:`EpisodeRecord` from UAV positions ``(T, N, 3)``, the rest defaulted.

    Times start at ``t0`` in steps of ``dt``; the plan is the flown path, velocities and
    accelerations zero, no obstacle, the region distance the obstacle centre distance.
    """
    pos = np.asarray(pos, dtype=float)
    n_t = pos.shape[0]
    time = t0 + dt * np.arange(n_t)
    planned = pos.copy() if planned is None else planned
    vel = np.zeros_like(pos) if vel is None else vel
    acc = np.zeros_like(pos) if acc is None else acc
    if obstacle_pos is None:
        obstacle_pos = np.zeros((n_t, 0, 3))
    obstacle_pos = np.asarray(obstacle_pos, dtype=float)
    n_obs = obstacle_pos.shape[1]
    if active is None:
        active = np.ones((n_t, n_obs), dtype=bool)
    if region is None:
        region = np.linalg.norm(pos[:, :, None, :] - obstacle_pos[:, None, :, :], axis=-1)
    return EpisodeRecord(
        time=time,
        dt=dt,
        uav_pos=pos,
        uav_vel=vel,
        uav_acc=acc,
        planned_pos=planned,
        obstacle_pos=obstacle_pos,
        obstacle_active=active,
        region_distance=region,
        collision_distance=collision_distance,
        uav_separation=uav_separation,
        obstacle_separation=obstacle_separation,
        **kwargs,
    )


@pytest.fixture
def repo_root() -> Path:
    """The repository root."""
    return ROOT


def replace_npz_arrays(raw: bytes, **arrays: Any) -> bytes:
    """An ``.npz`` file's bytes ``raw`` with some of its arrays replaced (or added)."""
    with np.load(io.BytesIO(raw)) as z:
        data = {k: z[k] for k in z.files}
    data.update(arrays)
    buf = io.BytesIO()
    np.savez(buf, **data)
    return buf.getvalue()
