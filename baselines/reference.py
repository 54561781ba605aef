"""The paper's controller as a policy over the masked per-agent observations.

``ReferencePolicy`` computes, for each vessel ``j`` and from ``j``'s own
observation only (never the global state):

* the coordination law (20): ``s_j = Σ_{i∈A_j} (θ_j − θ_i)`` from the link
  bits and relative coordination errors in the slots, ``u_cj = u_d − g(s_j)``
  and, for the force level, ``u̇_cj = u̇_d − g'(s_j)·Σ_{i∈A_j}(ẋ_j − ẋ_i)``;
  on a curved path (docs/paths.md) ``θ = ℓ − D_x``, ``ẋ`` is ``ℓ̇``, and
  ``u_cj`` is the lane's surge command ``(1 − κ·D_yj)·(u_d − g(s_j))`` with κ
  and D_yj from the observation;
* at ``speed``: the action that commands ``u_cj`` (the env's LOS path
  follower does the rest);
* at ``guidance``: ``(u_cj, ψ_LOS,j)`` with ψ_LOS from (12) (on a curved path
  relative to the path, ``−atan(e/Δ)``, as the level's heading command is);
* at ``force``: the full surge (11) and yaw (12)-(14) laws, docs/model.md §3
  corrected (or as printed when the env has ``paper_as_printed=True``), held
  over the control period.

It needs the model parameters and gains (it is a model-based controller);
those come from the env's configuration, not from its state.

Two options go beyond the paper (our extensions, off by default):

* ``extrapolate=True``: over a non-ideal channel a slot holds vessel i's
  position as it was when the message was sent, ``age`` seconds ago, while j's
  own position is current, so ``Δθ`` is off by about ``ẋ_i·age`` (7.5 m for a
  1.5 s old message at 5 m/s). The option predicts i's position now from the
  received velocity: ``Δθ ← Δθ − ẋ_i(t_s)·age`` with
  ``ẋ_i(t_s) = ẋ_j − Δẋ`` and ``ẋ_j = u cos ψ − v sin ψ`` from j's own
  observation (through the water: an along-path current V_x biases the
  prediction by ``V_x·age``).
* ``integral_los=σ`` (σ > 0, in m/s): integral LOS (Børhaug, Pavlov and
  Pettersen, CDC 2008) instead of (12): ``ψ_d = −atan((e + σ·e_int)/Δ)`` with
  ``ė_int = Δ·e/((e + σ·e_int)² + Δ²)``, integrated once per control period.
  With an unknown constant current it drives the cross-track error to zero,
  where plain LOS settles off the path. The policy steers only at the
  ``guidance`` and ``force`` levels, so the option needs one of those; at
  ``speed`` the env's built-in LOS steers, and the scenario's
  ``los_integral_gain`` makes it integral LOS. At ``force`` the ILOS angle
  replaces ψ_LOS in (14); its feed-forward omits the integrator's slow
  contribution σ·ė_int. The integrators are state: call ``reset`` at
  every episode start (``run_episode`` does).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from baselines.rollout import BatchPolicy
from marine_formation_env.actions import LEVEL_COMMANDS, normalized_actions
from marine_formation_env.control import (
    consensus_speed,
    curved_path_following_inputs,
    integral_los_rate,
    lane_speed,
    los_angle,
    path_following_inputs,
    turn_crab,
)
from marine_formation_env.observations import ObservationLayout
from marine_formation_env.rules import (
    AGE,
    COORDINATION,
    CROSS_TRACK,
    CURVATURE,
    HEADING,
    LANE_OFFSET,
    LINK,
    OWN_SIZE,
    SLOT_SIZE,
    SURGE,
    SWAY,
    VELOCITY,
)
from marine_formation_env.scenarios import ScenarioConfig

__all__ = [
    "ReferencePolicy",
    "coordination_gap",
    "own_path_rate",
    "predicted_coordination_error",
    "rule_broadcasting",
]


def rule_broadcasting(config: ScenarioConfig) -> ScenarioConfig:
    """``config`` for the reference beside a policy that decides when to broadcast: ``transmit`` off, so the
    channel's rule (periodic, or event-triggered) decides (the reference sends no ``transmit`` entry)."""
    return dataclasses.replace(config, transmit=False) if config.transmit else config


def own_path_rate(own: np.ndarray) -> np.ndarray:
    """Each vessel's own along-path rate from the own parts ``(..., 10)`` of its observation: the speed of its
    projection, ``ℓ̇ = (u cos ψ − v sin ψ)/(1 − κ·(D_y + e))`` (``ẋ`` on the straight path). Returns ``(...)``."""
    e, psi, u, v, kappa, d_y = (own[..., k] for k in (CROSS_TRACK, HEADING, SURGE, SWAY, CURVATURE, LANE_OFFSET))
    return np.asarray((u * np.cos(psi) - v * np.sin(psi)) / (1.0 - kappa * (d_y + e)))


def predicted_coordination_error(own: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Each slot's Δθ with the neighbour's position predicted to now from its message (``extrapolate=True``).

    ``own``: the own parts ``(..., 10)``; ``slots``: ``(..., K, 4)``. A slot holds vessel i's position as it
    was ``age`` seconds ago, so ``Δθ − ẋ_i·age`` with ``ẋ_i = ẋ_j − Δẋ`` and vessel j's own along-path rate
    ``ẋ_j`` (``own_path_rate``); exact while i's speed holds, unchanged at age 0 (an ideal link). Returns
    ``(..., K)``.
    """
    x_dot_own = own_path_rate(own)
    return np.asarray(slots[..., COORDINATION] - (x_dot_own[..., None] - slots[..., VELOCITY]) * slots[..., AGE])


def coordination_gap(own: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """The largest coordination error ``|θ_j − θ_i|`` over the linked slots, each predicted to now from its
    message's age (``predicted_coordination_error``); 0 without a linked slot. ``own`` ``(..., 10)``, ``slots``
    ``(..., K, 4)``; returns ``(...)``."""
    linked = slots[..., LINK] > 0.5
    return np.asarray(np.max(np.where(linked, np.abs(predicted_coordination_error(own, slots)), 0.0), axis=-1))


class ReferencePolicy(BatchPolicy):
    """LOS path following (11)-(14) plus the nonlinear consensus law (20).

    Args:
        env: a ParallelEnv of this package, anything with a ``config``
            attribute (wrappers are unwrapped), or a ``ScenarioConfig``.
        extrapolate: predict each neighbour's position now from its last
            message's velocity and age (module docstring).
        integral_los: σ > 0 [m/s] to steer with integral LOS (module
            docstring; ``guidance`` and ``force`` levels); None: the paper's LOS.
        any_team: read observations of any length, as a slot network does: the
            slot count is taken from each observation (own part, then slots, no
            ``transmit`` entries), not from ``env``'s team. The controller itself
            reads nothing else of the team: its gains, model and speed band are
            ``env``'s.

    Use ``act`` with a PettingZoo observation dict, or ``act_batch``
    with an array of observations ``(..., obs_dim)``.
    """

    def __init__(
        self, env: Any, extrapolate: bool = False, integral_los: float | None = None, any_team: bool = False
    ) -> None:
        config = env if isinstance(env, ScenarioConfig) else getattr(getattr(env, "unwrapped", env), "config", None)
        if not isinstance(config, ScenarioConfig):
            raise TypeError(
                f"ReferencePolicy needs a marine_formation_env env or ScenarioConfig, got {type(env).__name__}"
            )
        for name, flag in (("extrapolate", extrapolate), ("any_team", any_team)):
            if not isinstance(flag, bool):
                raise TypeError(f"{name} must be True or False, got {flag!r}")
        if integral_los is not None:
            if isinstance(integral_los, bool) or not isinstance(integral_los, (int, float)) or not integral_los > 0:
                raise ValueError(f"integral_los must be a gain σ > 0 [m/s] or None, got {integral_los!r}")
            if config.action_level == "speed":
                raise ValueError(
                    "integral_los needs action_level 'guidance' or 'force': at 'speed' the env's built-in LOS steers "
                    "and the policy only commands the speed (set the scenario's los_integral_gain instead)"
                )
        if config.transmit:
            raise ValueError(
                "ReferencePolicy does not send the transmit action the scenario has (transmit=True); the "
                "paper's controller broadcasts by the channel's rule: periodic, or event-triggered with "
                "channel.event_threshold (the policy 'reference:event=δ')"
            )
        self.config = config
        self.layout = ObservationLayout(config.n_vessels, config.observation_slots)
        self.extrapolate = extrapolate
        self.any_team = any_team
        self.integral_los = None if integral_los is None else float(integral_los)
        self._e_int: np.ndarray | None = None

    def reset(self) -> None:
        """Start a new episode: zero the integral-LOS integrators (no-op without them)."""
        self._e_int = None

    def _steering_error(self, e: np.ndarray, advance: bool) -> np.ndarray:
        """The error LOS steers on: ``e`` (paper), or ``e + σ·e_int`` (integral LOS).

        With ``advance`` the integrators then take one Euler step of ``dt``.
        """
        if self.integral_los is None:
            return e
        if self._e_int is None or self._e_int.shape != e.shape:
            self._e_int = np.zeros_like(e)
        z = e + self.integral_los * self._e_int
        if advance:
            rate = integral_los_rate(e, self._e_int, self.integral_los, self.config.gains.delta)
            self._e_int = self._e_int + self.config.dt * rate
        return z

    def layout_of(self, obs: np.ndarray) -> ObservationLayout:
        """The layout ``obs`` ``(..., dim)`` is read with: the team's, or (``any_team``) the one its length implies.

        Raises:
            ValueError: a length that is not the team's (or, with ``any_team``, no team's).
        """
        dim = obs.shape[-1] if obs.ndim else 0
        if not self.any_team:
            if dim != self.layout.dim:
                raise ValueError(f"observations must end in dimension {self.layout.dim}, got shape {obs.shape}")
            return self.layout
        slots, rest = divmod(dim - OWN_SIZE, SLOT_SIZE)
        if dim <= OWN_SIZE or rest:
            raise ValueError(
                f"observations of any team are {OWN_SIZE} own entries and {SLOT_SIZE} per slot "
                f"({OWN_SIZE + SLOT_SIZE}, {OWN_SIZE + 2 * SLOT_SIZE}, ...), got shape {obs.shape}"
            )
        return ObservationLayout(slots + 1)

    def commands(self, obs: np.ndarray, advance: bool = False) -> dict[str, np.ndarray]:
        """Physical commands for observations ``(..., obs_dim)``.

        ``advance`` steps the integral-LOS integrators after use (once per
        control period: ``act_batch`` does it).

        Returns:
            ``{"u_c", "u_c_dot"}`` always, plus ``psi_d`` (guidance) or
            ``tau_u, tau_r`` (force); each of shape ``obs.shape[:-1]``.
        """
        cfg = self.config
        obs = np.asarray(obs, dtype=float)
        own, slots = self.layout_of(obs).split(obs)
        # psi is the heading relative to the path (the heading itself on the straight path)
        e, psi, u, v, r, u_d, u_d_dot, kappa, _, d_y = (own[..., k] for k in range(10))
        linked, d_theta, d_xdot = (slots[..., k] for k in range(3))
        metric = 1.0 - kappa * (d_y + e)  # 1 − κ·d: 1 on the straight path
        if self.extrapolate:
            d_theta = predicted_coordination_error(own, slots)
        s = np.sum(linked * d_theta, axis=-1)
        s_dot = np.sum(linked * d_xdot, axis=-1)
        # (20) gives the projection's speed w; the lane's factor 1 − κ·D_y turns it into a surge command
        w, w_dot = consensus_speed(s, s_dot, u_d, u_d_dot, cfg.gains.a)
        u_c, u_c_dot = lane_speed(cfg.params, w, w_dot, kappa, d_y)
        out = {"u_c": u_c, "u_c_dot": u_c_dot}
        if cfg.action_level == "guidance" and not cfg.straight:  # relative to the path, crab included
            ell_dot = own_path_rate(own)
            crab = turn_crab(cfg.params, kappa, u, 0.0, ell_dot, 0.0)[0]
            out["psi_d"] = los_angle(self._steering_error(e, advance), cfg.gains.delta) - crab
        elif cfg.action_level == "guidance":
            out["psi_d"] = los_angle(self._steering_error(e, advance), cfg.gains.delta)
        elif cfg.action_level == "force" and not cfg.straight:
            out["tau_u"], out["tau_r"] = curved_path_following_inputs(
                cfg.params, cfg.gains, self._steering_error(e, advance), psi, kappa, metric, u, v, r, u_c, u_c_dot
            )
        elif cfg.action_level == "force":
            out["tau_u"], out["tau_r"] = path_following_inputs(
                cfg.params,
                cfg.gains,
                self._steering_error(e, advance),
                psi,
                u,
                v,
                r,
                u_c,
                u_c_dot,
                cfg.paper_as_printed,
            )
        return out

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Normalized actions ``(..., A)`` for observations ``(..., obs_dim)``."""
        cmd = self.commands(obs, advance=True)
        chosen = {k: cmd[k] for k in LEVEL_COMMANDS[self.config.action_level]}
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
