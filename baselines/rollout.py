"""Policies and the record of an episode.

A *policy* is any object with ``act(observations) -> actions`` over the
PettingZoo dicts; a ``BatchPolicy`` also acts on stacked observations
(``act_batch``), which lets the evaluation engine (``baselines.engine``)
run many episodes at once. ``Trajectory`` is what an episode leaves:
states, commands, actions and rewards as arrays
(``baselines.engine.run_episode`` records one).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

__all__ = ["BatchPolicy", "Policy", "RandomPolicy", "Trajectory"]


class Policy(Protocol):
    """What the evaluation engine (``baselines.engine``) needs of a policy."""

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]: ...


class BatchPolicy:
    """A policy defined on stacked observations: subclasses implement ``act_batch``.

    Every vessel acts from its own observation with the same function
    (parameter sharing), so a PettingZoo dict is stacked, acted on, and split.
    """

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Normalized actions ``(..., A)`` for observations ``(..., dim)``."""
        raise NotImplementedError

    def act(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Actions for a PettingZoo observation dict ``{agent: obs}``."""
        agents = list(observations)
        if not agents:
            return {}
        actions = self.act_batch(np.stack([observations[a] for a in agents]))
        return {agent: actions[k] for k, agent in enumerate(agents)}


@dataclass
class Trajectory:
    """One recorded episode (T control periods, n vessels).

    Attributes:
        t: ``(T+1,)`` times [s], starting at 0.
        state: ``(T+1, n, 6)`` vessel states (x, y, psi, u, v, r).
        u_d: ``(T+1,)`` desired speed u_d(t) [m/s].
        commanded_speed: ``(T, n)`` u_c [m/s] in force during each period (NaN if unknown).
        actions: ``(T, n, A)`` normalized actions as the env applied them (clipped).
        rewards: ``(T, n)``; components: name → ``(T, n)``.
        terminated, truncated, collision: how the episode ended.
        messages: the message counters of each step's control instant, info key
            (``messages_sent``, …, ``bits_sent``) → ``(T, n)`` (empty: not recorded).
    """

    t: np.ndarray
    state: np.ndarray
    u_d: np.ndarray
    commanded_speed: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    components: dict[str, np.ndarray] = field(default_factory=dict)
    terminated: bool = False
    truncated: bool = False
    collision: bool = False
    messages: dict[str, np.ndarray] = field(default_factory=dict)

    def to_npz_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Arrays for ``np.savez`` (``t``, ``state``, … with an optional key prefix)."""
        out = {
            "t": self.t,
            "state": self.state,
            "u_d": self.u_d,
            "commanded_speed": self.commanded_speed,
            "actions": self.actions,
            "rewards": self.rewards,
        }
        out.update({f"reward_{k}": v for k, v in self.components.items()})
        return {prefix + k: v for k, v in out.items()}


class RandomPolicy(BatchPolicy):
    """Uniform random actions in [−1, 1], seeded (a batch policy: one draw per vessel and step)."""

    def __init__(self, env: Any, seed: int | None = None) -> None:
        config = getattr(getattr(env, "unwrapped", env), "config", env)
        self.action_dim = int(config.action_dim)
        self.rng = np.random.default_rng(seed)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(..., A)`` drawn uniformly for observations ``(..., dim)``."""
        return self.rng.uniform(-1.0, 1.0, (*np.shape(obs)[:-1], self.action_dim)).astype(np.float32)
