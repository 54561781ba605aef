"""marine_formation_env: formation control of underactuated marine vessels under communication constraints.

A research environment built on "Formation Control of Underactuated Marine
Vehicles with Communication Constraints": batched 3-DOF vessel dynamics, a
directed communication graph that masks what each vessel observes (over ideal
links, as in the paper, or a lossy, delayed, scheduled channel), ocean
currents, and a PettingZoo ParallelEnv whose agents act at the force, guidance
or speed level.

Quick start::

    import marine_formation_env

    env = marine_formation_env.parallel_env(scenario="paper", action_level="speed")
    observations, infos = env.reset(seed=0)
"""

from marine_formation_env.channel import ChannelConfig, GilbertElliott
from marine_formation_env.core import FormationCore
from marine_formation_env.disturbances import Current, SensorNoise
from marine_formation_env.env import MarineFormationParallelEnv, parallel_env
from marine_formation_env.graph import GRAPH_PRESETS, CommGraph, GraphError, make_graph
from marine_formation_env.params import SUPPLY, VESSELS, Gains, ParameterError, VesselParams
from marine_formation_env.scenarios import (
    ACTION_LEVELS,
    SCENARIOS,
    ConfigError,
    InitNoise,
    RewardConfig,
    ScenarioConfig,
    SpeedProfile,
    make_config,
)

__version__ = "0.3.0.dev0"

ENV_ID = "MarineFormation-v1"


def _register() -> None:
    """Register the gymnasium views (and the ParallelEnv with PettingZoo's registry, if it has one)."""
    import gymnasium

    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            id=ENV_ID,
            entry_point="marine_formation_env.gym_env:MarineFormationGymEnv",
            vector_entry_point="marine_formation_env.vector:MarineFormationVectorEnv",
        )
    import pettingzoo

    registry = getattr(pettingzoo, "parallel_registry", None)
    if registry is not None and ENV_ID not in registry:
        pettingzoo.register("parallel", ENV_ID, entry_point="marine_formation_env.env:parallel_env")


_register()

__all__ = [
    "ACTION_LEVELS",
    "ENV_ID",
    "GRAPH_PRESETS",
    "SCENARIOS",
    "SUPPLY",
    "VESSELS",
    "ChannelConfig",
    "CommGraph",
    "ConfigError",
    "Current",
    "FormationCore",
    "Gains",
    "GilbertElliott",
    "GraphError",
    "InitNoise",
    "MarineFormationParallelEnv",
    "ParameterError",
    "RewardConfig",
    "ScenarioConfig",
    "SensorNoise",
    "SpeedProfile",
    "VesselParams",
    "make_config",
    "make_graph",
    "parallel_env",
]
