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
from training.smoothness import SmoothnessTerm, SmoothPPO, consecutive_pairs

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

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


def _adam_steps(model: PPO) -> int:
    """How many steps the policy's Adam optimizer has taken (its per-parameter step counter)."""
    return int(next(iter(model.policy.optimizer.state.values()))["step"])


def test_the_term_makes_the_mean_action_smoother_in_proportion_to_its_weight() -> None:
    runs = {weight: SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=weight, **PPO_KW).learn(2048)
            for weight in (0.0, 0.01, 1.0)}  # fmt: skip
    change = {weight: _mean_action_change(model) for weight, model in runs.items()}
    # measured on an AMD EPYC: 0.045 without the term, 0.020 with λ = 0.01, 0.0008 with λ = 1; the factors leave
    # room for other CPUs
    assert change[1.0] < 0.25 * change[0.0]
    # in PPO's loss the weight sets how hard the term pulls against PPO's gradient (a separate Adam step would not)
    assert change[1.0] < 0.5 * change[0.01]
    assert runs[1.0].logger.name_to_value["train/temporal_smoothness_loss"] > 0.0
    # the term rides on PPO's steps: as many optimizer steps as PPO (8 rollouts × 4 epochs × 4 minibatches)
    assert _adam_steps(runs[1.0]) == _adam_steps(runs[0.0]) == 8 * 4 * 4


def test_the_optimizer_is_plain_again_after_an_update_even_a_failing_one() -> None:
    model = SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=1.0, **PPO_KW).learn(256)
    optimizer = model.policy.optimizer
    assert "zero_grad" not in vars(optimizer)  # the hook is gone: zero_grad is Adam's own again
    model._mean_action = lambda obs: (_ for _ in ()).throw(RuntimeError("boom"))  # the term fails mid-update
    with pytest.raises(RuntimeError, match="boom"):
        model.learn(256)
    assert "zero_grad" not in vars(optimizer)


def test_the_term_moves_only_the_mean_s_path() -> None:
    model = SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=1.0, **PPO_KW)
    before, after = (torch.as_tensor(np.random.default_rng(k).normal(size=(512, 3)), dtype=torch.float32)
                     for k in (0, 1))  # fmt: skip
    term = SmoothnessTerm(model._mean_action, before, after, 1.0, 64, np.random.default_rng(0))
    model.policy.optimizer.zero_grad()
    term().backward()
    # the value head and the Gaussian's log-std get no gradient from it; the action head does
    assert all(p.grad is None or not p.grad.any() for p in model.policy.value_net.parameters())
    assert model.policy.log_std.grad is None or not model.policy.log_std.grad.any()
    assert model.policy.action_net.weight.grad.abs().sum() > 0


def test_the_term_runs_through_every_pair_before_it_repeats_one() -> None:
    seen: list[float] = []

    def mean(obs: torch.Tensor) -> torch.Tensor:
        seen.extend(obs[:, 0].tolist())
        return obs

    before = torch.arange(10.0).reshape(10, 1)
    term = SmoothnessTerm(mean, before, before + 100.5, 2.0, 4, np.random.default_rng(0))
    values = [float(term()) for _ in range(3)]  # minibatches of 4, 4 and the last 2 pairs
    assert values == pytest.approx([201.0] * 3)  # λ · mean |100.5|
    firsts = sorted(x for x in seen if x < 100)
    assert firsts == list(range(10))  # each pair once
    assert sorted(x - 100.5 for x in seen if x >= 100) == firsts  # each with its own partner
    term()
    assert len(seen) == 2 * (10 + 4)  # then a new shuffle of all ten
    assert term.mean_distance == pytest.approx(100.5)


@pytest.mark.parametrize(("pairs", "expected"), [(None, 64), (16, 16)])
def test_each_step_draws_temporal_smoothness_pairs_pairs(pairs, expected) -> None:
    model = SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=1.0, temporal_smoothness_pairs=pairs, **PPO_KW)
    sizes: list[int] = []
    mean_action = model._mean_action
    model._mean_action = lambda obs: (sizes.append(len(obs)), mean_action(obs))[1]
    model.learn(256)  # one rollout of 256 steps, 255 pairs (one episode of 200 steps ends inside: 254)
    assert max(sizes) == expected
    # every call runs both sides of a pair batch; 4 epochs × 4 minibatches of PPO's, one batch of pairs each
    assert len(sizes) == 2 * 4 * 4
    assert all(size == expected for size in sizes[: 2 * (254 // expected)])


@pytest.mark.parametrize("pairs", [0, -1, 2.5, True, "16"])
def test_a_bad_pair_count_is_refused_by_name(pairs: object) -> None:
    message = f"temporal_smoothness_pairs must be a whole number >= 1 or None, got {pairs!r}"
    with pytest.raises(ValueError, match=message):
        SmoothPPO("MlpPolicy", "Pendulum-v1", temporal_smoothness=1.0, temporal_smoothness_pairs=pairs, device="cpu")
    with pytest.raises(TrainConfigError, match="temporal_smoothness_pairs must be a whole number ≥ 1"):
        validate({"algo": "ppo", "scenario": "paper", "temporal_smoothness_pairs": pairs})


@pytest.mark.parametrize(("before", "after", "batch", "message"), [
    (torch.zeros(3, 1), torch.zeros(2, 1), 2, "pairs need as many"),
    (torch.zeros(0, 1), torch.zeros(0, 1), 2, "at least one pair"),
    (torch.zeros(3, 1), torch.zeros(3, 1), 0, "batch_size must be >= 1, got 0"),
])  # fmt: skip
def test_a_term_without_pairs_is_refused(before, after, batch, message) -> None:
    with pytest.raises(ValueError, match=message):
        SmoothnessTerm(lambda obs: obs, before, after, 1.0, batch, np.random.default_rng(0))


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
