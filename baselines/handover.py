"""A learned policy for the transient, the paper's controller once in the success band: ``HandoverPolicy``.

The learned rows return more than the paper's controller but end less
precisely: their formations stop centimetres to decimetres apart, where the
controller drives every error to zero (the paper's convergence result for
the consensus law (20) with LOS path following, from any initial condition,
on ideal links). ``HandoverPolicy`` composes the two: each vessel acts with the
learned policy until its **own observation** is inside the bands a
successful episode ends in (``baselines.metrics.SUCCESS_BANDS``),

* its cross-track error ``|e_j| ≤ 1 m``,
* its heading relative to the path ``|ψ̃_j| ≤ 2°`` (so a vessel that crosses
  the path mid-turn does not hand over; one that crabs across a current
  keeps the learned policy),
* every linked neighbour's coordination error ``|θ_j − θ_i| ≤ 1 m``
  (predicted to now from the message's age, as the extrapolating reference
  does; the message itself on ideal links),
* its speed along its lane ``|(1 − κ·D_yj)·(ℓ̇_j − u_d)| ≤ 0.1 m/s``,

for ``HOLD`` = 20 s without a break, and from then on with
``ReferencePolicy(extrapolate=True)``: the switch is per vessel and latched
for the rest of the episode (``reset`` starts a new one). The hold keeps a
vessel whose own neighbours agree, or seem to from stale messages, from
handing over while the rest of the team is still far from formation. Each
vessel decides from the same masked observation both policies read, so the
composite is as decentralized as its parts. It is a composite row, not a
learned one: its precision is the controller's, its transient the learned
policy's (``docs/benchmark.md``, Precision).

From the command line, ``handover:`` before any learned policy::

    python -m baselines.evaluate --policy handover:pretrained:paper_speed --policy pretrained:paper_speed \\
        --policy reference --episodes 20 --seed 500000
"""

from __future__ import annotations

from typing import Any

import numpy as np

from baselines.metrics import SUCCESS_BANDS
from baselines.reference import ReferencePolicy, coordination_gap, own_path_rate
from baselines.rollout import BatchPolicy
from marine_formation_env.observations import ObservationLayout
from marine_formation_env.rules import CROSS_TRACK, CURVATURE, DESIRED_SPEED, HEADING, LANE_OFFSET

__all__ = ["HANDOVER_PREFIX", "HOLD", "HandoverPolicy", "in_band", "is_handover"]

#: ``--policy handover:LEARNED``: the learned policy ``LEARNED`` handing over to the reference.
HANDOVER_PREFIX = "handover:"

#: How long [s] a vessel's own observation stays in the band, without a break, before it hands over.
HOLD = 20.0


def is_handover(spec: str) -> bool:
    """Whether a ``--policy`` value names a handover composite (``handover:LEARNED``)."""
    return spec.startswith(HANDOVER_PREFIX)


def in_band(layout: ObservationLayout, obs: np.ndarray, bands: dict[str, float] = SUCCESS_BANDS) -> np.ndarray:
    """Whether each observation ``(..., dim)`` is inside ``bands`` (module docstring): ``(...)`` booleans.

    Reads the own part and the slots only: the cross-track error, the
    heading relative to the path, the largest predicted coordination error
    over the linked slots (``coordination_gap``), and the lane speed error
    ``(1 − κ·D_y)·(ℓ̇ − u_d)`` with the own along-path rate ℓ̇ (``own_path_rate``).
    """
    own, slots = layout.split(np.asarray(obs, dtype=float))
    e, psi = own[..., CROSS_TRACK], own[..., HEADING]
    kappa, d_y, u_d = own[..., CURVATURE], own[..., LANE_OFFSET], own[..., DESIRED_SPEED]
    speed = (1.0 - kappa * d_y) * (own_path_rate(own) - u_d)
    return np.asarray(
        (np.abs(e) <= bands["cross_track"])
        & (np.abs(psi) <= np.radians(bands["heading_deg"]))
        & (coordination_gap(own, slots) <= bands["spread"])
        & (np.abs(speed) <= bands["speed"])
    )


class HandoverPolicy(BatchPolicy):
    """``learned`` until a vessel's own observation has been in the band for ``HOLD``, then the reference.

    Args:
        learned: a batch policy (``act_batch``) at the scenario's action level:
            a pretrained or saved learned policy.
        env: the env, or its ``ScenarioConfig``, the reference is built for
            (``ReferencePolicy``; it refuses a scenario with ``transmit``).

    ``act_batch`` keeps one switch per row of the observations it is given
    (one row per vessel of each formation, in the same order every step);
    ``reset`` clears them, and those of both parts.
    """

    def __init__(self, learned: Any, env: Any) -> None:
        if not callable(getattr(learned, "act_batch", None)):
            raise TypeError(f"HandoverPolicy needs a batch policy (act_batch) to hand over from, got {learned!r}")
        self.learned = learned
        self.reference = ReferencePolicy(env, extrapolate=True)
        self.hold_steps = int(np.ceil(HOLD / self.reference.config.dt - 1e-9))
        self.switched: np.ndarray | None = None
        self.inside: np.ndarray | None = None  # control periods in the band without a break, per row

    def reset(self) -> None:
        """Start a new episode: every vessel acts with the learned policy again."""
        self.switched = self.inside = None
        self.reference.reset()
        if callable(getattr(self.learned, "reset", None)):
            self.learned.reset()

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Normalized actions ``(..., A)`` for observations ``(..., obs_dim)``."""
        obs = np.asarray(obs)
        now = in_band(self.reference.layout, obs)
        if self.switched is None or self.inside is None or self.switched.shape != now.shape:
            self.switched, self.inside = np.zeros(now.shape, dtype=bool), np.zeros(now.shape, dtype=int)
        self.inside = np.where(now, self.inside + 1, 0)
        self.switched |= self.inside > self.hold_steps
        reference = self.reference.act_batch(obs)
        learned = np.asarray(self.learned.act_batch(obs), dtype=reference.dtype)
        return np.where(self.switched[..., None], reference, learned)
