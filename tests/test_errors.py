"""Every bad input raises a clear error that names the offending value."""

from __future__ import annotations

import re

import numpy as np
import pytest

import marine_formation_env
from marine_formation_env import CommGraph, ConfigError, Gains, GraphError, ParameterError

PAPER_X0 = np.array(
    [
        [-50.0, 20.0, 0.0, 3.0, 0.0, 0.0],
        [-60.0, 30.0, 0.3, 3.0, 0.0, 0.0],
        [-120.0, -10.0, -0.2, 3.0, 0.0, 0.0],
    ]
)


def make(**overrides):
    return marine_formation_env.parallel_env("paper", **overrides)


# --------------------------------------------------------------------------- configuration


def test_unknown_scenario():
    with pytest.raises(ConfigError, match="'no_such_scenario'"):
        marine_formation_env.parallel_env("no_such_scenario")


def test_unknown_action_level():
    with pytest.raises(ConfigError, match="'torque'"):
        make(action_level="torque")


def test_unknown_topology_preset():
    with pytest.raises(ConfigError, match="'hexagon'"):
        make(topology="hexagon")


def test_unknown_override_key():
    with pytest.raises(ConfigError, match="'n_boats'"):
        make(n_boats=3)


def test_self_loop_in_adjacency():
    adjacency = np.array([[0, 1, 0], [0, 1, 0], [1, 1, 0]])
    with pytest.raises(ConfigError, match=re.escape("adjacency[1, 1]")):
        make(topology=adjacency)


def test_self_loop_in_links():
    with pytest.raises(GraphError, match=re.escape("(2, 2)")):
        CommGraph.from_links(3, [(0, 1), (2, 2)])


@pytest.mark.parametrize("builder", [CommGraph.from_links, CommGraph.from_edges])
def test_out_of_range_node(builder):
    with pytest.raises(GraphError, match=r"vessel index 3 is out of range"):
        builder(3, [(0, 1), (0, 3)])
    with pytest.raises(GraphError, match=r"vessel index -1 is out of range"):
        builder(3, [(-1, 1)])


def test_non_square_adjacency():
    with pytest.raises(ConfigError, match=re.escape("(3, 4)")):
        make(topology=np.zeros((3, 4)))


def test_adjacency_of_wrong_size():
    adjacency = np.zeros((4, 4))
    adjacency[1:, 0] = 1
    with pytest.raises(ConfigError, match="4 vessels"):
        make(topology=adjacency)


def test_graph_without_globally_reachable_node():
    # 0 → 1 and 2 → 3: two separate pairs, no node reachable from all
    adjacency = np.zeros((4, 4), dtype=int)
    adjacency[1, 0] = 1
    adjacency[3, 2] = 1
    with pytest.raises(ConfigError, match=re.escape("[(0, 1), (2, 3)]")):
        marine_formation_env.parallel_env(n_vessels=4, topology=adjacency)
    # the opt-in accepts it, and the env runs
    env = marine_formation_env.parallel_env(n_vessels=4, topology=adjacency, allow_unreachable=True, horizon=1.0)
    env.reset(seed=0)
    while env.agents:
        env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert env.time == pytest.approx(1.0)


@pytest.mark.parametrize("delta", [-1, 0])
def test_non_positive_delta_in_gains(delta):
    with pytest.raises(ParameterError, match=f"got {delta}"):
        Gains(delta=delta)


def test_non_positive_delta_via_override():
    with pytest.raises(ConfigError, match=r"got -1\.5"):
        make(gains={"delta": -1.5})


def test_delta_below_sway_bound():
    # docs/model.md §1: Proposition 1 needs Δ > C_v·U_max = 37.7 m for `supply` on [3, 7] m/s
    with pytest.raises(ConfigError, match=r"30\.0.*37\.(7|69)"):
        make(gains={"delta": 30.0})
    make(gains={"delta": 40.0})  # above the bound: accepted


def test_desired_speed_violating_assumption_19():
    # u_d must lie in [U_min + a, U_max − a] = [4, 6]
    with pytest.raises(ConfigError, match=r"6\.5"):
        make(u_d=6.5, u_max=7.0, gains={"a": 1.0})
    with pytest.raises(ConfigError, match=r"3\.5"):
        make(u_d=3.5)
    make(u_d=6.0)  # at the edge: accepted


@pytest.mark.parametrize("u_min", [0.0, -1.0])
def test_non_positive_u_min(u_min):
    with pytest.raises(ConfigError, match=f"u_min = {u_min:g}"):
        make(u_min=u_min, u_d=4.0, gains={"a": 0.5})


# --------------------------------------------------------------------------- reset options


def test_initial_state_of_wrong_shape():
    env = make()
    with pytest.raises(ValueError, match=re.escape("(2, 6)")):
        env.reset(options={"initial_state": np.zeros((2, 6))})
    with pytest.raises(ValueError, match=re.escape("(3, 5)")):
        env.reset(options={"initial_state": np.zeros((3, 5))})


def test_initial_state_with_nan():
    env = make()
    x0 = PAPER_X0.copy()
    x0[1, 2] = np.nan
    # The message must name the entry as initial_state[1, 2] (not numpy reprs).
    with pytest.raises(ValueError, match=re.escape("initial_state[1, 2] = nan")):
        env.reset(options={"initial_state": x0})


def test_initial_state_with_inf():
    env = make()
    x0 = PAPER_X0.copy()
    x0[2, 0] = np.inf
    with pytest.raises(ValueError, match=r"= inf"):
        env.reset(options={"initial_state": x0})


# --------------------------------------------------------------------------- actions


def _ready(level="speed"):
    env = make(action_level=level, horizon=5.0)
    env.reset(seed=0)
    dim = 1 if level == "speed" else 2
    return env, {a: np.zeros(dim, np.float32) for a in env.agents}


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action(bad):
    env, actions = _ready("force")
    actions["vessel_2"] = np.array([0.0, bad])
    with pytest.raises(ValueError, match=rf"vessel_2.*{re.escape(str(bad))}"):
        env.step(actions)


def test_missing_agent_action():
    env, actions = _ready()
    del actions["vessel_1"]
    with pytest.raises(KeyError, match="vessel_1"):
        env.step(actions)


def test_unknown_agent_action():
    env, actions = _ready()
    actions["vessel_7"] = np.zeros(1, np.float32)
    with pytest.raises(KeyError, match="vessel_7"):
        env.step(actions)


@pytest.mark.parametrize(("level", "shape"), [("speed", (2,)), ("force", (1,)), ("guidance", (3,)), ("force", (2, 2))])
def test_wrong_action_shape(level, shape):
    env, actions = _ready(level)
    actions["vessel_0"] = np.zeros(shape, np.float32)
    with pytest.raises(ValueError, match=rf"vessel_0.*{re.escape(str(shape))}"):
        env.step(actions)


def test_step_after_episode_end():
    env, actions = _ready()
    while env.agents:
        env.step(actions)
    with pytest.raises(RuntimeError, match="ended"):
        env.step(actions)
    with pytest.raises(RuntimeError, match="ended"):
        env.step({})


def test_step_before_reset():
    env = make()
    with pytest.raises(RuntimeError, match="before reset"):
        env.step({a: np.zeros(1, np.float32) for a in env.possible_agents})


@pytest.mark.parametrize(
    ("level", "outside", "inside"),
    [
        ("speed", [5.0], [1.0]),
        ("speed", [-3.0], [-1.0]),
        ("guidance", [5.0, -2.5], [1.0, -1.0]),
        ("force", [5.0, -7.0], [1.0, -1.0]),
    ],
)
def test_out_of_range_actions_are_clipped(level, outside, inside):
    states = []
    for action in (outside, inside):
        env = make(action_level=level, horizon=5.0)
        env.reset(options={"initial_state": PAPER_X0})
        env.step({a: np.array(action, np.float32) for a in env.agents})
        states.append(env.vessel_states)
    assert np.array_equal(states[0], states[1])
    # and the clipped action is not a no-op
    env = make(action_level=level, horizon=5.0)
    env.reset(options={"initial_state": PAPER_X0})
    env.step({a: np.zeros(len(inside), np.float32) for a in env.agents})
    assert not np.array_equal(env.vessel_states, states[1])
