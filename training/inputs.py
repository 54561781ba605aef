"""The slot network's fixed input map in torch, for any network that reads one vessel's observation.

A vessel's observation is its own part (``OWN_SIZE`` entries) and one
``SLOT_SIZE``-entry slot per other vessel (``marine_formation_env.rules``).
``own_and_slots`` maps it, without learned parameters, to what
``training.slot_policy.SlotFeatures`` reads:

* each slot's Δθ predicted to now from the message's velocity and age,
  ``Δθ − ẋ_i·age`` (what ``reference:extrapolate`` does, exact while the
  neighbour's speed holds; unchanged over an ideal link, where the age is 0);
* the own lane offset D_y as κ·D_y (0 on a straight path whatever the lane);
* every entry divided by a fixed scale (``baselines.pretrained.OWN_SCALE``,
  ``SLOT_SCALE``: metres by 50, speeds by 5, ages by 10 s, …).

``PredictedInputs`` is the same map as a module that keeps the
observation's layout, for an MLP (``training.torchrl_ppo``'s ``inputs:
predicted``); ``baselines.pretrained.predicted_inputs`` is its numpy twin, so
an exported policy runs without torch.

``InputMask`` zeroes chosen entries of every observation
(``dropped_mask``; ``training.torchrl_ppo``'s ``drop_inputs``), so a
network cannot read them; ``baselines.pretrained.MLPPolicy``'s ``input_mask``
is its numpy twin.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from baselines.pretrained import OWN_SCALE, SLOT_SCALE, TRAFFIC_SCALE
from marine_formation_env.rules import (
    AGE,
    COORDINATION,
    CROSS_TRACK,
    CURVATURE,
    HEADING,
    LANE_OFFSET,
    OWN_FEATURES,
    OWN_SIZE,
    SLOT_FEATURES,
    SLOT_SIZE,
    SURGE,
    SWAY,
    VELOCITY,
    slot_count,
    traffic_entries,
)

__all__ = ["DROPPABLE", "InputMask", "PredictedInputs", "dropped_mask", "own_and_slots"]

#: The names ``dropped_mask`` takes: an own entry, or a slot entry (dropped from every slot).
DROPPABLE = (*OWN_FEATURES, *SLOT_FEATURES)


def dropped_mask(dim: int, names: Sequence[str]) -> np.ndarray:
    """``(dim,)`` float32: 0 at the entries ``names`` (own entries, or slot entries in every slot), 1 elsewhere.

    Raises:
        ValueError: a name that is neither in ``OWN_FEATURES`` nor in ``SLOT_FEATURES`` (named), or ``dim`` not
            ``OWN_SIZE + SLOT_SIZE · K``.
    """
    unknown = [name for name in names if name not in DROPPABLE]
    if unknown:
        raise ValueError(f"unknown observation entries {unknown}; choose from {list(DROPPABLE)}")
    own = np.array([name not in names for name in OWN_FEATURES], dtype=np.float32)
    slot = np.array([name not in names for name in SLOT_FEATURES], dtype=np.float32)
    return np.concatenate([own, np.tile(slot, slot_count(dim))])


def own_and_slots(
    observations: torch.Tensor, own_scale: torch.Tensor, slot_scale: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The own inputs ``(..., OWN_SIZE)`` and the slots ``(..., K, SLOT_SIZE)`` of observations ``(..., dim)``.

    ``baselines.pretrained.own_and_slots`` in torch, the scales given as tensors (a module's buffers).

    Raises:
        ValueError: the last dimension is not ``OWN_SIZE + SLOT_SIZE · K``.
    """
    k = slot_count(observations.shape[-1])
    own = observations[..., :OWN_SIZE]
    slots = observations[..., OWN_SIZE:].reshape(*observations.shape[:-1], k, SLOT_SIZE)
    e, psi, u, v = own[..., CROSS_TRACK], own[..., HEADING], own[..., SURGE], own[..., SWAY]
    metric = 1.0 - own[..., CURVATURE] * (own[..., LANE_OFFSET] + e)
    x_dot_own = (u * torch.cos(psi) - v * torch.sin(psi)) / metric
    predicted = slots[..., COORDINATION] - (x_dot_own.unsqueeze(-1) - slots[..., VELOCITY]) * slots[..., AGE]
    slots = torch.cat([slots[..., :COORDINATION], predicted.unsqueeze(-1), slots[..., COORDINATION + 1 :]], dim=-1)
    slots = slots / slot_scale
    bent = own[..., CURVATURE : CURVATURE + 1] * own[..., LANE_OFFSET : LANE_OFFSET + 1]  # κ·D_y, not D_y
    own = torch.cat([own[..., :LANE_OFFSET], bent, own[..., LANE_OFFSET + 1 :]], dim=-1) / own_scale
    return own, slots


class PredictedInputs(nn.Module):
    """``baselines.pretrained.predicted_inputs`` as a module ``(..., dim) → (..., dim)``: own inputs, then slots.

    The scales are buffers (saved with the network, never trained).
    """

    own_scale: torch.Tensor
    slot_scale: torch.Tensor
    traffic_scale: torch.Tensor

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("own_scale", torch.tensor(OWN_SCALE, dtype=torch.float32))
        self.register_buffer("slot_scale", torch.tensor(SLOT_SCALE, dtype=torch.float32))
        self.register_buffer("traffic_scale", torch.tensor(TRAFFIC_SCALE, dtype=torch.float32))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        traffic = traffic_entries(observations.shape[-1])
        dim = observations.shape[-1] - traffic
        own, slots = own_and_slots(observations[..., :dim], self.own_scale, self.slot_scale)
        parts = [own, slots.flatten(-2)]
        if traffic:
            parts.append(observations[..., dim:] / self.traffic_scale)
        return torch.cat(parts, dim=-1)


class InputMask(nn.Module):
    """``x ↦ x · mask`` with ``mask = dropped_mask(dim, names)`` a buffer (saved with the network, never trained)."""

    mask: torch.Tensor

    def __init__(self, dim: int, names: Sequence[str]) -> None:
        super().__init__()
        self.register_buffer("mask", torch.from_numpy(dropped_mask(dim, names)))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return observations * self.mask
