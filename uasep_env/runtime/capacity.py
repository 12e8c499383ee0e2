"""How much memory a batch of environments needs, checked before anything is allocated.

A count from the user (``num_envs`` of the vector env and ``gymnasium.make_vec``, ``n_envs``
of the SB3 adapter and :class:`~uasep_env.envs.core.EnvCore`, an evaluation's batch size and
episode count) is refused with a :class:`ValueError` naming it and the estimate when the
estimate exceeds the memory available, instead of a ``MemoryError`` after minutes, or a hang.

The estimate is per environment, from the config: the physics noise drawn in blocks (64
steps of every standard normal; the largest part), the world state and its pairwise
distances, and the observation buffers; doubled for a step's temporaries, plus 16 KiB.
Against the most memory held at once while a batch is made, reset, stepped and reset again
(``tracemalloc``'s peak, per environment, between 400 and 2,000 environments;
``tests/test_input_limits.py``): 52 KB measured, 64 KB estimated for the paper's config (3
UAVs, 1 obstacle); 466 KB and 720 KB with 32 UAVs and 8 obstacles.
"""

from __future__ import annotations

import contextlib
import itertools
import os
from pathlib import Path
from typing import TYPE_CHECKING

from uasep_env.config.checks import check_positive_int

try:
    import resource
except ImportError:  # pragma: no cover - not POSIX
    resource = None  # type: ignore[assignment]

if TYPE_CHECKING:
    from uasep_env.config import EnvConfig

__all__ = [
    "EPISODE_RESULT_BYTES",
    "available_memory",
    "check_count",
    "env_bytes",
    "memory_problem",
    "network_bytes",
    "record_bytes",
]

#: Memory one evaluated episode's results take (metrics, timelines as Python objects; a
#: pickled one is about 2.3 KB); a generous figure for checking ``--episodes``.
EPISODE_RESULT_BYTES = 32 * 1024
_NOISE_BLOCK = 64  # physics steps of noise drawn at once (World's default)
_PER_ENV_BYTES = 16 * 1024  # whatever the config does not scale: plans, episode draws
#: Training memory per network parameter: float32 weight, gradient and Adam's two moments.
_PARAM_BYTES = 16


def env_bytes(config: EnvConfig) -> int:
    """Estimated peak memory of one environment of a batch (bytes), from ``config``."""
    from uasep_env.interface.observation_layout import ObservationLayout
    from uasep_env.sim.obstacles import N_UNIFORMS

    n, m = config.n_uavs, config.n_obstacles
    width = ObservationLayout.from_config(config).dim
    noise = 8 * _NOISE_BLOCK * (9 * n + 6 * m + N_UNIFORMS * m)
    state = 8 * (60 * n + 60 * m + 4 * n * n + 4 * n * m)
    obs = 4 * 4 * n * width  # float32: the buffer, a copy, the residual and the returned one
    return 2 * (noise + state + obs) + _PER_ENV_BYTES


def record_bytes(config: EnvConfig) -> int:
    """Memory of one environment's recorded episode in an evaluation (bytes)."""
    n, m = config.n_uavs, config.n_obstacles
    # float64: time, 4 (N, 3) UAV arrays, obstacles, regions, predictions, cost (N); bool flags
    per_step = 8 * (1 + 4 * 3 * n + 3 * m + n * m + 3 * m + m + n) + m
    return (config.max_steps + 1) * per_step


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_available() -> int | None:
    root = Path("/sys/fs/cgroup")
    try:
        limit = (root / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int((root / "memory.current").read_text().strip())
    except (OSError, ValueError):
        return None


def available_memory() -> int:
    """Memory this process may still use (bytes).

    The least of what the system (``/proc/meminfo``'s ``MemAvailable``, else the physical
    memory), its cgroup and its address-space limit leave.
    """
    known = [_meminfo_available(), _cgroup_available()]
    if resource is not None:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            known.append(soft)
    if known[0] is None:
        with contextlib.suppress(ValueError, OSError, AttributeError):  # not POSIX
            known.append(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    values = [v for v in known if v is not None]
    return max(0, min(values)) if values else 2**63


def _size(n: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("KB", 1e3)):
        if n >= scale:
            return f"{n / scale:,.3g} {unit}"
    return f"{n:.0f} B"


def check_count(
    name: str,
    count: object,
    config: EnvConfig,
    *,
    extra_bytes: int = 0,
    copies: int = 1,
) -> int:
    """``count`` as an int, if that many environments fit in the memory available.

    Args:
        name: The argument's name, for the message (``num_envs``, ``--batch-size``).
        count: The number of environments asked for.
        config: Their config.
        extra_bytes: More memory per environment (an evaluation's recorded episode).
        copies: Batches held at once (evaluation workers).

    Returns:
        ``count``.

    Raises:
        ValueError: ``count`` is not a positive integer, or its estimated memory exceeds
            :func:`available_memory` (both named).
    """
    count = check_positive_int(name, count)
    per = env_bytes(config) + extra_bytes
    need = count * per * copies
    if count > 64 and need > (free := available_memory()):
        held = f" x {copies} batches held at once" if copies > 1 else ""
        raise ValueError(
            f"{name}={count:,} needs about {_size(need)} of memory ({_size(per)} per "
            f"environment with {config.n_uavs} UAVs and {config.n_obstacles} obstacle(s){held}), "
            f"more than the {_size(free)} available; use fewer"
        )
    return count


def network_bytes(widths: list[int], n_in: int, n_out: int, batch: int) -> int:
    """The least memory training an MLP takes: ``n_in -> widths -> n_out``, ``batch`` rows.

    Its parameters with their gradients and Adam's moments, and one minibatch's hidden
    activations (forward, their gradients and the activation's output; float32). An
    actor-critic needs it twice.
    """
    sizes = [n_in, *widths, n_out]
    params = sum((a + 1) * b for a, b in itertools.pairwise(sizes))
    return params * _PARAM_BYTES + 3 * 4 * batch * sum(widths)


def memory_problem(need: int, what: str) -> str | None:
    """Why ``need`` bytes (for ``what``) cannot be had here, or None when they fit."""
    free = available_memory()
    if need <= free:
        return None
    return f"needs about {_size(need)} of memory ({what}), more than the {_size(free)} available"
