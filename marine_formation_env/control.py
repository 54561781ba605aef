"""The paper's controllers (Sections III-IV), batched, with the docs/model.md §3 corrections.

Every function works element-wise on arrays of any (matching) shape, so the
same code serves the built-in inner loops of the environment (evaluated at
every RK4 stage, shapes ``(B, N)``) and the reference policy (evaluated once
per control period on per-agent observations).

Two equations of the printed paper contradict the paper's own error dynamics
and are corrected here (docs/model.md §3); ``as_printed=True`` runs them as printed so
the difference can be shown:

* Surge law (11) lacks the damping compensation ``(d11/m11)·u_c``; as printed,
  the closed loop is ``ũ̇ = −k_u·ũ − (d11/m11)·u`` and the vessels settle at
  ``u = k_u·u_c/(k_u + d11/m11)`` (4.889 m/s for the supply vessel at 5 m/s)
  instead of ``u_c``.
* The LOS feed-forward in (14) has the wrong sign: the printed
  ``+Δ/(e²+Δ²)·ẏ`` is minus the derivative of ψ_LOS in (12), so (16) does not
  hold. The corrected ``ψ̇_LOS = −Δ·ẏ/(e²+Δ²)`` is used.

Angles in heading errors are wrapped to ``[−π, π)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from marine_formation_env.dynamics import accelerations, wrap_angle
from marine_formation_env.params import Gains, VesselParams

#: ``(a_u, v̇, a_r)`` as returned by ``accelerations``.
Accelerations = tuple[np.ndarray, np.ndarray, np.ndarray]

__all__ = [
    "consensus_speed",
    "curved_heading_inputs",
    "curved_path_following_inputs",
    "heading_tracking_inputs",
    "heading_yaw_reference",
    "integral_los_rate",
    "lane_speed",
    "los_angle",
    "los_yaw_reference",
    "path_following_inputs",
    "path_rates",
    "saturation",
    "saturation_slope",
    "surge_law",
    "turn_crab",
    "turn_sway",
    "yaw_law",
]


def saturation(s: np.ndarray | float, a: float) -> np.ndarray:
    """The consensus nonlinearity ``g(s) = (2a/π)·atan(s)`` ∈ (−a, a) of (20)."""
    return (2.0 * a / np.pi) * np.arctan(s)


def saturation_slope(s: np.ndarray | float, a: float) -> np.ndarray:
    """``g'(s) = (2a/π)/(1 + s²)``."""
    return (2.0 * a / np.pi) / (1.0 + np.square(s))


def consensus_speed(
    s: np.ndarray,
    s_dot: np.ndarray,
    u_d: np.ndarray | float,
    u_d_dot: np.ndarray | float,
    a: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Coordination law (20) and its time derivative.

    Args:
        s: ``s_j = Σ_{i∈A_j} (x_j − x_i − d_ji)`` [m].
        s_dot: ``ṡ_j = Σ_{i∈A_j} (ẋ_j − ẋ_i)`` [m/s].
        u_d, u_d_dot: desired formation speed [m/s] and its rate [m/s²].
        a: saturation level of g [m/s].

    Returns:
        ``(u_c, u̇_c)``: commanded surge speed [m/s] and its rate [m/s²].
        Under (19), ``u_c ∈ (U_min, U_max)`` for every argument.
    """
    u_c = u_d - saturation(s, a)
    u_c_dot = u_d_dot - saturation_slope(s, a) * s_dot
    return u_c, u_c_dot


def los_angle(e: np.ndarray, delta: float) -> np.ndarray:
    """LOS guidance (12): ``ψ_LOS = −atan(e/Δ)`` [rad], ``e = y − D_y`` [m]."""
    return -np.arctan(e / delta)


def integral_los_rate(e: np.ndarray, e_int: np.ndarray, sigma: float, delta: float) -> np.ndarray:
    """Integral LOS (Børhaug, Pavlov, Pettersen, CDC 2008; our extension of (12)).

    LOS then steers on ``e + σ·e_int`` instead of ``e``, and the integrator
    moves at ``ė_int = Δ·e/((e + σ·e_int)² + Δ²)`` (returned). Its fixed point
    needs ``e = 0``, which removes the offset a constant current leaves.

    Args:
        e: cross-track error [m]; e_int: the integrator [s].
        sigma: integral gain σ [m/s] (above the largest cross current).
        delta: look-ahead distance Δ [m].
    """
    z = e + sigma * e_int
    return delta * e / (z * z + delta * delta)


def surge_law(
    p: VesselParams,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_c: np.ndarray,
    u_c_dot: np.ndarray | float,
    k_u: float,
    as_printed: bool = False,
) -> np.ndarray:
    """Surge acceleration input τ_u [m/s²] of (11), corrected (docs/model.md §3).

    ``τ_u = −(m22·v + m23·r)·r/m11 + (d11/m11)·u_c + u̇_c − k_u·(u − u_c)``
    gives ``ũ̇ = −(k_u + d11/m11)·ũ``. With ``as_printed=True`` the
    ``(d11/m11)·u_c`` term is dropped, as in the printed (11).
    """
    tau = -(p.m22 * v + p.m23 * r) * r / p.m11 + u_c_dot - k_u * (u - u_c)
    if not as_printed:
        tau = tau + (p.d11 / p.m11) * u_c
    return tau


def yaw_law(
    p: VesselParams,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    r_d: np.ndarray,
    r_d_dot: np.ndarray,
    k_r: float,
    acc: Accelerations | None = None,
) -> np.ndarray:
    """Yaw acceleration input τ_r [rad/s²] of (13): gives ``ṙ = ṙ_d − k_r·(r − r_d)``.

    ``acc`` are ``accelerations`` of the
    state, if already computed.
    """
    _, _, a_r = accelerations(p, u, v, r) if acc is None else acc
    return -a_r + r_d_dot - k_r * (r - r_d)


def los_yaw_reference(
    p: VesselParams,
    e: np.ndarray,
    psi: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    tau_u: np.ndarray,
    gains: Gains,
    as_printed: bool = False,
    acc: Accelerations | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Desired yaw rate (14), corrected, and its derivative (docs/model.md §3).

    ::

        ψ̇_LOS = −Δ·ẏ/(e² + Δ²),                      ẏ = u sin ψ + v cos ψ
        r_d   = ψ̇_LOS − k_ψ·(ψ − ψ_LOS)
        ṙ_d   = ψ̈_LOS − k_ψ·(r − ψ̇_LOS)
        ψ̈_LOS = −Δ·ÿ/(e² + Δ²) + 2·Δ·e·ẏ²/(e² + Δ²)²
        ÿ     = u̇ sin ψ + u·r cos ψ + v̇ cos ψ − v·r sin ψ

    with ``u̇`` from ``tau_u`` and ``v̇`` from the model. With
    ``as_printed=True`` the feed-forward term takes the printed sign
    (``+Δ·ẏ/(e² + Δ²)``) and ``ṙ_d`` is the exact derivative of that printed
    ``r_d``, so only the printed formula differs.

    Returns:
        ``(r_d, ṙ_d)`` [rad/s, rad/s²].
    """
    delta = gains.delta
    c, s = np.cos(psi), np.sin(psi)
    a_u, v_dot, _ = accelerations(p, u, v, r) if acc is None else acc
    u_dot = a_u + tau_u
    y_dot = u * s + v * c
    y_ddot = u_dot * s + u * r * c + v_dot * c - v * r * s
    den = e * e + delta * delta
    psi_los_dot = -delta * y_dot / den
    psi_los_ddot = -delta * y_ddot / den + 2.0 * delta * e * y_dot * y_dot / (den * den)
    heading_error = wrap_angle(psi - los_angle(e, delta))
    if as_printed:
        feed, feed_dot = -psi_los_dot, -psi_los_ddot
    else:
        feed, feed_dot = psi_los_dot, psi_los_ddot
    r_d = feed - gains.k_psi * heading_error
    r_d_dot = feed_dot - gains.k_psi * (r - psi_los_dot)
    return r_d, r_d_dot


def heading_yaw_reference(
    psi: np.ndarray, r: np.ndarray, psi_d: np.ndarray, k_psi: float
) -> tuple[np.ndarray, np.ndarray]:
    """Desired yaw rate for a held heading command ψ_d (the ``guidance`` level).

    ``r_d = −k_ψ·(ψ − ψ_d)`` and, with ψ_d constant over the control period,
    ``ṙ_d = −k_ψ·r``. This is (14) with the LOS angle replaced by ψ_d.
    """
    return -k_psi * wrap_angle(psi - psi_d), -k_psi * r


def path_following_inputs(
    p: VesselParams,
    gains: Gains,
    e: np.ndarray,
    psi: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_c: np.ndarray,
    u_c_dot: np.ndarray | float,
    as_printed: bool = False,
    acc: Accelerations | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's complete path-following controller: (11) + (12)-(14) + (13).

    Args:
        e: cross-track error ``y − D_y`` [m].
        psi, u, v, r: own heading [rad] and body velocities.
        u_c, u_c_dot: commanded surge speed [m/s] and its rate [m/s²].
        acc: accelerations of the state, if already computed.

    Returns:
        ``(τ_u, τ_r)`` [m/s², rad/s²].
    """
    acc = accelerations(p, u, v, r) if acc is None else acc
    tau_u = surge_law(p, u, v, r, u_c, u_c_dot, gains.k_u, as_printed)
    r_d, r_d_dot = los_yaw_reference(p, e, psi, u, v, r, tau_u, gains, as_printed, acc)
    return tau_u, yaw_law(p, u, v, r, r_d, r_d_dot, gains.k_r, acc)


def heading_tracking_inputs(
    p: VesselParams,
    gains: Gains,
    psi_d: np.ndarray,
    psi: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_c: np.ndarray,
    u_c_dot: np.ndarray | float,
    as_printed: bool = False,
    acc: Accelerations | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Surge (11) and yaw (13) loops tracking ``u_c`` (with rate ``u̇_c``) and a held heading ``ψ_d``.

    The arguments are in the order of ``path_following_inputs``, with the
    heading command ``ψ_d`` where that has the cross-track error ``e``.

    Returns:
        ``(τ_u, τ_r)`` [m/s², rad/s²].
    """
    tau_u = surge_law(p, u, v, r, u_c, u_c_dot, gains.k_u, as_printed)
    r_d, r_d_dot = heading_yaw_reference(psi, r, psi_d, gains.k_psi)
    return tau_u, yaw_law(p, u, v, r, r_d, r_d_dot, gains.k_r, acc)


# ----------------------------------------------------------------------------- curved paths (docs/paths.md)
# Our generalization of (11)-(14) and (20) to a path P(ℓ) of curvature κ(ℓ), not the paper's. Every
# function below takes the vessel's path coordinates: the cross-track error e [m], the heading relative
# to the path β = ψ − γ(ℓ) [rad], the curvature κ [1/m] at its projection and the metric factor
# 1 − κ·d [-] (d = D_y + e its offset from the path), besides its velocities. κ is piecewise constant
# (lines and arcs): its derivative is zero except at the joints, where the feed-forward steps.


def turn_sway(p: VesselParams, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``q(u) = −X(u)/Y(u)`` [m] and ``q'(u)``: the sway of steady turning is ``v = q(u)·r`` (``v̇ = 0`` in (3)).

    X and Y are affine in u (docs/model.md §1), so ``q' = −(X'·Y − X·Y')/Y²``.
    """
    x, y = _sway_coupling(p, u), _sway_damping(p, u)
    x_slope = _sway_coupling(p, 1.0) - _sway_coupling(p, 0.0)
    y_slope = _sway_damping(p, 1.0) - _sway_damping(p, 0.0)
    return -x / y, -(x_slope * y - x * y_slope) / (y * y)  # type: ignore[no-any-return]


def _sway_coupling(p: VesselParams, u: Any) -> Any:
    """X(u) of ``VesselParams.sway_coupling``, on the fields only (the compiled kernel's vessel is a tuple)."""
    return ((p.m23**2 - p.m11 * p.m33) * u + p.m23 * p.d33 - p.m33 * p.d23) / p.lam


def _sway_damping(p: VesselParams, u: Any) -> Any:
    """Y(u) of ``VesselParams.sway_damping``, on the fields only."""
    return ((p.m22 - p.m11) * p.m23 * u - (p.m33 * p.d22 - p.m23 * p.d32)) / p.lam


def lane_speed(
    p: VesselParams, w: np.ndarray, w_dot: np.ndarray | float, kappa: np.ndarray, d_y: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Surge command that moves a vessel's projection at ``w`` along its lane, and its rate.

    In steady turning on lane ``D_y`` (``e = 0``) at projection speed ``w``,
    the vessel turns at ``r = κ·w`` and moves along its lane at
    ``U = (1 − κ·D_y)·w`` (faster on the outer lane), with the sway
    ``v = q(u)·r`` of ``turn_sway``; so its surge speed solves
    ``u² + (q(u)·κ·w)² = U²``. Three fixed-point steps
    ``u ← U − v²/(U + √(U² − v²))`` solve it (``q`` varies slowly with u).
    The rate follows from differentiating that relation with κ constant
    between joints: ``u̇ = (U·U̇ − q²·Ω·Ω̇)/(u + q·q'·Ω²)`` with ``Ω = κ·w``.
    On a straight part (κ = 0) this is ``u_c = w``, ``u̇_c = ẇ`` exactly.
    """
    factor = 1.0 - kappa * d_y
    lane, lane_dot = factor * w, factor * w_dot
    omega, omega_dot = kappa * w, kappa * w_dot
    u = lane
    for _ in range(3):
        sway = turn_sway(p, u)[0] * omega
        den = lane + np.sqrt(np.maximum(lane * lane - sway * sway, 0.0))
        u = lane - sway * sway / np.where(den == 0.0, 1.0, den)  # sway = 0 (a straight part): u = lane exactly
    q, q_slope = turn_sway(p, u)
    den = u + q * q_slope * omega * omega
    safe = np.where(den == 0.0, 1.0, den)
    ratio = np.where(den == 0.0, 1.0, lane / safe)  # 1 exactly on a straight part (den = u = lane)
    return u, lane_dot * ratio - q * q * omega * omega_dot / safe


def path_rates(
    beta: np.ndarray,
    kappa: np.ndarray,
    metric: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_dot: np.ndarray,
    v_dot: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(ℓ̇, ℓ̈, ė, ë)`` of a vessel in path coordinates (docs/paths.md, "Kinematics").

    ::

        ℓ̇ = (u cos β − v sin β)/(1 − κ·d)        ė = u sin β + v cos β
        β̇ = r − κ·ℓ̇
        ℓ̈ = (u̇ cos β − v̇ sin β − β̇·ė + κ·ė·ℓ̇)/(1 − κ·d)
        ë = u̇ sin β + u·β̇ cos β + v̇ cos β − v·β̇ sin β
    """
    cb, sb = np.cos(beta), np.sin(beta)
    ell_dot = (u * cb - v * sb) / metric
    e_dot = u * sb + v * cb
    beta_dot = r - kappa * ell_dot
    ell_ddot = (u_dot * cb - v_dot * sb - beta_dot * e_dot + kappa * e_dot * ell_dot) / metric
    e_ddot = u_dot * sb + u * beta_dot * cb + v_dot * cb - v * beta_dot * sb
    return ell_dot, ell_ddot, e_dot, e_ddot


def curved_path_following_inputs(
    p: VesselParams,
    gains: Gains,
    e: np.ndarray,
    beta: np.ndarray,
    kappa: np.ndarray,
    metric: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_c: np.ndarray,
    u_c_dot: np.ndarray | float,
    acc: Accelerations | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Surge (11) and LOS (12)-(14) on a curved path, with (13): ``(τ_u, τ_r)`` [m/s², rad/s²].

    ``ψ_LOS = γ(ℓ) − atan(e/Δ)``, so ``ψ − ψ_LOS = β + atan(e/Δ)`` and::

        ψ̇_LOS = κ·ℓ̇ − Δ·ė/(e² + Δ²)
        ψ̈_LOS = κ·ℓ̈ − Δ·ë/(e² + Δ²) + 2·Δ·e·ė²/(e² + Δ²)²      (κ' = 0 between joints)
        r_d = ψ̇_LOS − k_ψ·(ψ − ψ_LOS),   ṙ_d = ψ̈_LOS − k_ψ·(r − ψ̇_LOS)

    and ψ_LOS is further corrected by the crab angle of steady turning
    (``turn_crab``), whose rate enters ψ̇_LOS; its second derivative
    (which would need v̈, hence ṙ) is left out of ψ̈_LOS: it vanishes in steady
    turning and on straight parts, and only the transients feel it. With
    ``κ = 0`` these are (12)-(14) of the straight path (docs/model.md §3).
    ``e`` is the error LOS steers on (with integral LOS, ``e + σ·e_int``);
    ``metric`` is ``1 − κ·d`` with the vessel's true offset ``d``.
    """
    acc = accelerations(p, u, v, r) if acc is None else acc
    a_u, v_dot, _ = acc
    tau_u = surge_law(p, u, v, r, u_c, u_c_dot, gains.k_u)
    u_dot = a_u + tau_u
    ell_dot, ell_ddot, e_dot, e_ddot = path_rates(beta, kappa, metric, u, v, r, u_dot, v_dot)
    crab, crab_dot = turn_crab(p, kappa, u, u_dot, ell_dot, ell_ddot)
    delta = gains.delta
    den = e * e + delta * delta
    psi_los_dot = kappa * ell_dot - delta * e_dot / den - crab_dot
    psi_los_ddot = kappa * ell_ddot - delta * e_ddot / den + 2.0 * delta * e * e_dot * e_dot / (den * den)
    r_d = psi_los_dot - gains.k_psi * wrap_angle(beta + np.arctan(e / delta) + crab)
    r_d_dot = psi_los_ddot - gains.k_psi * (r - psi_los_dot)
    return tau_u, yaw_law(p, u, v, r, r_d, r_d_dot, gains.k_r, acc)


def turn_crab(
    p: VesselParams,
    kappa: np.ndarray,
    u: np.ndarray,
    u_dot: np.ndarray | float,
    ell_dot: np.ndarray,
    ell_ddot: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray]:
    """The crab angle of steady turning at the path's rate, ``atan(q(u)·κ·ℓ̇/u)`` [rad], and its rate.

    A vessel turning with the path (``r = κ·ℓ̇``) sways at ``v = q(u)·r``
    (``turn_sway``), so its velocity points ``atan(v/u)`` off its heading;
    LOS on a curved path adds minus this angle to ψ_LOS, or it would settle
    ``Δ·v/u`` off the lane (docs/paths.md, "LOS on a curved path"). Zero on
    straight parts. ``u`` below 0.5 m/s is taken as 0.5 m/s.
    """
    speed = np.maximum(u, 0.5)
    q, q_slope = turn_sway(p, speed)
    ratio = q * kappa * ell_dot / speed
    ratio_dot = kappa * ((q_slope * u_dot * ell_dot + q * ell_ddot) - q * ell_dot * u_dot / speed) / speed
    return np.arctan(ratio), ratio_dot / (1.0 + ratio * ratio)


def curved_heading_inputs(
    p: VesselParams,
    gains: Gains,
    beta_d: np.ndarray,
    beta: np.ndarray,
    kappa: np.ndarray,
    metric: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    r: np.ndarray,
    u_c: np.ndarray,
    u_c_dot: np.ndarray | float,
    acc: Accelerations | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``guidance`` level's loops on a curved path: surge (11) and a heading ``β_d`` relative to the path.

    The desired heading ``ψ_d = γ(ℓ) + β_d`` turns with the path
    (``ψ̇_d = κ·ℓ̇``), so ``r_d = κ·ℓ̇ − k_ψ·(β − β_d)`` and
    ``ṙ_d = κ·ℓ̈ − k_ψ·(r − κ·ℓ̇)``; with ``κ = 0`` this is
    ``heading_tracking_inputs`` with a held ψ_d.
    """
    acc = accelerations(p, u, v, r) if acc is None else acc
    a_u, v_dot, _ = acc
    tau_u = surge_law(p, u, v, r, u_c, u_c_dot, gains.k_u)
    ell_dot, ell_ddot, _, _ = path_rates(beta, kappa, metric, u, v, r, a_u + tau_u, v_dot)
    turn = kappa * ell_dot
    r_d = turn - gains.k_psi * wrap_angle(beta - beta_d)
    r_d_dot = kappa * ell_ddot - gains.k_psi * (r - turn)
    return tau_u, yaw_law(p, u, v, r, r_d, r_d_dot, gains.k_r, acc)
