"""Residual policies: the paper's controller plus a learned correction that vanishes in formation.

A residual policy acts with

    a = clip(a_ref(o) + γ(o)·a_net(o), −1, 1),   γ(o) = 1 − exp(−(e/w_e)² − (Δθ_max/w_θ)²),

all from the vessel's own masked observation ``o`` and in the env's normalized
action units:

* ``a_ref`` is the extrapolating reference (``ReferencePolicy(extrapolate=True)``,
  over ideal links the paper's controller);
* ``a_net`` is a network's output, the learned part (residual policy learning:
  Silver et al., 2018; Johannink et al., 2019);
* ``γ`` is the gate: ``e`` the vessel's cross-track error and ``Δθ_max`` the
  largest coordination error over its linked slots, predicted to now from the
  message's age (``coordination_gap``); the widths are the success band's,
  ``w_e = w_θ = 1 m`` (``baselines.metrics.SUCCESS_BANDS``).

Far from formation ``γ ≈ 1`` and the network corrects the controller freely;
in formation (``e = 0``, every linked ``Δθ = 0``) ``γ = 0`` and the policy is
the controller, and since ``γ`` is quadratic in the errors the correction
leaves the controller's linearization there unchanged, so the formation the
paper's controller converges to is kept, with its precision. The controller
part reads observations of any team (``any_team``) and takes its gains,
model and speed band from one configuration, the policy's training one, so a
residual policy is one fixed function of the observation wherever it runs.

``ResidualPolicy`` is the policy; ``residual_actions`` the rule, which
``training.vec_env.ResidualVecEnv`` applies during training too.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from baselines.metrics import SUCCESS_BANDS
from baselines.reference import ReferencePolicy, coordination_gap
from baselines.rollout import BatchPolicy
from marine_formation_env.rules import CROSS_TRACK
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["ResidualPolicy", "correction_gate", "residual_actions", "residual_base"]


def residual_base(config: ScenarioConfig) -> ReferencePolicy:
    """The controller part of a residual policy trained on ``config``: the extrapolating reference, any team."""
    return ReferencePolicy(config, extrapolate=True, any_team=True)


def correction_gate(own: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """``γ = 1 − exp(−(e/w_e)² − (Δθ_max/w_θ)²)`` of the own parts ``(..., 10)`` and slots ``(..., K, 4)``
    (module docstring); returns ``(...)`` in [0, 1)."""
    e = own[..., CROSS_TRACK] / SUCCESS_BANDS["cross_track"]
    gap = coordination_gap(own, slots) / SUCCESS_BANDS["spread"]
    return np.asarray(-np.expm1(-(e * e) - gap * gap))


def residual_actions(base: ReferencePolicy, obs: np.ndarray, correction: np.ndarray) -> np.ndarray:
    """``clip(a_ref(obs) + γ(obs)·correction, −1, 1)`` for observations ``(..., dim)`` and the learned part's
    output ``(..., A)`` (float32, the env's units)."""
    obs = np.asarray(obs, dtype=float)
    own, slots = base.layout_of(obs).split(obs)
    gate = correction_gate(own, slots)[..., None]
    summed = base.act_batch(obs) + gate * np.asarray(correction).reshape(*obs.shape[:-1], -1)
    return np.clip(summed, -1.0, 1.0).astype(np.float32)


class ResidualPolicy(BatchPolicy):
    """The extrapolating reference plus ``correction``'s output, gated (module docstring).

    Args:
        correction: the learned part, a ``BatchPolicy`` (a ``MLPPolicy`` or a ``ModelPolicy``).
        config: the configuration the policy was trained on (its controller part's gains, model and band).
    """

    def __init__(self, correction: Any, config: ScenarioConfig) -> None:
        self.correction = correction
        self.base = residual_base(config)
        #: the header of the file it was loaded from (``baselines.pretrained.load_pretrained``), else None
        self.info: Any = None

    @property
    def any_slots(self) -> bool:
        """Whether the learned part reads any number of slots (then so does the policy)."""
        if hasattr(self.correction, "any_slots"):
            return bool(self.correction.any_slots)
        return getattr(self.correction, "observation_dim", 0) is None

    @property
    def observation_dim(self) -> int | None:
        """The observation length the learned part takes (None: any)."""
        return self.correction.observation_dim  # type: ignore[no-any-return]

    @property
    def action_dim(self) -> int:
        """The action length."""
        return int(self.correction.action_dim)

    def reset(self) -> None:
        """Start a new episode (the controller part keeps no state; the call is for the engine)."""
        self.base.reset()

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """``clip(a_ref(obs) + γ(obs)·a_net(obs), −1, 1)`` for observations ``(..., dim)``."""
        return residual_actions(self.base, obs, self.correction.act_batch(obs))
