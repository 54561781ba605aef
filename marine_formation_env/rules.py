"""The step's rules, written once, per element: observation entries, cost terms, termination, RK4.

Every function here works on numbers and on numpy arrays alike (broadcasting),
with no branch on values, so both backends call the *same* code:

* the numpy path of ``FormationCore`` calls
  them on whole ``(B, N)`` arrays (vectorized);
* the numba kernel (``marine_formation_env._numba``) registers them with
  ``register_jitable`` and calls them on one vessel's scalars inside its
  fused loop.

A change to a rule (a reward term, a termination test, the layout of an
observation slot) is therefore one edit here, and ``tests/test_backends.py``
checks that the two backends still agree.

Observation layout of vessel ``j`` (``OWN_SIZE + SLOT_SIZE·(N−1)`` entries):
the own part (``OWN_FEATURES``), then one slot (``SLOT_FEATURES``) per
other vessel, in the order of ``slot_vessels``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "AGE",
    "COORDINATION",
    "CROSS_TRACK",
    "CURVATURE",
    "CURVATURE_AHEAD",
    "DESIRED_SPEED",
    "HEADING",
    "LANE_OFFSET",
    "LINK",
    "LOOKAHEAD",
    "MAX_DRIFT",
    "OWN_FEATURES",
    "OWN_SIZE",
    "SLOT_FEATURES",
    "SLOT_SIZE",
    "SURGE",
    "SWAY",
    "TRANSMIT_FEATURES",
    "VELOCITY",
    "along_track",
    "bounded_cost",
    "cost_term",
    "effort_term",
    "outside_envelope",
    "outside_workspace",
    "rk4_combine",
    "slot_count",
    "slot_differences",
    "terminal_term",
    "traffic_entries",
]

#: The own part of a vessel's observation, in order.
OWN_FEATURES = (
    "cross_track_error",
    "heading",
    "surge",
    "sway",
    "yaw_rate",
    "desired_speed",
    "desired_speed_rate",
    "path_curvature",
    "path_curvature_ahead",
    "lane_offset",
)
#: One slot of a vessel's observation (what it knows of one other vessel), in order.
SLOT_FEATURES = ("linked", "coordination_error", "velocity_difference", "age")
OWN_SIZE = len(OWN_FEATURES)
SLOT_SIZE = len(SLOT_FEATURES)
#: Offsets inside the own part: the cross-track error e, the heading error ψ̃, the surge u and sway v speeds.
CROSS_TRACK, HEADING, SURGE, SWAY = (
    OWN_FEATURES.index(name) for name in ("cross_track_error", "heading", "surge", "sway")
)
#: Offset inside the own part of the desired speed u_d.
DESIRED_SPEED = OWN_FEATURES.index("desired_speed")
#: Offsets inside the own part: the path's curvature at the vessel's projection, at
#: ``LOOKAHEAD`` further along the path, and the vessel's lane offset D_y.
CURVATURE, CURVATURE_AHEAD, LANE_OFFSET = (
    OWN_FEATURES.index(name) for name in ("path_curvature", "path_curvature_ahead", "lane_offset")
)
#: How far ahead [m] of its projection a vessel sees the path's curvature (20 s at 5 m/s).
LOOKAHEAD = 100.0
#: Offsets inside a slot.
LINK, COORDINATION, VELOCITY, AGE = (
    SLOT_FEATURES.index(name) for name in ("linked", "coordination_error", "velocity_difference", "age")
)


#: The entries after the slots when each vessel decides when to broadcast (``ScenarioConfig.transmit``): the
#: share of its token bucket left, the time since its last broadcast [s], and how far its neighbours'
#: prediction of it from that broadcast is off (``channel.prediction_error``, the event-triggered rule's
#: quantity) [m], at most ``MAX_DRIFT``.
TRANSMIT_FEATURES = ("budget_left", "since_broadcast", "prediction_drift")
#: The largest ``prediction_drift`` observed [m]: a vessel this far from what the others predict of it (or
#: one that has not broadcast since reset) sees this value.
MAX_DRIFT = 10.0


def traffic_entries(dim: int) -> int:
    """How many entries follow the slots in an observation of ``dim`` entries: ``len(TRANSMIT_FEATURES)``
    with ``transmit``, else 0 (a slot has ``SLOT_SIZE`` = 4 entries, so the two cases never meet).

    Raises:
        ValueError: ``dim`` is neither ``OWN_SIZE + SLOT_SIZE · K`` nor that plus ``TRANSMIT_FEATURES``.
    """
    extra = (dim - OWN_SIZE) % SLOT_SIZE
    if dim < OWN_SIZE or extra not in (0, len(TRANSMIT_FEATURES)):
        raise ValueError(
            f"an observation of size {dim} is not {OWN_SIZE} + {SLOT_SIZE}·slots (+ {len(TRANSMIT_FEATURES)})"
        )
    return extra


def slot_count(dim: int) -> int:
    """How many slots an observation of ``dim`` entries holds (``OWN_SIZE + SLOT_SIZE · K``).

    Raises:
        ValueError: ``dim`` is not of that form (names the size).
    """
    if dim < OWN_SIZE or (dim - OWN_SIZE) % SLOT_SIZE:
        raise ValueError(f"an observation of size {dim} is not {OWN_SIZE} + {SLOT_SIZE}·slots")
    return (dim - OWN_SIZE) // SLOT_SIZE


def rk4_combine(x: Any, k1: Any, k2: Any, k3: Any, k4: Any, h: float) -> Any:
    """The classical RK4 update ``x + h/6·(k1 + 2·(k2 + k3) + k4)`` from the four stage slopes."""
    return x + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


def along_track(x: Any, d_x: Any, psi: Any, u: Any, v: Any) -> tuple[Any, Any]:
    """The coordination variable ``θ = x − D_x`` [m] of (20) and the along-path speed ``ẋ = u cos ψ − v sin ψ`` [m/s]
    (through the water)."""
    return x - d_x, u * np.cos(psi) - v * np.sin(psi)


def slot_differences(link: Any, theta_j: Any, theta_i: Any, xdot_j: Any, xdot_i: Any) -> tuple[Any, Any]:
    """Slot entries of vessel ``j`` about vessel ``i``: ``link·(θ_j − θ_i)`` [m] and ``link·(ẋ_j − ẋ_i)`` [m/s].

    ``link`` is 1 if ``i`` transmits to ``j`` (``i ∈ A_j``), else 0: nothing of
    an unlinked vessel reaches ``j``.
    """
    return link * (theta_j - theta_i), link * (xdot_j - xdot_i)


def bounded_cost(error: Any, sigma: float) -> Any:
    """``c(e; σ) = (e/σ)² / (1 + (e/σ)²) ∈ [0, 1)``: quadratic near 0, saturating far away."""
    z2 = (error / sigma) ** 2
    return z2 / (1.0 + z2)


def cost_term(weight: float, error: Any, sigma: float, dt: float, fine_share: float, fine_scale: float) -> Any:
    """One tracking term of the step reward: ``−dt·w·[(1 − f)·c(e; σ) + f·c(e; s·σ)]``.

    ``f`` is ``fine_share`` and ``s`` is ``fine_scale`` (``RewardConfig``). With ``f = 0``
    (the benchmark's reward) it is ``−dt·w·c(e; σ)``, and the fine cost is not computed.
    """
    cost = bounded_cost(error, sigma)
    if fine_share != 0.0:
        cost = (1.0 - fine_share) * cost + fine_share * bounded_cost(error, fine_scale * sigma)
    return -dt * weight * cost


def effort_term(weight: float, mean_square_action: Any, dt: float) -> Any:
    """The effort term of the step reward: ``−dt·w·mean(a²)`` of the clipped normalized action."""
    return -dt * weight * mean_square_action


def terminal_term(terminated: Any, penalty_rate: float, time_left: Any) -> Any:
    """``−rate·max(time left, 0)`` for a formation that terminated, else 0.

    ``rate`` is Σ_k w_k (or 0 with ``terminal_penalty=False``): the worst the
    rest of the episode could have given, so that ending early never pays.
    """
    return (-penalty_rate * np.maximum(time_left, 0.0)) * terminated + 0.0  # + 0.0: no −0.0 when not terminated


def outside_workspace(x: Any, y: Any, x_lo: float, x_hi: float, y_lo: float, y_hi: float) -> Any:
    """Whether a position [m] is outside the workspace box (terminates the formation)."""
    return (x < x_lo) | (x > x_hi) | (y < y_lo) | (y > y_hi)


def outside_envelope(u: Any, v: Any, r: Any, max_speed: float, max_yaw_rate: float) -> Any:
    """Whether a velocity is outside the model's envelope ``|u|, |v| ≤ max_speed``, ``|r| ≤ max_yaw_rate``."""
    return (np.abs(u) > max_speed) | (np.abs(v) > max_speed) | (np.abs(r) > max_yaw_rate)
