"""BenchMARL tasks on the batched TorchRL env (the ``marl`` extra).

The environment ``marine_formation`` of BenchMARL: every task is one
scenario of this project with its overrides, built as a
``MarineFormationTorchEnv`` of
``num_envs`` formations (no PettingZoo wrapper, no Python loop over
formations). The agent group is ``vessel``; ``state`` (every vessel's state
and the time) feeds MAPPO's and MASAC's centralized critics; the reward terms,
collision and out-of-bounds flags, the commanded speed and the message
counters are the group's ``info`` entries, which BenchMARL logs; evaluation renders formation 0.

=========================  ============================================================
task                       scenario
=========================  ============================================================
``paper_speed``            the paper's scenario, speed commands (the guidance law steers)
``paper_guidance``         the paper's scenario, speed and heading commands
``paper_force``            the paper's scenario, surge force and yaw moment
``acoustic_speed``         the paper's team over the lossy, delayed acoustic channel
``ring6_speed``            six vessels on a directed ring, speed commands
``survey_speed``           the paper's team on a lawnmower survey (docs/paths.md), speed commands
``paper_speed_budget``     ``paper_budget``: a bandwidth budget; each vessel also decides when to broadcast
``acoustic_speed_budget``  ``acoustic_budget``: the acoustic channel with a budget; each vessel decides too
=========================  ============================================================

Install (BenchMARL 1.5 needs TorchRL 0.10–0.11, so this extra cannot share a
virtual environment with the ``torchrl`` extra, which takes TorchRL 0.14)::

    pip install -c constraints-ecosystem.txt -e ".[marl]"

From BenchMARL's own experiment API::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    from marine_formation_env.benchmarl import MarineFormationTask

    experiment = Experiment(
        task=MarineFormationTask.PAPER_SPEED.get_from_yaml(),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=ExperimentConfig.get_from_yaml(),
    )
    experiment.run()

From BenchMARL's own command line (the project ships a Hydra plugin that puts
these task configs on Hydra's search path and the tasks in BenchMARL's
registry)::

    python -m benchmarl.run algorithm=mappo task=marine_formation/paper_speed experiment.loggers=[csv]
    python -m benchmarl.run algorithm=masac task=marine_formation/acoustic_speed \\
        task.overrides.channel.loss=0.3 experiment.loggers=[csv]

A task config holds ``scenario`` (a name of
``SCENARIOS``) and ``overrides`` (any
``parallel_env`` keyword); an unknown key or a bad value is refused by name
when the env is built. BenchMARL's default loggers include wandb, which
needs an account: ``experiment.loggers=[csv]`` (or ``[tensorboard]``) keeps
everything on disk, evaluation videos included.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

try:
    from benchmarl.environments import Task, TaskClass, task_config_registry
    from benchmarl.environments.common import _type_check_task_config
    from benchmarl.utils import _read_yaml_config
    from torchrl.data import Composite
    from torchrl.envs import EnvBase
except ImportError as error:  # pragma: no cover - the message is the point
    raise ImportError(
        "marine_formation_env.benchmarl needs BenchMARL: pip install -c constraints-ecosystem.txt -e '.[marl]'"
    ) from error

from marine_formation_env.errors import ConfigError
from marine_formation_env.scenarios import SCENARIOS, make_config
from marine_formation_env.torchrl import GROUP, MarineFormationTorchEnv

__all__ = ["CONFIG_DIR", "ENV_NAME", "MarineFormationClass", "MarineFormationTask", "register"]

#: The environment's name in BenchMARL (``task=marine_formation/<task>``).
ENV_NAME = "marine_formation"

#: The Hydra config folder of the tasks (``task/marine_formation/<task>.yaml``).
CONFIG_DIR = Path(__file__).resolve().parent / "benchmarl_conf"


def _task_settings(name: str, config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """``(scenario, overrides)`` of a task config, checked (an unknown key or scenario is named)."""
    unknown = sorted(set(config) - {"scenario", "overrides"})
    if unknown:
        raise ConfigError(f"task {name!r}: unknown key(s) {unknown}; a task config holds 'scenario' and 'overrides'")
    scenario = config.get("scenario", "paper")
    if scenario not in SCENARIOS:
        raise ConfigError(f"task {name!r}: unknown scenario {scenario!r}; known: {sorted(SCENARIOS)}")
    overrides = config.get("overrides") or {}
    if not isinstance(overrides, dict):
        raise ConfigError(f"task {name!r}: overrides must be a mapping, got {overrides!r}")
    overrides = copy.deepcopy(dict(overrides))
    make_config(scenario, **overrides)  # a bad override fails here, by name, before BenchMARL builds anything
    return scenario, overrides


class MarineFormationClass(TaskClass):
    """How BenchMARL builds a ``marine_formation`` task: the batched TorchRL env of its scenario."""

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        if not continuous_actions:
            raise ConfigError(
                f"task {self.name.lower()!r} has continuous actions only; "
                "use a continuous algorithm or experiment.prefer_continuous_actions=true"
            )
        scenario, overrides = _task_settings(self.name.lower(), self.config)
        return lambda: MarineFormationTorchEnv(
            num_envs=num_envs, scenario=scenario, device=device, seed=seed, render_mode="rgb_array", **overrides
        )

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return True

    def max_steps(self, env: EnvBase) -> int:
        return int(env.max_steps)

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return dict(env.group_map)

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        del spec[(GROUP, "info")]
        del spec["state"]
        return spec

    def info_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        del spec[(GROUP, "observation")]
        del spec["state"]
        return spec

    def state_spec(self, env: EnvBase) -> Composite:
        return Composite({"state": env.full_observation_spec_unbatched["state"].clone()})

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> None:
        return None

    @staticmethod
    def env_name() -> str:
        return ENV_NAME


class MarineFormationTask(Task):
    """The ``marine_formation`` tasks (configs in ``CONFIG_DIR``; see the module docstring)."""

    PAPER_SPEED = None
    PAPER_GUIDANCE = None
    PAPER_FORCE = None
    ACOUSTIC_SPEED = None
    RING6_SPEED = None
    SURVEY_SPEED = None
    PAPER_SPEED_BUDGET = None
    ACOUSTIC_SPEED_BUDGET = None

    @staticmethod
    def associated_class() -> type[TaskClass]:
        return MarineFormationClass

    def get_from_yaml(self, path: str | None = None) -> TaskClass:
        """The task with its config from this package's YAML (BenchMARL's looks in its own folder)."""
        if path is None:
            path = str(CONFIG_DIR / "task" / ENV_NAME / f"{self.name.lower()}.yaml")
        config = _type_check_task_config(self.env_name(), self.name.lower(), _read_yaml_config(path), False)
        return self.get_task(config=config)


def register() -> None:
    """Put the tasks in BenchMARL's registry (``task=marine_formation/<task>``); repeated calls do nothing."""
    for task in MarineFormationTask.__members__.values():
        task_config_registry.setdefault(f"{ENV_NAME}/{task.name.lower()}", task)


register()
