"""The slot network's fixed input map in torch, for any network that reads one vessel's observation.

A vessel's observation is its own part (``OWN_SIZE`` entries) and one
``SLOT_SIZE``-entry slot per other vessel (``marine_formation_env.rules``).
:func:`predicted_inputs` maps it, without learned parameters, to what
``training.slot_policy.SlotFeatures`` reads:

* each slot's Δθ predicted to now from the message's velocity and age,
  ``Δθ − ẋ_i·age`` (what ``reference:extrapolate`` does, exact while the
  neighbour's speed holds; unchanged over an ideal link, where the age is 0);
* the own lane offset D_y as κ·D_y (0 on a straight path whatever the lane);
* every entry divided by a fixed scale (``baselines.pretrained.OWN_SCALE``,
  ``SLOT_SCALE``: metres by 50, speeds by 5, ages by 10 s, …).

:class:`PredictedInputs` is the same map as a module that keeps the
observation's layout, for an MLP (``training.torchrl_ppo``'s ``inputs:
predicted``); ``baselines.pretrained.predicted_inputs`` is its numpy twin, so
an exported policy runs without torch.
"""

from __future__ import annotations

import torch
from torch import nn

from baselines.pretrained import OWN_SCALE, SLOT_SCALE
from marine_formation_env.rules import CURVATURE, LANE_OFFSET, OWN_SIZE, SLOT_SIZE, slot_count

__all__ = ["PredictedInputs", "predicted_inputs"]


def predicted_inputs(
    observations: torch.Tensor, own_scale: torch.Tensor, slot_scale: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The own inputs ``(..., OWN_SIZE)`` and the slots ``(..., K, SLOT_SIZE)`` of observations ``(..., dim)``.

    Raises:
        ValueError: the last dimension is not ``OWN_SIZE + SLOT_SIZE · K``.
    """
    k = slot_count(observations.shape[-1])
    own = observations[..., :OWN_SIZE]
    slots = observations[..., OWN_SIZE:].reshape(*observations.shape[:-1], k, SLOT_SIZE)
    e, psi, u, v = own[..., 0], own[..., 1], own[..., 2], own[..., 3]
    metric = 1.0 - own[..., CURVATURE] * (own[..., LANE_OFFSET] + e)
    x_dot_own = (u * torch.cos(psi) - v * torch.sin(psi)) / metric
    predicted = slots[..., 1] - (x_dot_own.unsqueeze(-1) - slots[..., 2]) * slots[..., 3]
    slots = torch.cat([slots[..., :1], predicted.unsqueeze(-1), slots[..., 2:]], dim=-1) / slot_scale
    bent = own[..., CURVATURE : CURVATURE + 1] * own[..., LANE_OFFSET : LANE_OFFSET + 1]  # κ·D_y, not D_y
    own = torch.cat([own[..., :LANE_OFFSET], bent, own[..., LANE_OFFSET + 1 :]], dim=-1) / own_scale
    return own, slots


class PredictedInputs(nn.Module):
    """:func:`predicted_inputs` as a module ``(..., dim) → (..., dim)``: the own inputs, then the slots, flat.

    The scales are buffers (saved with the network, never trained).
    """

    own_scale: torch.Tensor
    slot_scale: torch.Tensor

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("own_scale", torch.tensor(OWN_SCALE, dtype=torch.float32))
        self.register_buffer("slot_scale", torch.tensor(SLOT_SCALE, dtype=torch.float32))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        own, slots = predicted_inputs(observations, self.own_scale, self.slot_scale)
        return torch.cat([own, slots.flatten(-2)], dim=-1)
