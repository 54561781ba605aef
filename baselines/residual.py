"""Residual policies: the paper's controller plus a learned correction.

A residual policy acts with ``clip(a_ref(o) + a_net(o), −1, 1)``: ``a_ref`` is
the extrapolating reference (``ReferencePolicy(extrapolate=True)``, which over
ideal links is the paper's controller) and ``a_net`` a network's output, both
from the vessel's own masked observation and in the env's normalized action
units. A network that outputs zero is the reference; training it (residual
policy learning: Silver et al., 2018; Johannink et al., 2019) learns only
where the controller leaves return on the table. The controller part reads
observations of any team (``any_team``) and takes its gains, model and speed
band from one configuration, the policy's training one, so a residual policy
is one fixed function of the observation wherever it runs.

``ResidualPolicy`` is the policy; ``residual_base`` the controller part, which
``training.vec_env.ResidualVecEnv`` adds during training with
``residual_actions``, the one rule both use.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from baselines.reference import ReferencePolicy
from baselines.rollout import BatchPolicy
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["ResidualPolicy", "residual_actions", "residual_base"]


def residual_base(config: ScenarioConfig) -> ReferencePolicy:
    """The controller part of a residual policy trained on ``config``: the extrapolating reference, any team."""
    return ReferencePolicy(config, extrapolate=True, any_team=True)


def residual_actions(base: np.ndarray, correction: np.ndarray) -> np.ndarray:
    """The action a residual policy sends: ``clip(base + correction, −1, 1)`` (float32, the env's units)."""
    return np.clip(np.asarray(base) + np.asarray(correction), -1.0, 1.0).astype(np.float32)


class ResidualPolicy(BatchPolicy):
    """The extrapolating reference plus ``correction``'s output (module docstring).

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
        """``clip(a_ref(obs) + a_net(obs), −1, 1)`` for observations ``(..., dim)``."""
        return residual_actions(self.base.act_batch(obs), self.correction.act_batch(obs))
