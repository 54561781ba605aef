"""CAPS' temporal smoothness term on SB3's PPO (training.smoothness)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer

from training.config import TrainConfigError, validate
from training.smoothness import SmoothPPO, consecutive_pairs

PPO_KW = {"n_steps": 256, "batch_size": 64, "n_epochs": 4, "seed": 0, "device": "cpu", "learning_rate": 1e-3}


def test_pairs_stay_within_one_entry_and_one_episode() -> None:
    buffer = RolloutBuffer(4, spaces.Box(-np.inf, np.inf, (1,)), spaces.Box(-1, 1, (1,)), device="cpu", n_envs=2)
    starts = {(0, 0), (0, 1), (2, 1)}  # entry 1 starts a new episode at step 2
    for t in range(4):
        obs = np.array([[10.0 * t], [10.0 * t + 1]], dtype=np.float32)  # 10·t + entry
        episode_start = np.array([(t, e) in starts for e in range(2)])
        buffer.add(obs, np.zeros((2, 1)), np.zeros(2), episode_start, torch.zeros(2), torch.zeros(2))
    before, after = consecutive_pairs(buffer)
    got = sorted(zip(before[:, 0].tolist(), after[:, 0].tolist(), strict=True))
    # entry 0: (0,10), (10,20), (20,30); entry 1: (1,11), not (11,21) across its reset, (21,31)
    assert got == [(0.0, 10.0), (1.0, 11.0), (10.0, 20.0), (20.0, 30.0), (21.0, 31.0)]
    buffer.get(batch_size=2).__next__()  # sampling flattens the buffer: no longer readable in time order
    with pytest.raises(RuntimeError, match="before it is sampled"):
        consecutive_pairs(buffer)


def test_weight_zero_is_ppo_itself() -> None:
    ppo = PPO("MlpPolicy", "Pendulum-v1", **PPO_KW).learn(512)
    smooth = SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=0.0, **PPO_KW).learn(512)
    # the same seed on the same machine: the same updates, bit for bit
    assert all(torch.equal(p, q) for p, q in zip(ppo.policy.parameters(), smooth.policy.parameters(), strict=True))


def _mean_action_change(model: PPO) -> float:
    """Mean |μ(o_{t+1}) − μ(o_t)| along one fixed Pendulum trajectory (random actions, seed 123)."""
    env = gym.make("Pendulum-v1")
    obs, _ = env.reset(seed=123)
    env.action_space.seed(123)
    trajectory = []
    for _ in range(200):
        trajectory.append(obs)
        obs, *_ = env.step(env.action_space.sample())
    with torch.no_grad():
        dist = model.policy.get_distribution(torch.as_tensor(np.array(trajectory), dtype=torch.float32))
        mean = dist.distribution.mean.numpy()
    return float(np.mean(np.abs(np.diff(mean, axis=0))))


def test_the_term_makes_the_mean_action_smoother_and_leaves_the_critic_and_noise_to_ppo() -> None:
    plain = SmoothPPO("MlpPolicy", "Pendulum-v1", **PPO_KW).learn(2048)
    smooth = SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=1.0, **PPO_KW).learn(2048)
    # measured on this machine: 0.045 without the term, 0.0017 with λ = 1; a factor 4 leaves room for other CPUs
    assert _mean_action_change(smooth) < 0.25 * _mean_action_change(plain)
    assert smooth.logger.name_to_value.get("train/temporal_smoothness_loss", 0.0) >= 0.0
    # the pass itself touches only the mean's path: the value head and the Gaussian's log-std keep their values
    before, after = (np.random.default_rng(0).normal(size=(512, 3)).astype(np.float32) for _ in range(2))
    value_head = [p.detach().clone() for p in smooth.policy.value_net.parameters()]
    log_std = smooth.policy.log_std.detach().clone()
    action_head = smooth.policy.action_net.weight.detach().clone()
    smooth._smoothness_pass(before, after)
    assert all(torch.equal(p, q) for p, q in zip(value_head, smooth.policy.value_net.parameters(), strict=True))
    assert torch.equal(log_std, smooth.policy.log_std)
    assert not torch.equal(action_head, smooth.policy.action_net.weight)


@pytest.mark.parametrize("value", [-0.1, float("nan"), "0.5", True])
def test_a_bad_weight_is_refused_by_name(value: object) -> None:
    config = {"algo": "ppo", "scenario": "paper", "temporal_smoothness": value}
    with pytest.raises(TrainConfigError, match="temporal_smoothness"):
        validate(config)
    with pytest.raises(ValueError, match="temporal_smoothness must be a number >= 0"):
        SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=value, device="cpu")


def test_the_weight_is_a_ppo_hyperparameter_only() -> None:
    assert validate({"algo": "ppo", "scenario": "paper", "temporal_smoothness": 0.5})["temporal_smoothness"] == 0.5
    with pytest.raises(TrainConfigError, match=r"unknown key\(s\) \['temporal_smoothness'\] for algo 'sac'"):
        validate({"algo": "sac", "scenario": "paper", "temporal_smoothness": 0.5})
