"""Vessel parameter sets and controller gains.

Every number in this module carries its source. The model is the 3-DOF
surge/sway/yaw model of the paper (eqs. 1-4, docs/model.md §1):

    M ν̇ + C(ν) ν + D ν = B u,     M⁻¹ B u = [τ_u, 0, τ_r]ᵀ

with ``M = [[m11, 0, 0], [0, m22, m23], [0, m23, m33]]`` and
``D = [[d11, 0, 0], [0, d22, d23], [0, d32, d33]]`` in SI units (kg, kg·m,
kg·m², kg/s, kg·m/s, kg·m²/s).

The paper gives no numbers; the default set ``SUPPLY`` is the supply
vessel of Fossen, Sagatun & Sørensen (1996), built from its published
nondimensional (bis-system) data exactly as docs/model.md §2 describes, so the table in
docs/model.md §2 is *computed* here and checked by the tests rather than typed in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real

import numpy as np

__all__ = [
    "SUPPLY",
    "VESSELS",
    "Gains",
    "ParameterError",
    "VesselParams",
    "get_vessel",
]


class ParameterError(ValueError):
    """A parameter set or gain violates an assumption of the paper."""


@dataclass(frozen=True)
class VesselParams:
    """Rigid-body + hydrodynamic parameters of one vessel (SI units).

    The body origin is assumed to be placed so that the actuators do not
    accelerate sway (the paper's ``M⁻¹Bu = [τ_u, 0, τ_r]ᵀ``).

    Attributes:
        name: short identifier (used by ``vessel=`` overrides).
        source: bibliographic source of the numbers.
        m11, m22, m23, m33: mass/inertia matrix entries [kg, kg, kg·m, kg·m²].
        d11, d22, d23, d32, d33: linear damping entries
            [kg/s, kg/s, kg·m/s, kg·m/s, kg·m²/s].
        length: hull length [m] (drawing and separation checks only).
        beam: hull beam [m] (drawing only).
    """

    name: str
    source: str
    m11: float
    m22: float
    m23: float
    m33: float
    d11: float
    d22: float
    d23: float
    d32: float
    d33: float
    length: float = 0.0
    beam: float = 0.0

    def __post_init__(self) -> None:
        for key in ("m11", "m22", "m33", "d11"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError(f"vessel {self.name!r}: {key} must be finite and > 0, got {value!r}")
        for key in ("m23", "d22", "d23", "d32", "d33"):
            value = getattr(self, key)
            if not math.isfinite(value):
                raise ParameterError(f"vessel {self.name!r}: {key} must be finite, got {value!r}")
        if self.lam <= 0.0:
            raise ParameterError(
                f"vessel {self.name!r}: M must be positive definite, but Λ = m22·m33 − m23² = {self.lam:.6g} ≤ 0"
            )

    # ------------------------------------------------------------------ derived
    @property
    def lam(self) -> float:
        """Λ = m22·m33 − m23² (> 0 since M = Mᵀ > 0) [kg²·m²]."""
        return self.m22 * self.m33 - self.m23**2

    def sway_coupling(self, u: float | np.ndarray) -> float | np.ndarray:
        """X(u) [m/s]: the yaw-rate-to-sway gain in ``v̇ = X(u)·r + Y(u)·v`` (docs/model.md §1)."""
        return ((self.m23**2 - self.m11 * self.m33) * u + self.m23 * self.d33 - self.m33 * self.d23) / self.lam

    def sway_damping(self, u: float | np.ndarray) -> float | np.ndarray:
        """Y(u) [1/s]: the sway self-coupling in ``v̇ = X(u)·r + Y(u)·v`` (docs/model.md §1).

        ``Y(u) < 0`` is the paper's assumption 5 (sway is damped).
        """
        return ((self.m22 - self.m11) * self.m23 * u - (self.m33 * self.d22 - self.m23 * self.d32)) / self.lam

    def sway_ratio_bound(self, u_min: float, u_max: float, samples: int = 2001) -> float:
        """C_v·U_max [m]: max over u ∈ [u_min, u_max] of |X(u)/Y(u)|.

        In a steady turn ``|v| = |X(u)/Y(u)|·|r|``, so this is the smallest
        C_v·U_max for which assumption (5) holds on the speed band; Proposition 1
        needs the look-ahead distance Δ above it.
        """
        u = np.linspace(u_min, u_max, samples)
        return float(np.max(np.abs(self.sway_coupling(u) / self.sway_damping(u))))

    def validate_speed_band(self, u_min: float, u_max: float, delta: float) -> None:
        """Check the paper's assumptions for this vessel on ``[u_min, u_max]``.

        Raises:
            ParameterError: if sway is not damped (Y(u) ≥ 0) somewhere on the
                band, or if Δ ≤ C_v·U_max (Proposition 1).
        """
        band = f"the speed band [u_min, u_max] = [{u_min}, {u_max}] m/s"
        with np.errstate(over="ignore", invalid="ignore"):
            u = np.linspace(u_min, u_max, 2001)
            y = self.sway_damping(u)
            bound = self.sway_ratio_bound(u_min, u_max)
        if not (np.all(np.isfinite(y)) and math.isfinite(bound)):
            raise ParameterError(f"vessel {self.name!r}: the sway model overflows on {band}; choose a physical band")
        if np.any(y >= 0.0):
            bad = float(u[np.argmax(y)])
            raise ParameterError(
                f"vessel {self.name!r}: sway is not damped on {band}: Y(u={bad:.3g}) = {float(np.max(y)):.4g} 1/s ≥ 0 "
                "(the paper's assumption 5 requires Y(u) < 0)"
            )
        if not delta > bound:
            raise ParameterError(
                f"look-ahead distance Δ = {delta} m (gains.delta) must exceed C_v·U_max = {bound:.4g} m "
                f"for vessel {self.name!r} on {band} (Proposition 1)"
            )

    def as_array(self) -> np.ndarray:
        """The nine model coefficients ``[m11, m22, m23, m33, d11, d22, d23, d32, d33]``."""
        return np.array([self.m11, self.m22, self.m23, self.m33, self.d11, self.d22, self.d23, self.d32, self.d33])

    # -------------------------------------------------------------- constructors
    @classmethod
    def from_nondimensional(
        cls,
        *,
        name: str,
        source: str,
        length: float,
        mass: float,
        m_nd: Sequence[Sequence[float]],
        d_nd: Sequence[Sequence[float]],
        rudder_x: float,
        beam: float = 0.0,
        gravity: float = 9.81,
    ) -> VesselParams:
        """Build a parameter set from bis-system (nondimensional) data.

        ``M = m·T⁻¹·M''·T⁻¹`` and ``D = m·sqrt(g/L)·T⁻¹·D''·T⁻¹`` with
        ``T⁻¹ = diag(1, 1, L)`` (Fossen's bis system), then the body origin is
        moved forward by ``x_p = (l·m23 − m33)/(l·m22 − m23)`` (``l`` =
        ``rudder_x``, the lever arm of the yaw actuator) so that the yaw
        actuator does not accelerate sway (docs/model.md §2).
        """
        t_inv = np.diag([1.0, 1.0, length])
        m_mat = mass * t_inv @ np.asarray(m_nd, dtype=float) @ t_inv
        d_mat = mass * math.sqrt(gravity / length) * t_inv @ np.asarray(d_nd, dtype=float) @ t_inv
        m22, m23, m33 = m_mat[1, 1], m_mat[1, 2], m_mat[2, 2]
        d22, d23, d32, d33 = d_mat[1, 1], d_mat[1, 2], d_mat[2, 1], d_mat[2, 2]
        x_p = (rudder_x * m23 - m33) / (rudder_x * m22 - m23)
        return cls(
            name=name,
            source=source,
            m11=float(m_mat[0, 0]),
            m22=float(m22),
            m23=float(m23 - x_p * m22),
            m33=float(m33 - 2.0 * x_p * m23 + x_p**2 * m22),
            d11=float(d_mat[0, 0]),
            d22=float(d22),
            d23=float(d23 - x_p * d22),
            d32=float(d32 - x_p * d22),
            d33=float(d33 - x_p * (d23 + d32) + x_p**2 * d22),
            length=length,
            beam=beam,
        )


#: Supply vessel (L = 76.2 m, m = 6000 t) of Fossen, Sagatun & Sørensen (1996),
#: "Identification of dynamically positioned ships", Control Engineering
#: Practice 4(3), as published in Fossen's MSS toolbox (``supply.m``) and Python
#: Vehicle Simulator (``supply.py``). Origin moved to x_p = 7.929 m ahead of the
#: original so that a rudder at l = −L/2 does not accelerate sway (docs/model.md §2).
#: The beam (18.8 m) is only used for drawing.
SUPPLY = VesselParams.from_nondimensional(
    name="supply",
    source=(
        "Fossen, Sagatun & Sorensen (1996), Control Engineering Practice 4(3); "
        "MSS toolbox supply.m / Python Vehicle Simulator supply.py; origin shifted "
        "to x_p = (l*m23 - m33)/(l*m22 - m23), l = -L/2 (docs/model.md §2)"
    ),
    length=76.2,
    mass=6.0e6,
    m_nd=[[1.1274, 0.0, 0.0], [0.0, 1.8902, -0.0744], [0.0, -0.0744, 0.1278]],
    d_nd=[[0.0358, 0.0, 0.0], [0.0, 0.1183, -0.0124], [0.0, -0.0041, 0.0308]],
    rudder_x=-76.2 / 2.0,
    beam=18.8,
)

#: Registered vessel parameter sets, by name.
VESSELS: dict[str, VesselParams] = {SUPPLY.name: SUPPLY}


def get_vessel(vessel: str | VesselParams) -> VesselParams:
    """Return a parameter set by name (or pass one through).

    Raises:
        ValueError: for an unknown name, listing the known ones.
    """
    if isinstance(vessel, VesselParams):
        return vessel
    try:
        return VESSELS[vessel]
    except (KeyError, TypeError):
        raise ValueError(f"unknown vessel {vessel!r}; known vessels: {sorted(VESSELS)}") from None


@dataclass(frozen=True)
class Gains:
    """Controller gains and the consensus saturation (paper Section V values).

    Attributes:
        k_u: surge tracking gain in (11) [1/s].
        k_psi: heading gain in (14) [1/s].
        k_r: yaw-rate gain in (13) [1/s].
        delta: LOS look-ahead distance Δ in (12) [m].
        a: consensus saturation a in g(s) = (2a/π)·atan(s) [m/s]; (19) needs
            u_d(t) ∈ [U_min + a, U_max − a].
    """

    k_u: float = 0.5
    k_psi: float = 0.5
    k_r: float = 5.0
    delta: float = 70.0
    a: float = 1.0

    def __post_init__(self) -> None:
        for key in ("k_u", "k_psi", "k_r", "delta", "a"):
            value = getattr(self, key)
            number = float(value) if isinstance(value, Real) and not isinstance(value, bool) else math.nan
            if not (math.isfinite(number) and number > 0.0):
                name = "Δ (gains.delta)" if key == "delta" else f"gains.{key}"
                raise ParameterError(f"gain {name} must be a finite number > 0, got {value!r}")
            object.__setattr__(self, key, number)
