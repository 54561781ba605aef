"""``reset()`` reports the same info keys as ``step()``, with zeros where nothing has happened yet.

The message counters are the exception: the reset instant is a control instant at which the vessels
broadcast (their first messages), and ``reset()`` reports those.

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
from marine_formation_env.core import MESSAGE_KEYS, REWARD_COMPONENTS
from marine_formation_env.frontend import reward_terms
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
            if key != "time" and key not in MESSAGE_KEYS:
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
        assert set(reward_terms(reset_infos[agent])) == set(REWARD_COMPONENTS)
        assert_zero(reset_infos[agent])
        assert reset_infos[agent]["time"] == 0.0
        assert ("commanded_speed" in reset_infos[agent]) == (level != "force")
    # acoustic TDMA: the first slot, at the reset instant, is vessel_0's
    assert [reset_infos[agent]["messages_sent"] for agent in env.possible_agents] == [1, 0, 0]


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
    sent = reset_infos["messages_sent"]  # ideal links: every vessel broadcasts at the reset instant
    np.testing.assert_array_equal(sent, 3 if layout == "joint" else np.ones(9))


# --------------------------------------------------------------------------- one schema, every view


def flat_items(info, prefix=""):
    for key, value in info.items():
        if isinstance(value, dict):
            yield from flat_items(value, prefix + key + ".")
        else:
            yield prefix + key, value


@pytest.mark.parametrize("level", LEVELS)
def test_every_view_reports_the_same_infos_for_the_same_seed(level):
    """ParallelEnv == vector agent layout entry by entry; gym view == vector joint layout; the gym view's
    per-formation values are the ParallelEnv's per-vessel ones, averaged or gathered."""
    scenario, seed = "acoustic", 7
    par = marine_formation_env.parallel_env(scenario, action_level=level)
    gym_env = gymnasium.make(ENV_ID, scenario=scenario, action_level=level)
    agent_vec = MarineFormationVectorEnv(1, scenario, layout="agent", action_level=level)
    joint_vec = MarineFormationVectorEnv(1, scenario, layout="joint", action_level=level)
    results = [par.reset(seed=seed)[1], gym_env.reset(seed=seed)[1], agent_vec.reset(seed=seed)[1]]
    results.append(joint_vec.reset(seed=seed)[1])
    rng = np.random.default_rng(0)
    agents = par.possible_agents
    for step in range(6):
        par_infos, gym_info, agent_infos, joint_infos = results
        for j, agent in enumerate(agents):
            for key, value in flat_items(par_infos[agent]):
                stacked = dict(flat_items(agent_infos))[key]
                assert stacked[j] == value, (step, agent, key)
        gym_items, joint_items = dict(flat_items(gym_info)), dict(flat_items(joint_infos))
        assert set(gym_items) == set(joint_items)
        for key, value in gym_items.items():
            np.testing.assert_array_equal(joint_items[key][0], value, err_msg=key)
        for name in REWARD_COMPONENTS:
            per_vessel = [par_infos[a][f"reward_{name}"] for a in agents]
            assert gym_info[f"reward_{name}"] == pytest.approx(np.mean(per_vessel), rel=1e-12, abs=1e-15)
        if level != "force":
            commanded = [par_infos[a]["commanded_speed"] for a in agents]
            np.testing.assert_array_equal(gym_info["commanded_speed"], commanded)
        for key in ("time", "collision", "out_of_bounds"):
            assert gym_info[key] == par_infos[agents[0]][key]
        actions = rng.uniform(-1, 1, (len(agents), par.action_space(agents[0]).shape[0])).astype(np.float32)
        results = [
            par.step({a: actions[j] for j, a in enumerate(agents)})[4],
            gym_env.step(actions.reshape(-1))[4],
            agent_vec.step(actions)[4],
            joint_vec.step(actions.reshape(1, -1))[4],
        ]
