"""A policy for any team size: a graph network over the observation's slots (SB3 features extractor).

A vessel's observation is its own part (10 entries) and one 4-entry slot per
other vessel (``marine_formation_env.rules``); the link bit of a slot says
whether anything was heard from that vessel. ``SlotFeatures`` reads
them as a set:

* the own lane offset D_y is read as κ·D_y (the path's curvature times
  D_y, the only way the curved-path law uses it), which is 0 on a straight
  path: raw, it grows with the team and biased the first any-team policy
  by each vessel's lane (``baselines.pretrained.own_inputs``);
* each slot's Δθ is read as predicted to now from the message's velocity
  and age, ``Δθ − ẋ_i·age`` (what ``reference:extrapolate`` does; the same
  Δθ over an ideal link, where the age is 0), so over a lossy, delayed
  channel the network need not learn that product itself;
* every entry is divided by a fixed scale (``OWN_SCALE``,
  ``SLOT_SCALE``: metres by 50, speeds by 5, …), not by running
  statistics, so the same weights read every team size and the link bit
  stays a mask;
* each slot k becomes a message ``m_k = φ([own, slot_k])`` (an MLP, tanh);
* the messages of the slots heard (link bit 1) are summed and averaged
  (``Σ_k l_k m_k`` and ``Σ_k l_k m_k / max(1, Σ_k l_k)``): the paper's law
  (20) sums over the in-neighbours, the mean keeps the scale when a vessel
  hears many;
* the features are ``[ψ(own), sum, mean]``; SB3's ``net_arch`` layers and
  action head follow, as for ``MlpPolicy``; with ``transmit`` the
  observation's last entries (``TRANSMIT_FEATURES``, divided by
  ``TRAFFIC_SCALE``) are read by ψ beside the own inputs, not by the messages;
* with ``zero_at_agreement = True`` (default False) each message is measured
  from the message of a neighbour in agreement, ``m_k = φ([own, slot_k]) −
  φ([own, slot_k⁰])``, where ``slot_k⁰`` keeps the link bit and the age but
  has Δθ = 0 and Δẋ = 0: a neighbour that agrees adds nothing, as in the
  paper's law (20), whose sum over the in-neighbours is 0 at agreement. A
  vessel whose neighbours all agree then commands what a vessel that hears
  no one does, so a chain has no steady offset per link for its length to
  multiply.

Nothing depends on the number of slots, so the weights trained on teams of 3
to 6 (observations padded to one length with ``observation_slots``) act in a
team of 20, whose observations have 19 slots. Config (``training.train``)::

    policy: MlpPolicy
    policy_kwargs:
      features_extractor_class: slots       # this module's SlotFeatures
      features_extractor_kwargs: {hidden: 64}
      net_arch: [64, 64]

``baselines.pretrained.slot_features`` is the same function in numpy
(pretrained policies run without torch).
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from baselines.pretrained import AGREEMENT_MASK, OWN_SCALE, SLOT_SCALE, TRAFFIC_SCALE
from marine_formation_env.rules import OWN_SIZE, SLOT_SIZE, traffic_entries
from training.inputs import own_and_slots

__all__ = ["SlotFeatures"]


class SlotFeatures(BaseFeaturesExtractor):
    """Features ``[ψ(own), Σ heard messages, mean heard message]`` of size ``3 · hidden`` (module docstring)."""

    def __init__(
        self,
        observation_space: spaces.Box,
        hidden: int = 64,
        zero_at_agreement: bool = False,
    ) -> None:
        traffic = traffic_entries(int(observation_space.shape[0]))  # refuses a size that is not own + slots (+ traffic)
        if not isinstance(zero_at_agreement, bool):
            raise ValueError(f"zero_at_agreement must be True or False, got {zero_at_agreement!r}")
        super().__init__(observation_space, features_dim=3 * hidden)
        self.hidden = hidden
        self.zero_at_agreement = zero_at_agreement
        self.traffic = traffic
        self.own_scale: torch.Tensor
        self.slot_scale: torch.Tensor
        self.agreement_mask: torch.Tensor
        self.traffic_scale: torch.Tensor
        self.register_buffer("own_scale", torch.tensor(OWN_SCALE, dtype=torch.float32))
        self.register_buffer("slot_scale", torch.tensor(SLOT_SCALE, dtype=torch.float32))
        if traffic:  # a constant, as the agreement mask
            self.register_buffer("traffic_scale", torch.tensor(TRAFFIC_SCALE, dtype=torch.float32), persistent=False)
        if zero_at_agreement:  # not saved (persistent=False): it is a constant, and old state_dicts load strictly
            self.register_buffer("agreement_mask", torch.tensor(AGREEMENT_MASK, dtype=torch.float32), persistent=False)
        self.message = nn.Sequential(
            nn.Linear(OWN_SIZE + SLOT_SIZE, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh()
        )
        self.own = nn.Sequential(nn.Linear(OWN_SIZE + traffic, hidden), nn.Tanh())

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        # Δθ predicted to now, κ·D_y, fixed scales (training.inputs; a bad size raises there)
        dim = observations.shape[-1] - self.traffic
        own, slots = own_and_slots(observations[..., :dim], self.own_scale, self.slot_scale)
        heard = (slots[..., :1] > 0.5).to(observations.dtype)  # (..., K, 1): the link bits
        own_k = own.unsqueeze(-2).expand(*slots.shape[:-1], own.shape[-1])
        messages = self.message(torch.cat([own_k, slots], dim=-1))
        if self.zero_at_agreement:  # minus the message of a neighbour that agrees: Δθ = Δẋ = 0
            agreed = slots * self.agreement_mask
            messages = messages - self.message(torch.cat([own_k, agreed], dim=-1))
        messages = messages * heard
        total = messages.sum(dim=-2)
        mean = total / heard.sum(dim=-2).clamp(min=1.0)
        if self.traffic:
            own_in = torch.cat([own, observations[..., dim:] / self.traffic_scale], dim=-1)
        else:
            own_in = own
        return torch.cat([self.own(own_in), total, mean], dim=-1)
