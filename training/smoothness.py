"""Temporal action smoothness for SB3's PPO: the temporal term of CAPS.

CAPS (Mysore, Mabsout, Mancuso and Saenko, "Regularizing Action Policies for
Smooth Control with Reinforcement Learning", ICRA 2021) adds to the policy's
loss the distance between its actions at consecutive states. :class:`SmoothPPO`
is SB3's PPO with that term as the hyperparameter ``temporal_smoothness``
(λ ≥ 0, default 0: exactly PPO). After each PPO update it makes one more
pass over the rollout, in minibatches of ``batch_size``, minimizing

    λ · mean over consecutive pairs (o_t, o_{t+1}) of mean_k |μ_k(o_{t+1}) − μ_k(o_t)|

where μ is the Gaussian's mean (the deterministic action, before clipping)
and the pairs are those of one env entry within one episode. The distance is
the one the benchmark's Δa column measures, on the noise-free action.

Unlike a cost on action changes in the learner's reward
(:class:`training.vec_env.ActionChangePenalty`, which sees the sampled and
clipped actions), this term does not charge the exploration noise and gives
nothing for holding an action beyond the bounds of the action space; the
reward, the returns the run logs and every evaluation are unchanged. It is
a separate gradient step after PPO's epochs, not a term of PPO's clipped
loss as in the paper. The run's TensorBoard gets
``train/temporal_smoothness_loss`` (the distance before the step, without λ).

:func:`smoothness_pass` is the pass itself, for any policy whose mean is a
differentiable function of the observation; the TorchRL trainer
(``training.torchrl_ppo``, key ``temporal_smoothness``) calls it too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer

__all__ = ["SmoothPPO", "consecutive_pairs", "smoothness_pass"]


def consecutive_pairs(buffer: RolloutBuffer) -> tuple[np.ndarray, np.ndarray]:
    """The observations ``(o_t, o_{t+1})`` of one entry within one episode, from a full rollout buffer.

    Read before the buffer is sampled (SB3 flattens it then). ``episode_starts[t + 1]``
    is 1 when ``o_{t+1}`` opens a new episode, so such a pair is left out; the pair across
    the rollout's end is left out too (its second observation is not in the buffer).
    """
    if buffer.generator_ready:
        raise RuntimeError("consecutive_pairs needs the rollout buffer before it is sampled")
    obs = np.asarray(buffer.observations)
    if obs.ndim < 3:
        raise ValueError(f"expected observations of shape (n_steps, n_envs, ...), got {obs.shape}")
    same_episode = np.asarray(buffer.episode_starts)[1:] == 0  # (n_steps − 1, n_envs)
    return obs[:-1][same_episode], obs[1:][same_episode]


class SmoothPPO(PPO):
    """SB3's PPO with CAPS' temporal smoothness term (module docstring).

    Args:
        temporal_smoothness: λ ≥ 0, the weight of the term; 0 (the default) is PPO.
        *args, **kwargs: PPO's.
    """

    def __init__(self, *args: Any, temporal_smoothness: float = 0.0, **kwargs: Any) -> None:
        value = temporal_smoothness
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (np.isfinite(value) and value >= 0):
            raise ValueError(f"temporal_smoothness must be a number >= 0, got {value!r}")
        self.temporal_smoothness = float(value)
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        """PPO's update, then (λ > 0) one pass of the smoothness term over the same rollout."""
        pairs = consecutive_pairs(self.rollout_buffer) if self.temporal_smoothness > 0 else None
        super().train()
        if pairs is not None and len(pairs[0]):
            self.logger.record("train/temporal_smoothness_loss", self._smoothness_pass(*pairs))

    def _smoothness_pass(self, before: np.ndarray, after: np.ndarray) -> float:
        """One pass in minibatches of ``batch_size``; the mean distance before each step."""
        policy = self.policy
        policy.set_training_mode(True)
        rng = np.random.default_rng([self.seed or 0, self._n_updates])  # reproducible with the run's seed
        first, second = (torch.as_tensor(side, device=self.device) for side in (before, after))
        distance = smoothness_pass(
            self._mean_action, first, second, self.temporal_smoothness, self.batch_size,
            policy.optimizer, policy.parameters(), self.max_grad_norm, rng,
        )  # fmt: skip
        policy.set_training_mode(False)
        return distance

    def _mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean for a batch of observations (with gradients)."""
        dist = self.policy.get_distribution(obs).distribution
        if not isinstance(dist, torch.distributions.Normal):
            raise TypeError(f"temporal_smoothness needs a Gaussian policy (Box actions), got {type(dist).__name__}")
        return dist.mean


def smoothness_pass(
    mean: Callable[[torch.Tensor], torch.Tensor],
    before: torch.Tensor,
    after: torch.Tensor,
    weight: float,
    batch_size: int,
    optimizer: torch.optim.Optimizer,
    parameters: Iterable[torch.nn.Parameter],
    max_grad_norm: float,
    rng: np.random.Generator,
) -> float:
    """One pass of ``weight · mean |mean(after) − mean(before)|`` over the pairs, in shuffled minibatches.

    ``before[i]`` and ``after[i]`` are consecutive observations of one agent in one episode (any trailing
    shape ``mean`` takes); each minibatch of ``batch_size`` pairs is one step of ``optimizer`` with the
    gradient norm of ``parameters`` clipped to ``max_grad_norm``, as the PPO steps before it. Returns the
    mean over minibatches of the distance before each step (without the weight).
    """
    if len(before) != len(after):
        raise ValueError(f"before and after hold {len(before)} and {len(after)} observations; pairs need as many")
    parameters = list(parameters)
    order = torch.as_tensor(rng.permutation(len(before)), device=before.device)
    distances = []
    for start in range(0, len(order), batch_size):
        batch = order[start : start + batch_size]
        distance = torch.mean(torch.abs(mean(after[batch]) - mean(before[batch])))
        optimizer.zero_grad()
        (weight * distance).backward()
        torch.nn.utils.clip_grad_norm_(parameters, max_grad_norm)
        optimizer.step()
        distances.append(float(distance.detach()))
    return float(np.mean(distances)) if distances else float("nan")
