"""uasep-env: separation management for UAV formations among non-cooperative obstacles.

* :func:`parallel_env` -- the PettingZoo parallel environment (primary API); :func:`env`
  its AEC view. The package is a PettingZoo env module (``pettingzoo.test`` takes it).
* ``gymnasium.make("uasep/Formation-v3")`` / ``"uasep/PaperEncounter-v3"`` -- centralised
  Gymnasium views, registered on import (``gymnasium.make_vec`` gives the batched vector env).
* :class:`World` -- the batched numpy core, the one transition function.
* :mod:`uasep_env.policies` -- the paper's APF and its comparison methods.
"""

from __future__ import annotations

from uasep_env._deprecation import install_moved_modules

install_moved_modules()  # old module paths (uasep_env.world, ...) import, with a warning

from uasep_env.config import EnvConfig, make_config  # noqa: E402
from uasep_env.envs.parallel import UAVSeparationParallelEnv, env, parallel_env  # noqa: E402
from uasep_env.registration import register_envs  # noqa: E402
from uasep_env.sim.world import World  # noqa: E402

__version__ = "0.4.0"

__all__ = [
    "EnvConfig",
    "UAVSeparationParallelEnv",
    "World",
    "__version__",
    "env",
    "make_config",
    "parallel_env",
    "register_envs",
]

register_envs()
