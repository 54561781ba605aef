"""The paper's controller as a policy over the masked per-agent observations.

:class:`ReferencePolicy` computes, for each vessel ``j`` and from ``j``'s own
observation only (never the global state):

* the coordination law (20): ``s_j = Σ_{i∈A_j} (θ_j − θ_i)`` from the link
  bits and relative coordination errors in the slots, ``u_cj = u_d − g(s_j)``
  and, for the force level, ``u̇_cj = u̇_d − g'(s_j)·Σ_{i∈A_j}(ẋ_j − ẋ_i)``;
* at ``speed``: the action that commands ``u_cj`` (the env's LOS path
  follower does the rest);
* at ``guidance``: ``(u_cj, ψ_LOS,j)`` with ψ_LOS from (12);
* at ``force``: the full surge (11) and yaw (12)-(14) laws, SPEC §3
  corrected (or as printed when the env has ``paper_as_printed=True``), held
  over the control period.

It needs the model parameters and gains (it is a model-based controller);
those come from the env's configuration, not from its state.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from baselines.rollout import BatchPolicy
from marine_formation_env.control import consensus_speed, los_angle, path_following_inputs
from marine_formation_env.core import ObservationLayout, normalized_actions
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["ReferencePolicy"]


class ReferencePolicy(BatchPolicy):
    """LOS path following (11)-(14) plus the nonlinear consensus law (20).

    Args:
        env: a ParallelEnv of this package, anything with a ``config``
            attribute (wrappers are unwrapped), or a :class:`ScenarioConfig`.

    Use :meth:`act` with a PettingZoo observation dict, or :meth:`act_batch`
    with an array of observations ``(..., obs_dim)``.
    """

    def __init__(self, env: Any) -> None:
        config = env if isinstance(env, ScenarioConfig) else getattr(getattr(env, "unwrapped", env), "config", None)
        if not isinstance(config, ScenarioConfig):
            raise TypeError(
                f"ReferencePolicy needs a marine_formation_env env or ScenarioConfig, got {type(env).__name__}"
            )
        self.config = config
        self.layout = ObservationLayout(config.n_vessels)

    def commands(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Physical commands for observations ``(..., obs_dim)``.

        Returns:
            ``{"u_c", "u_c_dot"}`` always, plus ``psi_d`` (guidance) or
            ``tau_u, tau_r`` (force); each of shape ``obs.shape[:-1]``.
        """
        cfg = self.config
        obs = np.asarray(obs, dtype=float)
        if obs.shape[-1:] != (self.layout.dim,):
            raise ValueError(f"observations must end in dimension {self.layout.dim}, got shape {obs.shape}")
        own, slots = self.layout.split(obs)
        linked = slots[..., 0]
        s = np.sum(linked * slots[..., 1], axis=-1)
        s_dot = np.sum(linked * slots[..., 2], axis=-1)
        e, psi, u, v, r, u_d, u_d_dot = (own[..., k] for k in range(7))
        u_c, u_c_dot = consensus_speed(s, s_dot, u_d, u_d_dot, cfg.gains.a)
        out = {"u_c": u_c, "u_c_dot": u_c_dot}
        if cfg.action_level == "guidance":
            out["psi_d"] = los_angle(e, cfg.gains.delta)
        elif cfg.action_level == "force":
            out["tau_u"], out["tau_r"] = path_following_inputs(
                cfg.params, cfg.gains, e, psi, u, v, r, u_c, u_c_dot, cfg.paper_as_printed
            )
        return out

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Normalized actions ``(..., A)`` for observations ``(..., obs_dim)``."""
        cmd = self.commands(obs)
        keys = {"force": ("tau_u", "tau_r"), "guidance": ("u_c", "psi_d"), "speed": ("u_c",)}
        chosen = {k: cmd[k] for k in keys[self.config.action_level]}
        return normalized_actions(self.config, **chosen).astype(np.float32)

    def commanded_speed(self, observations: Mapping[str, np.ndarray]) -> dict[str, float]:
        """The consensus command u_c [m/s] each agent's observation implies."""
        agents = list(observations)
        if not agents:
            return {}
        u_c = self.commands(np.stack([observations[a] for a in agents]))["u_c"]
        return {agent: float(u_c[k]) for k, agent in enumerate(agents)}

    def __call__(self, observations: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return self.act(observations)
