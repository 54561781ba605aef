"""marine_formation_env: formation control of underactuated marine vessels under communication constraints.

A research environment built on "Formation Control of Underactuated Marine
Vehicles with Communication Constraints": batched 3-DOF vessel dynamics, a
directed communication graph that masks what each vessel observes, and a
PettingZoo ParallelEnv whose agents act at the force, guidance or speed level.

Quick start::

    import marine_formation_env

    env = marine_formation_env.parallel_env(scenario="paper", action_level="speed")
    observations, infos = env.reset(seed=0)
"""

from marine_formation_env.core import FormationCore
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

__version__ = "0.1.0"

__all__ = [
    "ACTION_LEVELS",
    "GRAPH_PRESETS",
    "SCENARIOS",
    "SUPPLY",
    "VESSELS",
    "CommGraph",
    "ConfigError",
    "FormationCore",
    "Gains",
    "GraphError",
    "InitNoise",
    "MarineFormationParallelEnv",
    "ParameterError",
    "RewardConfig",
    "ScenarioConfig",
    "SpeedProfile",
    "VesselParams",
    "make_config",
    "make_graph",
    "parallel_env",
]
