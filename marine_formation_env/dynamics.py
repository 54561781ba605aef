"""The vessel ODE of docs/model.md §1 (paper eqs. 1-4), batched, and its RK4 integrator.

State arrays have the columns ``x, y, psi, u, v, r`` in the last axis and any
number of leading batch axes, typically ``(B, N, 6)`` for B formations of N
vessels. Units: m, m, rad, m/s, m/s, rad/s. The actuated inputs are the
accelerations ``τ_u`` [m/s²] and ``τ_r`` [rad/s²] with the leading shape of the
state (the paper's ``M⁻¹Bu = [τ_u, 0, τ_r]ᵀ``).

This is the only place where the equations of motion are written down; the
controllers in ``marine_formation_env.control`` use ``accelerations``
for their feedback-linearizing terms, so the model and the model-based
controller cannot drift apart.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from marine_formation_env.params import VesselParams
from marine_formation_env.rules import rk4_combine

__all__ = [
    "PSI",
    "R",
    "U",
    "V",
    "X",
    "Y",
    "accelerations",
    "current_velocity",
    "rk4_step",
    "vessel_rhs",
    "wrap_angle",
]

#: Column indices of the state vector.
X, Y, PSI, U, V, R = range(6)


def wrap_angle(angle: Any) -> Any:
    """Wrap an angle [rad] to ``[−π, π)`` (Fossen's smallest signed angle); scalars or arrays."""
    wrapped = np.mod(angle + np.pi, 2.0 * np.pi) - np.pi
    # np.mod rounds a tiny negative argument up to 2π; keep the interval half-open.
    return wrapped - (2.0 * np.pi) * (wrapped >= np.pi)


def accelerations(
    p: VesselParams, u: np.ndarray, v: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unforced body accelerations of eq. (4).

    Returns ``(a_u, v_dot, a_r)`` such that ``u̇ = a_u + τ_u``, ``v̇ = v_dot``
    and ``ṙ = a_r + τ_r`` (docs/model.md §1)::

        a_u   = [(m22·v + m23·r)·r − d11·u] / m11
        f2    = −m11·u·r − d22·v − d23·r
        f3    = (−m22·v − m23·r)·u + m11·u·v − d32·v − d33·r
        v_dot = (m33·f2 − m23·f3) / Λ
        a_r   = (m22·f3 − m23·f2) / Λ

    Args:
        p: vessel parameters.
        u, v, r: surge [m/s], sway [m/s] and yaw rate [rad/s], same shape.
    """
    m22v_m23r = p.m22 * v + p.m23 * r
    a_u = (m22v_m23r * r - p.d11 * u) / p.m11
    f2 = -p.m11 * u * r - p.d22 * v - p.d23 * r
    f3 = -m22v_m23r * u + p.m11 * u * v - p.d32 * v - p.d33 * r
    inv_lam = 1.0 / p.lam
    v_dot = (p.m33 * f2 - p.m23 * f3) * inv_lam
    a_r = (p.m22 * f3 - p.m23 * f2) * inv_lam
    return a_u, v_dot, a_r


def current_velocity(speed: float, amplitude: float, omega: float, cos_dir: float, sin_dir: float, t: Any) -> Any:
    """Inertial ocean-current velocity ``(V_x, V_y)`` [m/s] at time ``t`` [s].

    ``V_c(t) = (speed + amplitude·sin(ω·t))·(cos β, sin β)``: a current of
    fixed direction β (the direction it flows *towards*, from the x axis)
    whose magnitude varies slowly around ``speed`` (``amplitude = 0``: the
    constant current of Børhaug, Pavlov and Pettersen, CDC 2008).
    Scalars or arrays (also compiled by the numba backend).
    """
    magnitude = speed + amplitude * np.sin(omega * t)
    return magnitude * cos_dir, magnitude * sin_dir


def vessel_derivatives(
    p: VesselParams,
    psi: Any,
    u: Any,
    v: Any,
    r: Any,
    tau_u: Any,
    tau_r: Any,
    acc: tuple[Any, Any, Any] | None = None,
    vc_x: Any = None,
    vc_y: Any = None,
) -> tuple[Any, Any, Any, Any, Any, Any]:
    """Eqs. (1)-(4) component by component: ``(ẋ, ẏ, ψ̇, u̇, v̇, ṙ)``.

    With an ocean current ``(vc_x, vc_y)`` [m/s] (inertial frame; None: still
    water), ``u, v`` are
    the velocities *relative to the water* and the kinematics become
    ``η̇ = R(ψ)·ν_r + V_c`` (Børhaug, Pavlov, Pettersen, CDC 2008). For an
    irrotational constant current the kinetics in relative velocities are
    exactly eqs. (2)-(4); for a slowly varying one the current's acceleration
    is neglected. Without a current (the default) this is the paper's model.

    Works element-wise on scalars or arrays of one shape (it is also compiled
    by the optional numba backend, so it sticks to arithmetic and ufuncs).
    """
    c, s = np.cos(psi), np.sin(psi)
    a_u, v_dot, a_r = accelerations(p, u, v, r) if acc is None else acc
    x_dot, y_dot = u * c - v * s, u * s + v * c
    if vc_x is not None and vc_y is not None:
        x_dot, y_dot = x_dot + vc_x, y_dot + vc_y
    return x_dot, y_dot, r, a_u + tau_u, v_dot, a_r + tau_r


def vessel_rhs(
    p: VesselParams,
    state: np.ndarray,
    tau_u: np.ndarray,
    tau_r: np.ndarray,
    acc: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    current: tuple[Any, Any] | None = None,
) -> np.ndarray:
    """Time derivative of ``state`` (shape ``(..., 6)``) under inputs τ_u, τ_r (eqs. 1-4).

    Args:
        p: vessel parameters.
        state: ``(..., 6)`` array, columns ``x, y, psi, u, v, r``.
        tau_u: surge acceleration input [m/s²], shape ``state.shape[:-1]``.
        tau_r: yaw acceleration input [rad/s²], shape ``state.shape[:-1]``.
        acc: ``accelerations`` of this state, if already computed.
        current: inertial current velocity ``(V_x, V_y)`` [m/s], broadcastable
            to ``state.shape[:-1]`` (see ``vessel_derivatives``); None: still water.

    Returns:
        ``(..., 6)`` array ``(ẋ, ẏ, ψ̇, u̇, v̇, ṙ)``.
    """
    out = np.empty_like(state)
    vc_x, vc_y = (None, None) if current is None else current
    derivs = vessel_derivatives(
        p, state[..., PSI], state[..., U], state[..., V], state[..., R], tau_u, tau_r, acc, vc_x, vc_y
    )
    for k, value in enumerate(derivs):
        out[..., k] = value
    return out


def rk4_step(rhs: Callable[[float, np.ndarray], np.ndarray], state: np.ndarray, h: float, t: float = 0.0) -> np.ndarray:
    """One classical fourth-order Runge-Kutta step of ``ẏ = rhs(t, y)`` from time ``t`` with step ``h`` [s].

    ``rhs`` follows scipy's ``fun(t, y)`` convention. The closed-loop inner
    controllers are part of ``rhs``, which is why they act at every stage.
    """
    half = 0.5 * h
    k1 = rhs(t, state)
    k2 = rhs(t + half, state + half * k1)
    k3 = rhs(t + half, state + half * k2)
    k4 = rhs(t + h, state + h * k3)
    return rk4_combine(state, k1, k2, k3, k4, h)
