"""``reset()`` reports the same info keys as ``step()``, with zeros where nothing has happened yet.

Wrappers (TorchRL's ``PettingZooWrapper`` and ``GymEnv`` among them) build their
info specs from the first ``reset()``: a key that only ``step()`` reports never
reaches them.
"""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import marine_formation_env
from marine_formation_env import ENV_ID
from marine_formation_env.core import REWARD_COMPONENTS
from marine_formation_env.vector import MarineFormationVectorEnv

LEVELS = ["force", "guidance", "speed"]


def key_tree(info):
    """Nested keys of an info dict, with the shape of array values (types are compared too)."""
    if isinstance(info, dict):
        return {key: key_tree(value) for key, value in info.items()}
    return (type(info).__name__, np.shape(info))


def assert_zero(info):
    if isinstance(info, dict):
        for key, value in info.items():
            if key != "time":
                assert_zero(value)
        return
    assert not np.any(info), info


@pytest.mark.parametrize("level", LEVELS)
def test_parallel_env_reset_infos_have_the_step_keys(level):
    env = marine_formation_env.parallel_env("acoustic", action_level=level)
    _, reset_infos = env.reset(seed=3)
    assert set(reset_infos) == set(env.agents)
    _, _, _, _, step_infos = env.step({a: env.action_space(a).sample() for a in env.agents})
    for agent in env.possible_agents:
        assert key_tree(reset_infos[agent]) == key_tree(step_infos[agent])
        assert set(reset_infos[agent]["reward_components"]) == set(REWARD_COMPONENTS)
        assert_zero(reset_infos[agent])
        assert reset_infos[agent]["time"] == 0.0
        assert ("commanded_speed" in reset_infos[agent]) == (level != "force")


@pytest.mark.parametrize("level", LEVELS)
def test_gym_view_reset_info_has_the_step_keys(level):
    env = gymnasium.make(ENV_ID, action_level=level)
    _, reset_info = env.reset(seed=3)
    _, _, _, _, step_info = env.step(env.action_space.sample())
    assert key_tree(reset_info) == key_tree(step_info)
    assert_zero(reset_info)


@pytest.mark.parametrize("layout", ["joint", "agent"])
@pytest.mark.parametrize("level", LEVELS)
def test_vector_env_reset_infos_have_the_step_keys(level, layout):
    env = MarineFormationVectorEnv(3, "paper", layout=layout, action_level=level)
    _, reset_infos = env.reset(seed=3)
    _, _, _, _, step_infos = env.step(env.action_space.sample())
    assert key_tree(reset_infos) == key_tree(step_infos)
    assert_zero(reset_infos)
