"""BenchMARL's MAPPO on a custom task wrapping ``uasep_env.parallel_env``.

BenchMARL 1.5.2 pins TorchRL 0.11.1 / TensorDict 0.11.0, while the ``clients`` extra (Ray
RLlib, the TorchRL tests) uses TorchRL 0.14.1, so BenchMARL lives in a venv of its own:
``make test-benchmarl`` (part of ``make ci``) installs ``torch==2.13.0``,
``benchmarl==1.5.2`` and this package there and runs this file with
``UASEP_REQUIRE_BENCHMARL=1``. Elsewhere the test skips unless BenchMARL imports.

The task is added the way BenchMARL's documentation extends it (a ``TaskClass`` that builds
a TorchRL env, and a ``Task`` enum naming it); MAPPO's critic reads the env's ``state()``.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import pytest

if os.environ.get("UASEP_REQUIRE_BENCHMARL") != "1":
    pytest.importorskip("benchmarl")

from benchmarl.algorithms import MappoConfig
from benchmarl.environments.common import Task, TaskClass
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig
from torchrl.envs import EnvBase, PettingZooWrapper

import uasep_env


class UasepTaskClass(TaskClass):
    """Builds the formation env (config: ``parallel_env`` keywords) as a TorchRL env."""

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: str
    ) -> Callable[[], EnvBase]:
        config = dict(self.config)
        return lambda: PettingZooWrapper(
            env=uasep_env.parallel_env(**config),
            return_state=True,
            categorical_actions=False,
            seed=seed,
            device=device,
        )

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return int(self.config["max_cycles"])

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return env.group_map

    def state_spec(self, env: EnvBase):
        from torchrl.data import Composite

        return Composite({"state": env.observation_spec["state"].clone()})

    def action_mask_spec(self, env: EnvBase):
        return None

    def observation_spec(self, env: EnvBase):
        spec = env.observation_spec.clone()
        for group in self.group_map(env):
            for key in list(spec[group].keys()):
                if key != "observation":
                    del spec[group][key]
        del spec["state"]
        return spec

    def info_spec(self, env: EnvBase):
        return None

    def action_spec(self, env: EnvBase):
        return env.full_action_spec

    @staticmethod
    def env_name() -> str:
        return "uasep"


class UasepTask(Task):
    """The formation tasks BenchMARL can run."""

    FORMATION = None

    @staticmethod
    def associated_class() -> type[TaskClass]:
        return UasepTaskClass


def test_benchmarl_mappo_trains_on_a_custom_uasep_task(tmp_path):
    task = UasepTask.FORMATION.get_task(config={"scenario": "random", "max_cycles": 20})
    experiment_config = ExperimentConfig.get_from_yaml()
    experiment_config.sampling_device = experiment_config.train_device = "cpu"
    experiment_config.max_n_frames = 240
    experiment_config.on_policy_collected_frames_per_batch = 120
    experiment_config.on_policy_n_envs_per_worker = 2
    experiment_config.on_policy_n_minibatch_iters = 1
    experiment_config.on_policy_minibatch_size = 60
    experiment_config.evaluation = False
    experiment_config.render = False
    experiment_config.loggers = []
    experiment_config.create_json = False
    experiment_config.save_folder = str(tmp_path)
    algorithm = MappoConfig.get_from_yaml()
    assert algorithm.share_param_critic  # one critic, on the global state
    experiment = Experiment(
        task=task,
        algorithm_config=algorithm,
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=experiment_config,
    )
    experiment.run()
    assert experiment.total_frames == 240
    assert experiment.n_iters_performed == 2
    # The critic reads the env's state(): the formation's global state, not one agent's view.
    env = task.get_env_fun(1, True, 0, "cpu")()
    assert env.observation_spec["state"].shape[-1] == uasep_env.parallel_env().state().shape[-1]
