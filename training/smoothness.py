"""Temporal action smoothness for PPO: the temporal term of CAPS, inside PPO's loss.

CAPS (Mysore, Mabsout, Mancuso and Saenko, "Regularizing Action Policies for
Smooth Control with Reinforcement Learning", ICRA 2021) adds to the policy's
loss the distance between its actions at consecutive states. ``SmoothPPO``
is SB3's PPO with that term as the hyperparameter ``temporal_smoothness``
(λ ≥ 0, default 0: exactly PPO). Every minibatch step of PPO's epochs
minimizes PPO's loss plus

    λ · mean over a minibatch of consecutive pairs (o_t, o_{t+1}) of mean_k |μ_k(o_{t+1}) − μ_k(o_t)|

where μ is the Gaussian's mean (the deterministic action, before clipping)
and the pairs are those of one env entry within one episode of the rollout,
``temporal_smoothness_pairs`` of them per step (default: ``batch_size``),
drawn in a shuffled order that runs through every pair before it repeats
one. The distance is the one the benchmark's Δa column measures, on the
noise-free action. Both terms share one backward pass, one gradient
clipping and one optimizer step, so λ weighs the term against PPO's own
gradient.

Unlike a cost on action changes in the learner's reward, this term does not
charge the exploration noise and gives nothing for holding an action beyond
the bounds of the action space; the reward, the returns the run logs and
every evaluation are unchanged. The
run's TensorBoard gets ``train/temporal_smoothness_loss`` (the mean distance
over the update's steps, without λ).

The term is part of PPO's loss, not a separate pass of optimizer steps:
Adam normalizes each parameter's step by the running size of its gradients,
so the weight of a loss stepped on its own would barely set the size of the
step.

``SmoothnessTerm`` is the term itself, for any policy whose mean is a
differentiable function of the observation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer

__all__ = ["SmoothPPO", "SmoothnessTerm", "consecutive_pairs"]


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


class SmoothnessTerm:
    """``weight · mean |mean(after) − mean(before)|`` on the next minibatch of pairs, at each call.

    ``before[i]`` and ``after[i]`` are consecutive observations of one agent in one episode (any
    trailing shape ``mean`` takes). Each call takes the next ``batch_size`` pairs of a shuffled
    order (``rng``), reshuffling once every pair has been used, and returns the weighted distance
    as a tensor with gradients, to be added to the loss of one optimizer step.
    ``distances`` lists the distance of each call, without the weight; ``mean_distance`` is
    their mean.
    """

    def __init__(
        self,
        mean: Callable[[torch.Tensor], torch.Tensor],
        before: torch.Tensor,
        after: torch.Tensor,
        weight: float,
        batch_size: int,
        rng: np.random.Generator,
    ) -> None:
        if len(before) != len(after):
            raise ValueError(f"before and after hold {len(before)} and {len(after)} observations; pairs need as many")
        if len(before) == 0:
            raise ValueError("the smoothness term needs at least one pair of consecutive observations")
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.mean, self.before, self.after = mean, before, after
        self.weight, self.batch_size, self.rng = float(weight), int(batch_size), rng
        self._order = torch.empty(0, dtype=torch.long)
        self.distances: list[float] = []  # one per call, without the weight

    def __call__(self) -> torch.Tensor:
        if len(self._order) == 0:
            self._order = torch.as_tensor(self.rng.permutation(len(self.before)), device=self.before.device)
        batch, self._order = self._order[: self.batch_size], self._order[self.batch_size :]
        distance = torch.mean(torch.abs(self.mean(self.after[batch]) - self.mean(self.before[batch])))
        self.distances.append(float(distance.detach()))
        return self.weight * distance

    @property
    def mean_distance(self) -> float:
        """The mean distance (without the weight) over the calls so far; NaN before the first."""
        return float(np.mean(self.distances)) if self.distances else float("nan")


class SmoothPPO(PPO):
    """SB3's PPO with CAPS' temporal smoothness term in its loss (module docstring).

    Args:
        temporal_smoothness: λ ≥ 0, the weight of the term; 0 (the default) is PPO.
        temporal_smoothness_pairs: how many pairs of consecutive observations each optimizer step
            draws for the term; ``None`` (the default): ``batch_size``, as many as PPO's minibatch.
            The term runs the policy on both observations of each pair, so with as many pairs
            as the minibatch it costs about twice PPO's own forward and backward pass; fewer
            pairs make it cheaper in wall-clock time, with a noisier estimate of the same term.
        *args, **kwargs: PPO's.
    """

    def __init__(
        self,
        *args: Any,
        temporal_smoothness: float = 0.0,
        temporal_smoothness_pairs: int | None = None,
        **kwargs: Any,
    ) -> None:
        value = temporal_smoothness
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (np.isfinite(value) and value >= 0):
            raise ValueError(f"temporal_smoothness must be a number >= 0, got {value!r}")
        pairs = temporal_smoothness_pairs
        if pairs is not None and (isinstance(pairs, bool) or not isinstance(pairs, int) or pairs < 1):
            raise ValueError(f"temporal_smoothness_pairs must be a whole number >= 1 or None, got {pairs!r}")
        self.temporal_smoothness = float(value)
        self.temporal_smoothness_pairs = pairs
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        """PPO's update; with λ > 0 each of its optimizer steps also descends the smoothness term.

        SB3's ``PPO.train`` zeroes the optimizer's gradients right before the backward pass of each
        minibatch's loss, then clips and steps. For the length of this update the optimizer's
        ``zero_grad`` is followed by the backward pass of the term on the next minibatch of pairs,
        so its gradient adds to PPO's before the one clipping and the one step.
        """
        if self.temporal_smoothness == 0:
            super().train()
            return
        before, after = (torch.as_tensor(side, device=self.device) for side in consecutive_pairs(self.rollout_buffer))
        if len(before) == 0:  # every entry's episode restarted at every step: nothing to pull together
            super().train()
            return
        rng = np.random.default_rng([self.seed or 0, self._n_updates])  # reproducible with the run's seed
        pairs = self.temporal_smoothness_pairs or self.batch_size
        term = SmoothnessTerm(self._mean_action, before, after, self.temporal_smoothness, pairs, rng)
        optimizer = self.policy.optimizer
        zero_grad = optimizer.zero_grad

        def zero_grad_then_add_the_term(set_to_none: bool = True) -> None:
            zero_grad(set_to_none=set_to_none)
            term().backward()

        optimizer.zero_grad = zero_grad_then_add_the_term  # type: ignore[method-assign]
        try:
            super().train()
        finally:
            del optimizer.zero_grad  # the instance attribute: the class's method again
        self.logger.record("train/temporal_smoothness_loss", term.mean_distance)

    def _mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean for a batch of observations (with gradients)."""
        dist = self.policy.get_distribution(obs).distribution
        if not isinstance(dist, torch.distributions.Normal):
            raise TypeError(f"temporal_smoothness needs a Gaussian policy (Box actions), got {type(dist).__name__}")
        return dist.mean
