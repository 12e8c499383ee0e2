"""Environment views of the batched core: PettingZoo, Gymnasium, vector and SB3."""

from uasep_env.envs.core import EnvCore, StepResult
from uasep_env.envs.gym_env import FormationEnv
from uasep_env.envs.parallel import UAVSeparationParallelEnv, parallel_env

__all__ = ["EnvCore", "FormationEnv", "StepResult", "UAVSeparationParallelEnv", "parallel_env"]
