"""The PettingZoo ParallelEnv: API conformance, spaces, reset, episode end, rewards, masking.

Expected values come from PettingZoo's own test suite, docs/model.md §3–§7, the env and
RewardConfig docstrings, and quantities computed here by hand from the state
(ẋ = u cos ψ − v sin ψ, e = y − D_y, …), never by calling the package's own
observation code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo.test import parallel_api_test, parallel_seed_test

import marine_formation_env
from marine_formation_env import RewardConfig, SpeedProfile
from marine_formation_env.frontend import reward_terms
from marine_formation_env.settings import TRACKING_TERMS

LEVELS = ("force", "guidance", "speed")
ACTION_DIM = {"force": 2, "guidance": 2, "speed": 1}
DT_DEFAULT = {"force": 0.1, "guidance": 0.5, "speed": 0.5}

# docs/model.md §5, typed in by hand (columns x, y, psi, u, v, r; offsets D_x, D_y).
PAPER_X0 = np.array(
    [
        [-50.0, 20.0, 0.0, 3.0, 0.0, 0.0],
        [-60.0, 30.0, 0.3, 3.0, 0.0, 0.0],
        [-120.0, -10.0, -0.2, 3.0, 0.0, 0.0],
    ]
)
PAPER_D = np.array([[-100.0, 50.0], [0.0, 0.0], [-100.0, -50.0]])
# docs/model.md §5 graph: vessel_1 → vessel_0, vessel_1 → vessel_2, vessel_0 → vessel_2.
PAPER_NEIGHBOURS = {0: {1}, 1: set(), 2: {0, 1}}
# RewardConfig defaults (its docstring / the env docstring): Σ weights = 1 + 0.25 + 1 + 0.5 + 0.
DEFAULT_TOTAL_WEIGHT = 2.75

OWN = 10  # docs/model.md §7: e, ψ, u, v, r, u_d, u̇_d, κ, κ ahead, D_y
SLOT = 4


def wrap(angle: float) -> float:
    """Angle wrapped to [−π, π), by hand."""
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a < 0:
        a += 2.0 * math.pi
    return a - math.pi


def x_dot(row: np.ndarray) -> float:
    """ẋ = u cos ψ − v sin ψ (docs/model.md §1)."""
    return row[3] * math.cos(row[2]) - row[4] * math.sin(row[2])


def slot_of(j: int, i: int, n: int) -> int:
    """Slot k of j's observation holding vessel i = (j + k + 1) mod n."""
    k = (i - j - 1) % n
    assert (j + k + 1) % n == i
    return k


def slot_view(obs: np.ndarray, n: int) -> np.ndarray:
    return obs[OWN:].reshape(n - 1, SLOT)


def random_state(rng: np.random.Generator, n: int) -> np.ndarray:
    """A well-separated random state with nonzero sway and yaw rate."""
    x = np.zeros((n, 6))
    x[:, 0] = -300.0 * np.arange(n) + rng.uniform(-20, 20, n)
    x[:, 1] = rng.uniform(-60, 60, n)
    x[:, 2] = rng.uniform(-0.6, 0.6, n)
    x[:, 3] = rng.uniform(3.5, 6.5, n)
    x[:, 4] = rng.uniform(-0.5, 0.5, n)
    x[:, 5] = rng.uniform(-0.02, 0.02, n)
    return x


#: A workspace that holds every :func:`random_state` (the derived one of a 5 s horizon does not).
WIDE = (-3000.0, 3000.0, -1000.0, 1000.0)


def first_obs(env, x0: np.ndarray) -> dict[str, np.ndarray]:
    obs, _ = env.reset(options={"initial_state": x0})
    return obs


# --------------------------------------------------------------------------- PettingZoo's own tests


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
@pytest.mark.parametrize("level", LEVELS)
def test_parallel_api_test(level):
    # horizon 10 s: the 300 cycles run through several truncations (and resets)
    env = marine_formation_env.parallel_env("paper", action_level=level, horizon=10.0)
    parallel_api_test(env, num_cycles=300)


@pytest.mark.parametrize("level", LEVELS)
def test_parallel_seed_test(level):
    parallel_seed_test(
        lambda: marine_formation_env.parallel_env(n_vessels=4, topology="ring", action_level=level, horizon=10.0),
        num_cycles=50,
    )


@pytest.mark.parametrize("level", LEVELS)
def test_seed_determines_random_initial_state(level):
    make = lambda: marine_formation_env.parallel_env(n_vessels=4, topology="ring", action_level=level, horizon=5.0)
    env_a, env_b = make(), make()
    obs_a0, _ = env_a.reset(seed=0)
    obs_b0, _ = env_b.reset(seed=0)
    state_a0 = env_a.vessel_states
    for agent in env_a.possible_agents:
        assert np.array_equal(obs_a0[agent], obs_b0[agent])
    # same seed, same trajectory under the same actions
    rng = np.random.default_rng(5)
    for _ in range(5):
        actions = {a: rng.uniform(-1, 1, ACTION_DIM[level]).astype(np.float32) for a in env_a.agents}
        out_a, out_b = env_a.step(actions), env_b.step(actions)
        for agent in env_a.possible_agents:
            assert np.array_equal(out_a[0][agent], out_b[0][agent])
            assert out_a[1][agent] == out_b[1][agent]
    # another seed: other initial state and other observations
    obs_a1, _ = env_a.reset(seed=1)
    assert not np.array_equal(env_a.vessel_states, state_a0)
    assert any(not np.array_equal(obs_a1[a], obs_a0[a]) for a in env_a.possible_agents)
    # and the same seed again reproduces the first one
    obs_a2, _ = env_a.reset(seed=0)
    assert np.array_equal(env_a.vessel_states, state_a0)
    assert all(np.array_equal(obs_a2[a], obs_a0[a]) for a in env_a.possible_agents)


# --------------------------------------------------------------------------- agents and spaces


@pytest.mark.parametrize("level", LEVELS)
def test_agents_and_spaces(level):
    env = marine_formation_env.parallel_env("paper", action_level=level)
    assert env.possible_agents == ["vessel_0", "vessel_1", "vessel_2"]
    env.reset(seed=0)
    assert env.agents == ["vessel_0", "vessel_1", "vessel_2"]
    first_obs_space, first_act_space = env.observation_space("vessel_0"), env.action_space("vessel_0")
    for agent in env.possible_agents:
        assert env.observation_space(agent) is first_obs_space
        assert env.action_space(agent) is first_act_space
    act = first_act_space
    assert isinstance(act, spaces.Box)
    assert act.shape == (ACTION_DIM[level],)
    assert act.dtype == np.float32
    assert np.all(act.low == -1.0) and np.all(act.high == 1.0)
    # docs/model.md §7 / core docstring: 10 own entries + 4 per other vessel
    assert first_obs_space.shape == (10 + 4 * 2,)
    assert env.state_space.shape == (3 * 6 + 1,)


@pytest.mark.parametrize("level", LEVELS)
def test_observations_and_state_in_spaces_along_random_rollout(level):
    env = marine_formation_env.parallel_env("paper", action_level=level, horizon=20.0)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    steps = 0
    while env.agents and steps < 100:
        for agent, o in obs.items():
            assert env.observation_space(agent).contains(o), (agent, o)
        assert env.state_space.contains(env.state())
        actions = {a: rng.uniform(-1, 1, ACTION_DIM[level]).astype(np.float32) for a in env.agents}
        obs, *_ = env.step(actions)
        steps += 1
    assert steps > 10


def test_six_vessel_ring():
    env = marine_formation_env.parallel_env(n_vessels=6, topology="ring", horizon=5.0)
    obs, _ = env.reset(seed=0)
    assert env.possible_agents == [f"vessel_{j}" for j in range(6)]
    assert env.observation_space("vessel_3").shape == (10 + 4 * 5,)
    assert env.state_space.shape == (6 * 6 + 1,)
    for j in range(6):
        o = obs[f"vessel_{j}"]
        assert o.shape == (30,)
        # ring j → j+1: vessel j receives from j−1 only, which sits in slot (j−1−j−1) mod 6 = 4
        links = slot_view(o, 6)[:, 0]
        expected = np.zeros(5)
        expected[slot_of(j, (j - 1) % 6, 6)] = 1.0
        assert np.array_equal(links, expected)
    while env.agents:
        obs, rewards, *_ = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        assert all(np.isfinite(list(rewards.values())))


# --------------------------------------------------------------------------- reset


@pytest.mark.parametrize("level", LEVELS)
def test_reset_with_initial_state_sets_it_exactly(level):
    env = marine_formation_env.parallel_env("paper", action_level=level)
    x0 = np.array(
        [
            [12.5, -3.25, 0.7, 4.5, 0.125, -0.01],
            [-333.0, 44.0, -1.2, 6.0, -0.3, 0.02],
            [250.0, 7.0, 2.5, 3.1, 0.0, 0.005],
        ]
    )
    env.reset(seed=123, options={"initial_state": x0})
    assert np.array_equal(env.vessel_states, x0)
    state = env.state()
    # state(): n·6 vessel entries (ψ wrapped; here already in [−π, π)) then time 0
    assert state.shape == (19,)
    assert np.array_equal(state[:-1], x0.astype(np.float32).ravel())
    assert state[-1] == 0.0
    assert env.time == 0.0


def test_default_reset_is_spec_initial_state():
    env = marine_formation_env.parallel_env("paper")
    env.reset(seed=7)
    assert np.array_equal(env.vessel_states, PAPER_X0)


def test_state_wraps_heading_and_reports_time():
    env = marine_formation_env.parallel_env("paper", action_level="force")
    x0 = PAPER_X0.copy()
    x0[:, 2] = [7.0, -4.0, math.pi]
    env.reset(options={"initial_state": x0})
    state = env.state().reshape(-1)
    np.testing.assert_allclose(state[2:18:6], [wrap(7.0), wrap(-4.0), -math.pi], rtol=1e-6)
    for k in range(1, 4):
        env.step({a: np.zeros(2, np.float32) for a in env.agents})
        assert env.state()[-1] == pytest.approx(0.1 * k, rel=1e-6)


# --------------------------------------------------------------------------- episode end


@pytest.mark.parametrize(("level", "horizon"), [("speed", 7.3), ("guidance", 7.3), ("force", 2.04)])
def test_truncation_exactly_at_round_horizon_over_dt(level, horizon):
    env = marine_formation_env.parallel_env("paper", action_level=level, horizon=horizon)
    expected_steps = round(horizon / DT_DEFAULT[level])  # 15 (7.3/0.5 = 14.6) and 20 (2.04/0.1 = 20.4)
    env.reset(seed=0)
    zero = np.zeros(ACTION_DIM[level], np.float32)
    for k in range(1, expected_steps + 1):
        assert env.agents == env.possible_agents
        _, _, terminations, truncations, _ = env.step({a: zero for a in env.agents})
        assert set(truncations) == set(env.possible_agents)
        assert not any(terminations.values())
        if k < expected_steps:
            assert not any(truncations.values()), f"truncated early at step {k}"
        else:
            assert all(truncations.values()), f"not truncated at step {k}"
    assert env.agents == []
    assert env.time == pytest.approx(expected_steps * DT_DEFAULT[level])


@pytest.mark.parametrize(
    ("reward", "total_weight"),
    [
        (None, DEFAULT_TOTAL_WEIGHT),
        (
            RewardConfig(cross_track=2.0, heading=1.0, coordination=0.5, speed=0.25, effort=0.1),
            2.0 + 1.0 + 0.5 + 0.25 + 0.1,
        ),
        # a fine share only splits each term between two scales, each cost < 1: the worst rate stays Σ w
        (RewardConfig(fine_share=0.5, fine_scale=0.1), DEFAULT_TOTAL_WEIGHT),
    ],
)
def test_collision_terminates_all_with_terminal_penalty(reward, total_weight):
    overrides = {"safety_distance": 5.0, "horizon": 50.0}
    if reward is not None:
        overrides["reward"] = reward
    env = marine_formation_env.parallel_env("paper", action_level="speed", **overrides)
    # head-on, 6 m apart at 5 m/s each: closer than 5 m within the first control period (a start
    # that is already inside the safety distance is refused at reset)
    x0 = np.array(
        [
            [0.0, 50.0, math.pi / 2, 5.0, 0.0, 0.0],  # vessel_0 heading +y
            [0.0, 56.0, -math.pi / 2, 5.0, 0.0, 0.0],  # vessel_1, 6 m to +y, heading −y
            [-100.0, -50.0, 0.0, 5.0, 0.0, 0.0],
        ]
    )
    env.reset(options={"initial_state": x0})
    _, rewards, terminations, truncations, infos = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert all(terminations.values()) and len(terminations) == 3
    assert not any(truncations.values())
    assert env.agents == []
    time_left = 50.0 - 0.5
    for agent in env.possible_agents:
        assert infos[agent]["collision"] is True
        assert infos[agent]["out_of_bounds"] is False
        comp = reward_terms(infos[agent])
        assert comp["terminal"] == pytest.approx(-total_weight * time_left, rel=1e-12)
        assert rewards[agent] == pytest.approx(sum(comp.values()), rel=1e-12, abs=1e-12)
    with pytest.raises(RuntimeError):
        env.step({})


def test_no_collision_when_far_apart():
    env = marine_formation_env.parallel_env("paper", safety_distance=5.0, horizon=5.0)
    env.reset()  # docs/model.md §5 state: vessels ≥ 14 m apart at the start
    _, _, terminations, _, infos = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert not any(terminations.values())
    assert not any(info["collision"] for info in infos.values())


def test_leaving_workspace_terminates():
    env = marine_formation_env.parallel_env(
        "paper", action_level="force", horizon=30.0, workspace=(-1000.0, 1000.0, -200.0, 200.0)
    )
    x0 = PAPER_X0.copy()
    x0[2] = [-120.0, -199.9, -math.pi / 2, 5.0, 0.0, 0.0]  # heading −y, 0.1 m from the edge
    env.reset(options={"initial_state": x0})
    _, rewards, terminations, truncations, infos = env.step({a: np.zeros(2, np.float32) for a in env.agents})
    assert env.vessel_states[2, 1] < -200.0  # moved ≈ 0.5 m in 0.1 s, so ≈ 0.4 m out
    assert all(terminations.values()) and not any(truncations.values())
    assert env.agents == []
    for agent in env.possible_agents:
        assert infos[agent]["out_of_bounds"] is True
        assert infos[agent]["collision"] is False
        assert reward_terms(infos[agent])["terminal"] == pytest.approx(-DEFAULT_TOTAL_WEIGHT * (30.0 - 0.1), rel=1e-9)
        assert rewards[agent] == pytest.approx(sum(reward_terms(infos[agent]).values()), rel=1e-12)


@pytest.mark.parametrize("level", LEVELS)
def test_reward_components_sum_to_reward(level):
    env = marine_formation_env.parallel_env("paper", action_level=level, horizon=10.0, reward=RewardConfig(effort=0.3))
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    names = {"cross_track", "heading", "coordination", "speed", "effort", "terminal", "communication"}
    while env.agents:
        actions = {a: rng.uniform(-1, 1, ACTION_DIM[level]).astype(np.float32) for a in env.agents}
        _, rewards, _, _, infos = env.step(actions)
        for agent, r in rewards.items():
            comp = reward_terms(infos[agent])
            assert set(comp) == names
            assert r == pytest.approx(sum(comp.values()), rel=1e-12, abs=1e-12)
            assert r < 0.0  # every cost is ≥ 0 and effort > 0 with random actions
            # bounded costs: each term is in (−dt·w, 0]
            assert -DT_DEFAULT[level] * 1.0 <= comp["cross_track"] <= 0.0
            assert -DT_DEFAULT[level] * 0.3 <= comp["effort"] < 0.0


def _cost(error: float, sigma: float) -> float:
    """c(e; σ) = (e/σ)²/(1 + (e/σ)²), the RewardConfig docstring's bounded cost, by hand."""
    return (error / sigma) ** 2 / (1.0 + (error / sigma) ** 2)


@pytest.mark.parametrize(
    ("reward", "share", "fine", "fine_terms"),
    [
        (None, 0.0, 0.05, TRACKING_TERMS),
        ({"fine_share": 0.4}, 0.4, 0.05, TRACKING_TERMS),
        ({"fine_share": 1.0, "fine_scale": 0.2}, 1.0, 0.2, TRACKING_TERMS),
        (
            {"fine_share": 0.5, "fine_scale": 0.1, "fine_terms": ["cross_track", "coordination"]},
            0.5,
            0.1,
            ("cross_track", "coordination"),
        ),
    ],
)
def test_reward_terms_match_the_docstring_formula_from_the_state(reward, share, fine, fine_terms):
    # the reward after one step, from the state after it: each tracking term in fine_terms is
    # −dt·w·[(1 − f)·c(e; σ) + f·c(e; s·σ)], the others −dt·w·c(e; σ), with the defaults
    # w = (1, 0.25, 1, 0.5), σ = (20 m, 0.2 rad, 20 m, 1 m/s); f = 0 is the benchmark's reward
    overrides = {} if reward is None else {"reward": reward}
    env = marine_formation_env.parallel_env("paper", action_level="speed", **overrides)
    env.reset(options={"initial_state": PAPER_X0})
    _, rewards, _, _, infos = env.step({a: np.array([0.3], np.float32) for a in env.agents})
    s = env.vessel_states
    theta = s[:, 0] - PAPER_D[:, 0]
    dt = DT_DEFAULT["speed"]
    for j in range(3):
        errors = {
            "cross_track": (s[j, 1] - PAPER_D[j, 1], 1.0, 20.0),
            "heading": (wrap(s[j, 2]), 0.25, 0.2),
            "coordination": (theta[j] - theta.mean(), 1.0, 20.0),
            "speed": (x_dot(s[j]) - 5.0, 0.5, 1.0),
        }
        comp = reward_terms(infos[f"vessel_{j}"])
        for name, (e, w, sigma) in errors.items():
            f = share if name in fine_terms else 0.0
            expected = -dt * w * ((1.0 - f) * _cost(e, sigma) + f * _cost(e, fine * sigma))
            assert comp[name] == pytest.approx(expected, rel=1e-9, abs=1e-15), name
        assert rewards[f"vessel_{j}"] == pytest.approx(sum(comp.values()), rel=1e-12)


# --------------------------------------------------------------------------- observation content


def test_own_observation_matches_hand_computation():
    env = marine_formation_env.parallel_env("paper", action_level="speed")
    x0 = np.array(
        [
            [-50.0, 20.0, 7.0, 3.0, 0.2, 0.01],
            [-60.0, 30.0, -4.0, 4.5, -0.1, -0.02],
            [-120.0, -10.0, -0.2, 5.5, 0.05, 0.003],
        ]
    )
    obs = first_obs(env, x0)
    for j in range(3):
        o = obs[f"vessel_{j}"]
        assert o.dtype == np.float32
        expected = [
            x0[j, 1] - PAPER_D[j, 1],  # e_j = y_j − D_yj
            wrap(x0[j, 2]),
            x0[j, 3],
            x0[j, 4],
            x0[j, 5],
            5.0,  # u_d
            0.0,  # u̇_d (constant)
            0.0,  # κ at the vessel: the straight path
            0.0,  # κ ahead
            PAPER_D[j, 1],  # D_y, the lane offset
        ]
        np.testing.assert_allclose(o[:OWN], expected, rtol=1e-6, atol=1e-7)
        assert -math.pi <= o[1] <= math.pi


@pytest.mark.parametrize("n", [3, 4])
def test_slots_hold_relative_coordination_quantities(n):
    # complete graph, so every slot is filled; explicit offsets known by hand
    formation = np.array([[0.0, 0.0], [-100.0, 50.0], [-100.0, -50.0], [-200.0, 100.0]])[:n]
    env = marine_formation_env.parallel_env(
        "paper", n_vessels=n, formation=formation, topology="complete", horizon=5.0, workspace=WIDE
    )
    x0 = random_state(np.random.default_rng(n), n)
    obs = first_obs(env, x0)
    for j in range(n):
        slots = slot_view(obs[f"vessel_{j}"], n)
        for k in range(n - 1):
            i = (j + k + 1) % n
            theta_j = x0[j, 0] - formation[j, 0]
            theta_i = x0[i, 0] - formation[i, 0]
            np.testing.assert_allclose(
                slots[k], [1.0, theta_j - theta_i, x_dot(x0[j]) - x_dot(x0[i]), 0.0], rtol=1e-5, atol=1e-5
            )


def _perturbed(x0: np.ndarray, i: int, columns: tuple[int, ...]) -> np.ndarray:
    x = x0.copy()
    bump = {0: 37.0, 1: -23.0, 2: 0.4, 3: 1.3, 4: 0.2, 5: 0.01}
    for c in columns:
        x[i, c] += bump[c]
    return x


ALL = (0, 1, 2, 3, 4, 5)


def test_paper_graph_masking():
    env = marine_formation_env.parallel_env("paper")
    x0 = PAPER_X0.copy()
    x0[:, 4] = [0.1, -0.2, 0.15]  # nonzero sway so ẋ depends on v too
    base = first_obs(env, x0)
    for j, neighbours in PAPER_NEIGHBOURS.items():
        agent = f"vessel_{j}"
        slots = slot_view(base[agent], 3)
        for i in set(range(3)) - {j}:
            k = slot_of(j, i, 3)
            linked = i in neighbours
            assert slots[k, 0] == float(linked)
            if not linked:
                assert np.all(slots[k] == 0.0), (j, i, slots[k])
            # any change of a non-neighbour: j's observation is bit-identical
            changed = first_obs(env, _perturbed(x0, i, ALL))[agent]
            if linked:
                assert not np.array_equal(changed, base[agent])
                # a neighbour's x alone reaches j …
                only_x = first_obs(env, _perturbed(x0, i, (0,)))[agent]
                assert not np.array_equal(only_x, base[agent])
                # … but its y and r are not transmitted (docs/model.md §3: only x_i and ẋ_i)
                not_sent = first_obs(env, _perturbed(x0, i, (1, 5)))[agent]
                assert np.array_equal(not_sent, base[agent])
            else:
                assert np.array_equal(changed, base[agent]), (j, i)
        # j's own state always shows
        assert not np.array_equal(first_obs(env, _perturbed(x0, j, (1,)))[agent], base[agent])


@pytest.mark.parametrize("topology_seed", [1, 2, 3])
def test_random_graph_masking(topology_seed):
    n = 5
    env = marine_formation_env.parallel_env(
        "paper", n_vessels=n, topology="random", topology_seed=topology_seed, horizon=5.0, workspace=WIDE
    )
    adjacency = np.asarray(env.config.graph.adjacency)  # A[j, i] = 1 iff i transmits to j
    x0 = random_state(np.random.default_rng(topology_seed), n)
    base = first_obs(env, x0)
    n_links = 0
    for j in range(n):
        agent = f"vessel_{j}"
        slots = slot_view(base[agent], n)
        for i in set(range(n)) - {j}:
            k = slot_of(j, i, n)
            linked = bool(adjacency[j, i])
            n_links += linked
            assert slots[k, 0] == float(linked)
            changed = first_obs(env, _perturbed(x0, i, ALL))[agent]
            if linked:
                assert not np.array_equal(changed, base[agent])
                np.testing.assert_allclose(
                    slots[k, 1:3],
                    [
                        (x0[j, 0] - env.config.formation[j, 0]) - (x0[i, 0] - env.config.formation[i, 0]),
                        x_dot(x0[j]) - x_dot(x0[i]),
                    ],
                    rtol=1e-5,
                    atol=1e-4,
                )
            else:
                assert np.all(slots[k] == 0.0)
                assert np.array_equal(changed, base[agent]), (j, i)
    assert n - 1 <= n_links < n * (n - 1)  # a spanning tree at least, and some vessels not linked


def test_time_varying_desired_speed_in_observation():
    profile = SpeedProfile(mean=5.0, amplitude=0.5, period=100.0)
    env = marine_formation_env.parallel_env("paper", u_d=profile, horizon=60.0)
    obs, _ = env.reset()
    checked = 0
    for k in range(0, 101):
        t = 0.5 * k
        if k % 10 == 0:
            for o in obs.values():
                assert o[5] == pytest.approx(5.0 + 0.5 * math.sin(2 * math.pi * t / 100.0), abs=1e-6)
                assert o[6] == pytest.approx(0.5 * 2 * math.pi / 100.0 * math.cos(2 * math.pi * t / 100.0), abs=1e-7)
            checked += 1
        if not env.agents:
            break
        obs, *_ = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert checked == 11  # t = 0, 5, …, 50 s
