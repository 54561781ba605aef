"""Run a policy in the ParallelEnv and record what happened, as arrays.

A *policy* is any object with ``act(observations) -> actions`` over the
PettingZoo dicts; if it also has ``commanded_speed(observations) -> {agent:
u_c}`` (the reference policy does), the commanded speeds are recorded even at
the ``force`` level, where the env never sees them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from marine_formation_env.env import MarineFormationParallelEnv

__all__ = ["BatchPolicy", "Policy", "RandomPolicy", "Trajectory", "run_episode"]


class Policy(Protocol):
    """What :func:`run_episode` needs of a policy."""

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]: ...


class BatchPolicy:
    """A policy defined on stacked observations: subclasses implement :meth:`act_batch`.

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


class RandomPolicy:
    """Uniform random actions from the env's action spaces, seeded."""

    def __init__(self, env: MarineFormationParallelEnv, seed: int | None = None) -> None:
        self.env = env
        self.rng = np.random.default_rng(seed)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        dim = self.env.config.action_dim
        return {a: self.rng.uniform(-1.0, 1.0, dim).astype(np.float32) for a in observations}


def run_episode(
    env: MarineFormationParallelEnv,
    policy: Any,
    seed: int | None = None,
    options: dict[str, Any] | None = None,
) -> Trajectory:
    """Roll out one episode of ``policy`` in ``env`` and record it.

    Args:
        env: a ParallelEnv of this package (not wrapped: the physical state is
            read from it for the record, never passed to the policy).
        policy: has ``act(observations)``; optionally ``commanded_speed``,
            and ``reset()``, called before the episode starts (stateful
            policies such as the reference with integral LOS).
        seed, options: passed to ``env.reset``.
    """
    cfg = env.config
    n, steps = cfg.n_vessels, cfg.max_steps
    obs, _ = env.reset(seed=seed, options=options)
    if callable(getattr(policy, "reset", None)):
        policy.reset()
    agents = list(env.possible_agents)
    states = np.empty((steps + 1, n, 6))
    times = np.empty(steps + 1)
    u_c = np.full((steps, n), np.nan)
    actions = np.zeros((steps, n, cfg.action_dim))
    rewards = np.zeros((steps, n))
    components: dict[str, np.ndarray] = {}
    states[0], times[0] = env.vessel_states, env.time
    speed_of = getattr(policy, "commanded_speed", None)
    k = 0
    terminated = truncated = collision = False
    while env.agents:
        act = policy.act(obs)
        if speed_of is not None:
            u_c[k] = [speed_of(obs)[a] for a in agents]
        obs, rew, term, trunc, infos = env.step(act)
        actions[k] = np.clip([np.asarray(act[a], dtype=float).reshape(-1) for a in agents], -1.0, 1.0)
        rewards[k] = [rew[a] for a in agents]
        for name in infos[agents[0]]["reward_components"]:
            components.setdefault(name, np.zeros((steps, n)))[k] = [infos[a]["reward_components"][name] for a in agents]
        if "commanded_speed" in infos[agents[0]]:
            u_c[k] = [infos[a]["commanded_speed"] for a in agents]
        k += 1
        states[k], times[k] = env.vessel_states, env.time
        terminated, truncated = any(term.values()), any(trunc.values())
        collision = bool(infos[agents[0]]["collision"])
    return Trajectory(
        t=times[: k + 1],
        state=states[: k + 1],
        u_d=np.asarray(cfg.u_d.value(times[: k + 1]), dtype=float),
        commanded_speed=u_c[:k],
        actions=actions[:k],
        rewards=rewards[:k],
        components={name: value[:k] for name, value in components.items()},
        terminated=terminated,
        truncated=truncated,
        collision=collision,
    )
