"""The evaluation engine runs many seeds as one batch and records what a ParallelEnv loop records.

The truth here is the plain PettingZoo loop (reset with the seed, step until
the agents are gone), written out in this file. Same backend, same machine:
the batch of B formations and the B single-formation runs do the same
arithmetic per formation, but numpy's vectorized transcendental functions may
round an element differently depending on where it falls in an array, so
states are compared to 1e-12 relative (the closed loop does not amplify a
last-bit difference beyond that over an episode; see tests/test_backends.py).
"""

from __future__ import annotations

import numpy as np
import pytest

import marine_formation_env
from baselines import ReferencePolicy
from baselines.engine import episode_reports, evaluate_episodes, run_episode
from baselines.metrics import episode_metrics
from baselines.rollout import RandomPolicy


def parallel_loop(env, policy, seed):
    """States, rewards and how the episode ended, from the PettingZoo API alone."""
    obs, _ = env.reset(seed=seed)
    if callable(getattr(policy, "reset", None)):
        policy.reset()
    states, rewards, infos = [env.vessel_states], [], {}
    term = trunc = {}
    while env.agents:
        obs, rew, term, trunc, infos = env.step(policy.act(obs))
        states.append(env.vessel_states)
        rewards.append([rew[a] for a in env.possible_agents])
    first = env.possible_agents[0]
    return np.array(states), np.array(rewards), term[first], trunc[first], infos[first]["collision"]


def assert_same_episode(traj, states, rewards, term, trunc):
    assert traj.state.shape == states.shape
    scale = np.maximum(np.abs(states), 1.0)
    assert np.max(np.abs(traj.state - states) / scale) <= 1e-12
    np.testing.assert_allclose(traj.rewards, rewards, rtol=0, atol=1e-12)
    assert (traj.terminated, traj.truncated) == (term, trunc)
    dt = traj.t[1] - traj.t[0]
    np.testing.assert_allclose(traj.t, dt * np.arange(len(states)), rtol=1e-12)


class FullThrottle:
    """A PettingZoo-dict policy (no act_batch): full surge ahead until |u| passes max_speed and the episode ends."""

    def act(self, observations):
        return {agent: np.array([1.0, 0.0], dtype=np.float32) for agent in observations}


def test_batched_reference_episodes_equal_parallel_env_episodes():
    env = marine_formation_env.parallel_env("paper", init_noise={"x": 30.0, "y": 15.0, "psi": 0.2}, horizon=60.0)
    seeds = [3, 11, 12, 40]
    trajectories = evaluate_episodes(ReferencePolicy(env), env.config, seeds)
    assert len(trajectories) == len(seeds)
    for seed, traj in zip(seeds, trajectories, strict=True):
        states, rewards, term, trunc, _ = parallel_loop(env, ReferencePolicy(env), seed)
        assert_same_episode(traj, states, rewards, term, trunc)
        assert traj.truncated and len(traj.t) == env.config.max_steps + 1


def test_episodes_that_end_at_different_steps_are_cut_where_they_ended():
    # initial surge 3 ± 2 m/s: the time to accelerate past max_speed = 14 m/s differs by seed
    overrides = {"action_level": "force", "init_noise": {"u": 2.0, "x": 20.0}, "horizon": 30.0}
    env = marine_formation_env.parallel_env("paper", **overrides)
    seeds = [0, 1, 2, 3, 4]
    trajectories = evaluate_episodes(FullThrottle(), env.config, seeds)
    lengths = {len(traj.t) for traj in trajectories}
    assert len(lengths) > 1, "the case must end episodes at different steps"
    for seed, traj in zip(seeds, trajectories, strict=True):
        states, rewards, term, trunc, collision = parallel_loop(env, FullThrottle(), seed)
        assert term and not trunc  # |u| beyond max_speed: out of the envelope
        assert_same_episode(traj, states, rewards, term, trunc)
        assert traj.collision == collision
        assert traj.actions.shape == (len(traj.t) - 1, 3, 2)


def test_commanded_speed_is_recorded_at_the_force_level_from_the_reference():
    env = marine_formation_env.parallel_env("paper", action_level="force", horizon=5.0)
    policy = ReferencePolicy(env)
    traj = evaluate_episodes(policy, env.config, [0])[0]
    obs, _ = env.reset(seed=0)
    expected = policy.commanded_speed(obs)
    np.testing.assert_allclose(traj.commanded_speed[0], [expected[a] for a in env.possible_agents], rtol=1e-12)
    assert np.all(np.isfinite(traj.commanded_speed))


def test_run_episode_and_episode_reports_are_views_of_the_engine():
    env = marine_formation_env.parallel_env("acoustic", horizon=40.0)
    policy = ReferencePolicy(env, extrapolate=True)
    metrics, trajectories = episode_reports(policy, env.config, [5, 6])
    single = run_episode(env, policy, seed=6)
    np.testing.assert_array_equal(single.state, trajectories[1].state)  # one formation: the same code path
    assert metrics[1]["seed"] == 6
    assert metrics[1]["return"] == pytest.approx(episode_metrics(single, env.config)["return"], rel=1e-12)


def test_random_policy_is_seeded_and_inside_the_box():
    env = marine_formation_env.parallel_env("paper", action_level="guidance", horizon=3.0)
    a = evaluate_episodes(RandomPolicy(env, seed=1), env.config, [0, 1])
    b = evaluate_episodes(RandomPolicy(env, seed=1), env.config, [0, 1])
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.actions, y.actions)
        assert np.all(np.abs(x.actions) <= 1.0)
    assert not np.array_equal(a[0].actions, a[1].actions)


def test_no_seed_is_an_error():
    env = marine_formation_env.parallel_env("paper")
    with pytest.raises(ValueError, match="at least one seed"):
        evaluate_episodes(ReferencePolicy(env), env.config, [])
