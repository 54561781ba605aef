"""What a vessel observes: the layout of its observation vector and its bounds.

The entries themselves are computed by the core with the rules of
``marine_formation_env.rules``; this module says where each one sits
(``ObservationLayout``) and what range it can take (``observation_bounds``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from marine_formation_env.rules import MAX_DRIFT, OWN_FEATURES, SLOT_FEATURES, TRANSMIT_FEATURES
from marine_formation_env.scenarios import ScenarioConfig

__all__ = ["MIN_CURVATURE_BOUND", "TRANSMIT_FEATURES", "ObservationLayout", "observation_bounds", "observation_space"]


#: The curvature entries' bound [1/m] is at least this (a radius of 100 m), so that
#: observation spaces of straight and gently curved scenarios are the same.
MIN_CURVATURE_BOUND = 0.01


@dataclass(frozen=True)
class ObservationLayout:
    """Index arithmetic of the per-agent observation vector.

    Vessel ``j``'s observation is its own part (``OWN_FEATURES``)
    followed by one slot (``SLOT_FEATURES``) per
    other vessel ``i = (j + k + 1) mod N``, ``k = 0 … N−2``: ordered relative to
    ``j``, so one shared policy sees "the next vessel", "the one after" and so
    on in the same place for every vessel; with ``transmit``, the
    ``TRANSMIT_FEATURES`` last.
    """

    n_vessels: int
    #: slots per observation; None: n − 1 (``observation_slots``); the slots beyond n − 1 stay empty (all 0)
    n_slots: int | None = None

    own: int = len(OWN_FEATURES)
    slot: int = len(SLOT_FEATURES)
    #: the policies decide when to broadcast (``ScenarioConfig.transmit``): ``TRANSMIT_FEATURES`` at the end
    transmit: bool = False

    @property
    def slots_end(self) -> int:
        """Index one past the last slot entry (where ``TRANSMIT_FEATURES`` start)."""
        return self.own + self.slot * self.slots

    @property
    def traffic(self) -> int:
        """Entries after the slots: ``TRANSMIT_FEATURES`` with ``transmit``, else none."""
        return len(TRANSMIT_FEATURES) if self.transmit else 0

    @property
    def slots(self) -> int:
        """Number of slots in one observation (n − 1 unless padded)."""
        return self.n_vessels - 1 if self.n_slots is None else self.n_slots

    @property
    def dim(self) -> int:
        """Length of one agent's observation."""
        return self.slots_end + self.traffic

    def slot_vessels(self, j: int) -> list[int]:
        """The vessel held in each slot of vessel ``j``'s observation."""
        n = self.n_vessels
        return [(j + k + 1) % n for k in range(n - 1)]

    def split(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Split ``(..., dim)`` observations into own ``(..., 10)`` and the N − 1 vessels' slots ``(..., N−1, 4)``.

        Padding slots (``observation_slots`` > N − 1) are left out.
        """
        own = obs[..., : self.own]
        slots = obs[..., self.own : self.slots_end].reshape(*obs.shape[:-1], self.slots, self.slot)
        return own, slots[..., : self.n_vessels - 1, :]


def observation_bounds(config: ScenarioConfig) -> tuple[np.ndarray, np.ndarray]:
    """Per-agent observation bounds ``(low, high)``, float32 (see ``observation_space``)."""
    cfg = config
    x_lo, x_hi, y_lo, y_hi = cfg.workspace
    d = cfg.formation
    rate = max(2.0 * np.pi * cfg.u_d.amplitude / cfg.u_d.period, 0.1)
    if cfg.straight:
        e_max = max(abs(y_lo), abs(y_hi)) + float(np.max(np.abs(d[:, 1])))
    else:
        e_max = cfg.corridor  # beyond it the formation terminates
    kappa_max = max(MIN_CURVATURE_BOUND, 1.0 / cfg.path.min_radius)
    lane_max = max(float(np.max(np.abs(d[:, 1]))), 1.0)
    own_high = [
        e_max,  # e_j
        np.pi,  # ψ
        cfg.max_speed,  # u
        cfg.max_speed,  # v
        cfg.max_yaw_rate,  # r
        cfg.u_max,  # u_d ∈ [U_min + a, U_max − a] by (19)
        rate,  # u̇_d
        kappa_max,  # κ at the vessel
        kappa_max,  # κ ahead
        lane_max,  # D_y
    ]
    own_low = [-h for h in own_high]
    own_low[5] = cfg.u_min
    dtheta = (x_hi - x_lo) + float(np.ptp(d[:, 0]))
    dxdot = 2.0 * np.sqrt(2.0) * cfg.max_speed
    slot_low = [0.0, -dtheta, -dxdot, 0.0]
    slot_high = [1.0, dtheta, dxdot, cfg.horizon]
    traffic_low, traffic_high = ([0.0, 0.0, 0.0], [1.0, cfg.horizon, MAX_DRIFT]) if cfg.transmit else ([], [])
    low = np.array(own_low + slot_low * cfg.observation_slots + traffic_low, dtype=np.float32)
    high = np.array(own_high + slot_high * cfg.observation_slots + traffic_high, dtype=np.float32)
    return low, high


def observation_space(config: ScenarioConfig, joint: bool = False) -> spaces.Box:
    """One vessel's observation space (``joint``: the N vessels' concatenated).

    Bounds: ``e_j`` within the workspace's y-extent plus the largest |D_y|
    (on a curved path: within the corridor);
    ψ in [−π, π]; u, v in ±max_speed; r in ±max_yaw_rate; u_d in
    [U_min, U_max]; u̇_d within the profile's range (at least ±0.1 m/s²); the
    curvatures within ±max(0.01, 1/R_min) 1/m; the lane offset within ±max(1 m,
    max |D_y|); link bits in
    [0, 1]; coordination differences within the workspace's x-extent plus the
    spread of D_x; ẋ differences within ±2√2·max_speed; ages in
    [0, horizon]; with ``transmit`` the budget left in [0, 1], the time
    since the last broadcast in [0, horizon] and the prediction drift in
    [0, ``MAX_DRIFT``] m. A formation that leaves the workspace or the speed/yaw-rate
    envelope terminates, so only its last observation can reach past the
    bounds, and it is clipped to them.
    """
    low, high = observation_bounds(config)
    if joint:
        n = config.n_vessels
        return spaces.Box(np.tile(low, n), np.tile(high, n), dtype=np.float32)
    return spaces.Box(low, high, dtype=np.float32)
