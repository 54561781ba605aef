"""An independent implementation of the paper's vessel model, for the tests.

Written from eqs. (1)-(4) of the paper with M, C(ν) and D as matrices and a
linear solve, sharing no code with ``marine_formation_env.dynamics``.
"""

from __future__ import annotations

import math

import numpy as np

from marine_formation_env.params import VesselParams


def model_rhs(p: VesselParams, state: np.ndarray, tau_u: float, tau_r: float) -> np.ndarray:
    """Eqs. (1)-(4): M ν̇ + C(ν)ν + Dν = Bu with M⁻¹Bu = [τ_u, 0, τ_r]ᵀ, one state of shape (6,)."""
    _, _, psi, u, v, r = state
    m_mat = np.array([[p.m11, 0.0, 0.0], [0.0, p.m22, p.m23], [0.0, p.m23, p.m33]])
    d_mat = np.array([[p.d11, 0.0, 0.0], [0.0, p.d22, p.d23], [0.0, p.d32, p.d33]])
    c_mat = np.array(
        [
            [0.0, 0.0, -p.m22 * v - p.m23 * r],
            [0.0, 0.0, p.m11 * u],
            [p.m22 * v + p.m23 * r, -p.m11 * u, 0.0],
        ]
    )
    nu = np.array([u, v, r])
    bu = m_mat @ np.array([tau_u, 0.0, tau_r])
    nu_dot = np.linalg.solve(m_mat, bu - c_mat @ nu - d_mat @ nu)
    rot = np.array([[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0], [0.0, 0.0, 1.0]])
    return np.concatenate([rot @ nu, nu_dot])
