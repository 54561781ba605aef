"""The centralized gymnasium view ``gymnasium.make("MarineFormation-v1")`` (docs/model.md §7).

Truth comes from outside the view: gymnasium's and Stable-Baselines3's own env
checkers (which must pass without a single warning), gymnasium's and
PettingZoo's registries, and the PettingZoo ParallelEnv stepped by hand with the
same seed and the same actions (the view's documented contract: observation =
the vessels' observations concatenated in vessel order, reward = the mean of
the vessels' rewards, termination/truncation = the formation's).
"""

from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env as gym_check_env

import marine_formation_env
from marine_formation_env.gym_env import MarineFormationGymEnv
from marine_formation_env.vector import MarineFormationVectorEnv

ENV_ID = "MarineFormation-v1"
LEVELS = ("force", "guidance", "speed")
ACTION_DIM = {"force": 2, "guidance": 2, "speed": 1}
OWN, SLOT = 10, 4

# docs/model.md §5, typed in by hand (columns x, y, psi, u, v, r; offsets D_x, D_y).
PAPER_X0 = np.array(
    [
        [-50.0, 20.0, 0.0, 3.0, 0.0, 0.0],
        [-60.0, 30.0, 0.3, 3.0, 0.0, 0.0],
        [-120.0, -10.0, -0.2, 3.0, 0.0, 0.0],
    ]
)
PAPER_D = np.array([[-100.0, 50.0], [0.0, 0.0], [-100.0, -50.0]])


def obs_dim(n: int) -> int:
    """docs/model.md §7 / env docstring: 10 own entries plus a 4-entry slot per other vessel."""
    return OWN + SLOT * (n - 1)


def wrap(angle: float) -> float:
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a < 0:
        a += 2.0 * math.pi
    return a - math.pi


def joint_of(per_agent: dict[str, np.ndarray], n: int) -> np.ndarray:
    """The documented joint layout, built by hand: vessel j's block at [j·dim, (j+1)·dim)."""
    return np.concatenate([per_agent[f"vessel_{j}"] for j in range(n)])


def split_joint_action(action: np.ndarray, n: int, a: int) -> dict[str, np.ndarray]:
    """The documented joint action layout: vessel j's action at [j·A, (j+1)·A)."""
    return {f"vessel_{j}": action[j * a : (j + 1) * a] for j in range(n)}


# --------------------------------------------------------------------------- registration


def test_import_registers_gymnasium_id_with_string_entry_points():
    spec = gymnasium.registry[ENV_ID]
    assert isinstance(spec.entry_point, str)
    assert isinstance(spec.vector_entry_point, str)
    # the strings resolve to the documented classes
    assert gymnasium.envs.registration.load_env_creator(spec.entry_point) is MarineFormationGymEnv
    assert gymnasium.envs.registration.load_env_creator(spec.vector_entry_point) is MarineFormationVectorEnv


def test_registration_is_idempotent_without_warnings():
    import importlib

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        importlib.reload(marine_formation_env)
    assert [str(w.message) for w in caught] == []
    assert ENV_ID in gymnasium.registry


def test_make_five_vessel_ring_shapes():
    env = gymnasium.make(ENV_ID, scenario="paper", action_level="speed", topology="ring", n_vessels=5)
    assert isinstance(env.unwrapped, MarineFormationGymEnv)
    assert isinstance(env.observation_space, spaces.Box)
    assert env.observation_space.shape == (5 * (10 + 4 * 4),)
    assert env.observation_space.dtype == np.float32
    assert isinstance(env.action_space, spaces.Box)
    assert env.action_space.shape == (5,)
    assert env.action_space.dtype == np.float32
    assert np.all(env.action_space.low == -1.0) and np.all(env.action_space.high == 1.0)
    obs, info = env.reset(seed=0)
    assert obs.shape == (130,)
    assert obs.dtype == np.float32
    assert isinstance(info, dict)
    assert env.observation_space.contains(obs)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape == (130,) and env.observation_space.contains(obs)
    assert isinstance(reward, float) and np.isfinite(reward)
    assert terminated is False and truncated is False
    env.close()


@pytest.mark.parametrize("level", LEVELS)
def test_spaces_per_level(level):
    env = gymnasium.make(ENV_ID, action_level=level)
    assert env.observation_space.shape == (3 * obs_dim(3),)
    assert env.action_space.shape == (3 * ACTION_DIM[level],)
    # each joint block has the ParallelEnv's per-agent bounds
    par = marine_formation_env.parallel_env(action_level=level)
    block = par.observation_space("vessel_0")
    assert np.array_equal(env.observation_space.low, np.tile(block.low, 3))
    assert np.array_equal(env.observation_space.high, np.tile(block.high, 3))


# --------------------------------------------------------------------------- the checkers, warning-free


@pytest.mark.parametrize("level", LEVELS)
def test_gymnasium_check_env_passes_without_warnings(level):
    env = gymnasium.make(ENV_ID, scenario="paper", action_level=level, topology="ring", n_vessels=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gym_check_env(env.unwrapped)
    assert [f"{w.category.__name__}: {w.message}" for w in caught] == []


@pytest.mark.parametrize("level", LEVELS)
def test_sb3_check_env_passes_without_warnings(level):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gymnasium.make(ENV_ID, scenario="paper", action_level=level, topology="ring", n_vessels=5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env.unwrapped, warn=True)
    assert [f"{w.category.__name__}: {w.message}" for w in caught] == []


# --------------------------------------------------------------------------- the centralized-view contract


def _compare_with_parallel(level: str, seed: int, horizon: float, **overrides) -> int:
    """Step the gym view and a ParallelEnv side by side until the episode ends; return the step count."""
    n = overrides.get("n_vessels", 3)
    a = ACTION_DIM[level]
    gym_env = gymnasium.make(ENV_ID, action_level=level, horizon=horizon, **overrides)
    par = marine_formation_env.parallel_env(action_level=level, horizon=horizon, **overrides)
    obs, _ = gym_env.reset(seed=seed)
    par_obs, _ = par.reset(seed=seed)
    np.testing.assert_array_equal(obs, joint_of(par_obs, n))
    rng = np.random.default_rng(seed + 100)
    steps = 0
    while True:
        action = rng.uniform(-1.0, 1.0, n * a).astype(np.float32)
        obs, reward, terminated, truncated, info = gym_env.step(action)
        par_obs, par_rew, par_term, par_trunc, _ = par.step(split_joint_action(action, n, a))
        steps += 1
        np.testing.assert_array_equal(obs, joint_of(par_obs, n))
        vessel_rewards = [par_rew[f"vessel_{j}"] for j in range(n)]
        assert reward == pytest.approx(sum(vessel_rewards) / n, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(info["vessel_rewards"], vessel_rewards, rtol=1e-12, atol=0)
        assert terminated == all(par_term.values()) == any(par_term.values())
        assert truncated == all(par_trunc.values()) == any(par_trunc.values())
        if terminated or truncated:
            assert par.agents == []
            return steps
        assert par.agents == par.possible_agents
        assert steps < 1000


@pytest.mark.parametrize("level", LEVELS)
def test_joint_view_matches_parallel_env_with_random_initial_states(level):
    # n_vessels=4 switches to random initial states, so the seed matters
    steps = _compare_with_parallel(level, seed=3, horizon=2.0, n_vessels=4, topology="ring")
    dt = {"force": 0.1, "guidance": 0.5, "speed": 0.5}[level]
    assert steps == round(2.0 / dt)  # ended by truncation after round(horizon/dt) steps


@pytest.mark.parametrize("level", LEVELS)
def test_joint_view_matches_parallel_env_paper_scenario(level):
    _compare_with_parallel(level, seed=0, horizon=3.0)


def test_termination_agrees_with_parallel_env():
    # two vessels 6 m apart, head-on at 5 m/s, with a 5 m safety distance: they collide within the first step
    x0 = np.array(
        [
            [0.0, 0.0, math.pi / 2, 5.0, 0.0, 0.0],
            [0.0, 6.0, -math.pi / 2, 5.0, 0.0, 0.0],
            [-300.0, -50.0, 0.0, 5.0, 0.0, 0.0],
        ]
    )
    gym_env = gymnasium.make(ENV_ID, safety_distance=5.0)
    par = marine_formation_env.parallel_env(safety_distance=5.0)
    obs, _ = gym_env.reset(options={"initial_state": x0})
    par_obs, _ = par.reset(options={"initial_state": x0})
    np.testing.assert_array_equal(obs, joint_of(par_obs, 3))
    action = np.zeros(3, dtype=np.float32)
    obs, reward, terminated, truncated, info = gym_env.step(action)
    par_obs, par_rew, par_term, par_trunc, _ = par.step(split_joint_action(action, 3, 1))
    assert terminated is True and truncated is False
    assert all(par_term.values()) and not any(par_trunc.values())
    assert info["collision"] is True
    np.testing.assert_array_equal(obs, joint_of(par_obs, 3))
    assert reward == pytest.approx(np.mean(list(par_rew.values())), rel=1e-12)
    # the terminal penalty (env docstring) makes the reward large and negative
    assert reward < -100.0


# --------------------------------------------------------------------------- reset


def test_reset_with_initial_state_sets_it():
    env = gymnasium.make(ENV_ID, action_level="speed")
    x0 = np.array(
        [
            [12.5, -3.25, 0.7, 4.5, 0.125, -0.01],
            [-333.0, 44.0, -1.2, 6.0, -0.3, 0.02],
            [250.0, 7.0, 2.5, 3.1, 0.0, 0.005],
        ]
    )
    obs, _ = env.reset(seed=123, options={"initial_state": x0})
    np.testing.assert_array_equal(env.unwrapped.core.state[0], x0)
    d = obs_dim(3)
    for j in range(3):
        own = obs[j * d : j * d + OWN]
        assert own[0] == pytest.approx(x0[j, 1] - PAPER_D[j, 1], abs=1e-4)  # e_j = y_j − D_yj
        assert own[1] == pytest.approx(wrap(x0[j, 2]), abs=1e-6)
        np.testing.assert_allclose(own[2:5], x0[j, 3:6], rtol=1e-6)
        assert own[5] == pytest.approx(5.0)  # u_d of the paper scenario
        assert own[6] == 0.0
        assert own[7] == own[8] == 0.0  # the straight path's curvature, now and ahead
        assert own[9] == PAPER_D[j, 1]  # the lane offset
    # the seed does not matter when the state is given
    obs2, _ = env.reset(seed=999, options={"initial_state": x0})
    np.testing.assert_array_equal(obs, obs2)


def test_reset_without_options_is_paper_initial_state():
    env = gymnasium.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(env.unwrapped.core.state[0], PAPER_X0)
    d = obs_dim(3)
    for j in range(3):
        assert obs[j * d] == pytest.approx(PAPER_X0[j, 1] - PAPER_D[j, 1])


def test_same_seed_same_episode_other_seed_other_start():
    make = lambda: gymnasium.make(ENV_ID, n_vessels=4, topology="ring", horizon=5.0)
    a, b = make(), make()
    obs_a, _ = a.reset(seed=7)
    obs_b, _ = b.reset(seed=7)
    np.testing.assert_array_equal(obs_a, obs_b)
    obs_c, _ = b.reset(seed=8)
    assert not np.array_equal(obs_a, obs_c)


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises_value_error(bad):
    env = gymnasium.make(ENV_ID, action_level="guidance")
    env.reset(seed=0)
    action = np.zeros(6, dtype=np.float32)
    action[3] = bad  # vessel 1, action entry 1 (heading)
    with pytest.raises(ValueError, match="finite") as err:
        env.step(action)
    # the message names the offending entry (formation 0, vessel 1, entry 1)
    assert "[0, 1, 1]" in str(err.value)


def test_rejected_action_does_not_advance_the_simulation():
    env = gymnasium.make(ENV_ID, action_level="speed")
    par = marine_formation_env.parallel_env(action_level="speed")
    env.reset(seed=0)
    par.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([0.0, np.nan, 0.0], dtype=np.float32))
    action = np.array([0.3, -0.2, 0.9], dtype=np.float32)
    obs, *_ = env.step(action)
    par_obs, *_ = par.step(split_joint_action(action, 3, 1))
    np.testing.assert_array_equal(obs, joint_of(par_obs, 3))


@pytest.mark.parametrize(
    ("level", "shape"),
    [("speed", (2,)), ("speed", (4,)), ("speed", (3, 1)), ("force", (3,)), ("force", (3, 2)), ("guidance", ())],
)
def test_wrong_action_shape_raises_value_error(level, shape):
    env = gymnasium.make(ENV_ID, action_level=level)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(shape, dtype=np.float32))


def test_step_after_episode_end_raises():
    env = gymnasium.make(ENV_ID, action_level="speed", horizon=1.5)  # 3 steps
    env.reset(seed=0)
    flags = [env.step(np.zeros(3, dtype=np.float32))[3] for _ in range(3)]
    assert flags == [False, False, True]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(3, dtype=np.float32))
    # reset makes it usable again
    env.reset()
    env.step(np.zeros(3, dtype=np.float32))


def test_step_before_reset_raises():
    env = MarineFormationGymEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(3, dtype=np.float32))


def test_unknown_override_is_rejected_by_make():
    with pytest.raises(marine_formation_env.ConfigError, match="no_such_key"):
        gymnasium.make(ENV_ID, no_such_key=1)


# --------------------------------------------------------------------------- PettingZoo registry


def test_parallel_env_in_pettingzoo_registry():
    import pettingzoo

    registry = getattr(pettingzoo, "parallel_registry", None)
    if registry is None:
        pytest.skip("this pettingzoo has no parallel registry")
    assert ENV_ID in registry
    env = pettingzoo.make("parallel", ENV_ID, n_vessels=4, topology="ring", action_level="force")
    assert isinstance(env, marine_formation_env.MarineFormationParallelEnv)
    assert env.possible_agents == [f"vessel_{j}" for j in range(4)]
    assert env.action_space("vessel_0").shape == (2,)
    obs, _ = env.reset(seed=0)
    assert obs["vessel_0"].shape == (obs_dim(4),)


@pytest.mark.parametrize("level", LEVELS)
def test_rollout_through_make_emits_no_warnings(level):
    env = gymnasium.make(ENV_ID, action_level=level, n_vessels=4, topology="ring", horizon=2.0)
    rng = np.random.default_rng(0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for episode in range(2):
            env.reset(seed=episode)
            done = False
            while not done:
                _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
                done = terminated or truncated
        env.close()
    assert [str(w.message) for w in caught] == []


def test_terminal_observation_is_clipped_into_the_space():
    # full yaw torque pushes |r| past max_yaw_rate: termination, and the last observation stays in bounds
    env = gymnasium.make(ENV_ID, action_level="force", horizon=20.0)
    env.reset(seed=0)
    action = np.tile(np.array([0.0, 1.0], dtype=np.float32), 3)
    for _ in range(200):
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert terminated and not truncated
    assert info["out_of_bounds"] is True
    assert env.observation_space.contains(obs)
    # the yaw-rate entries sit at the bound (|r| ≤ 1 rad/s by default)
    assert np.max(np.abs(obs[4 :: obs_dim(3)])) == pytest.approx(1.0)
