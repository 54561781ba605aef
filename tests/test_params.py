"""Tests of :mod:`marine_formation_env.params` against docs/model.md §1–§2 and first principles.

Independent truths used here:

* the docs/model.md §2 table of SI values (typed in below, as published there);
* the origin shift derived from rigid-body kinematics: moving the body origin
  forward by ``x_p`` gives ``ν_old = H ν_new`` with ``H = [[1,0,0],[0,1,−x_p],[0,0,1]]``,
  hence ``M' = Hᵀ M H`` and ``D' = Hᵀ D H`` (congruence, not the code's
  element-wise formulas);
* ``X(u)``, ``Y(u)`` recomputed from the paper's matrices M, C(ν), D: for a fixed
  surge speed the sway/yaw rows of ``−M⁻¹(C(ν)+D)ν`` are linear in ``(v, r)``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from marine_formation_env.params import SUPPLY, VESSELS, Gains, ParameterError, VesselParams, get_vessel

pytestmark = pytest.mark.backend_independent

# --------------------------------------------------------------------------- data
# docs/model.md §2 table (SI units).
MODEL_TABLE = {
    "m11": 6.7644e6,
    "m22": 1.13412e7,
    "m23": -1.2394e8,
    "m33": 5.7048e9,
    "d11": 7.7071e4,
    "d22": 2.54679e5,
    "d23": -4.0535e6,
    "d32": -2.6919e6,
    "d33": 4.2248e8,
}

# docs/model.md §2 raw data of the supply vessel (Fossen, Sagatun & Sørensen 1996).
L_SUPPLY = 76.2
MASS = 6.0e6
GRAVITY = 9.81
M_ND = np.array([[1.1274, 0.0, 0.0], [0.0, 1.8902, -0.0744], [0.0, -0.0744, 0.1278]])
D_ND = np.array([[0.0358, 0.0, 0.0], [0.0, 0.1183, -0.0124], [0.0, -0.0041, 0.0308]])

# CyberShip II (Skjetne, Fossen & Kokotović 2005, Automatica 41) with linear
# damping only: m11 = m − X_u̇, m22 = m − Y_v̇, m23 = m·x_g − Y_ṙ, m33 = I_z − N_ṙ,
# d11 = −X_u, d22 = −Y_v, d23 = −Y_r, d32 = −N_v, d33 = −N_r.
# docs/model.md §2: it has Y > 0 at the Froude-equivalent speed, so it must be rejected.
CYBERSHIP2_LINEAR = dict(
    m11=25.8,
    m22=33.8,
    m23=1.0948,
    m33=2.76,
    d11=0.7225,
    d22=0.8612,
    d23=-0.1079,
    d32=-0.1052,
    d33=0.5,
)
L_CS2 = 1.255


def _fields(p: VesselParams) -> dict[str, float]:
    return {k: getattr(p, k) for k in MODEL_TABLE}


def _original_matrices() -> tuple[np.ndarray, np.ndarray]:
    """M and D of the supply vessel before the origin shift (bis system, docs/model.md §2)."""
    t_inv = np.diag([1.0, 1.0, L_SUPPLY])
    m_mat = MASS * t_inv @ M_ND @ t_inv
    d_mat = MASS * math.sqrt(GRAVITY / L_SUPPLY) * t_inv @ D_ND @ t_inv
    return m_mat, d_mat


def _sway_yaw_system(f: dict[str, float], u: float) -> np.ndarray:
    """A(u) with (v̇, ṙ) = A(u)·(v, r) for τ = 0, from the paper's M, C(ν), D.

    Rows 2-3 of C(ν)ν + Dν are
        m11·u·r + d22·v + d23·r
        (m22·v + m23·r)·u − m11·u·v + d32·v + d33·r,
    which are linear in (v, r) for fixed u.
    """
    m_sub = np.array([[f["m22"], f["m23"]], [f["m23"], f["m33"]]])
    n_mat = np.array(
        [
            [f["d22"], f["m11"] * u + f["d23"]],
            [(f["m22"] - f["m11"]) * u + f["d32"], f["m23"] * u + f["d33"]],
        ]
    )
    return -np.linalg.solve(m_sub, n_mat)


# --------------------------------------------------------------------- docs/model.md table
@pytest.mark.parametrize("key", list(MODEL_TABLE))
def test_supply_matches_spec_table(key: str) -> None:
    # The table has at least 5 significant digits; require agreement to 4 (rel 5e-5).
    assert getattr(SUPPLY, key) == pytest.approx(MODEL_TABLE[key], rel=5e-5)


def test_supply_is_registered_and_has_a_source() -> None:
    assert VESSELS["supply"] is SUPPLY
    assert get_vessel("supply") is SUPPLY
    assert get_vessel(SUPPLY) is SUPPLY
    assert "Fossen" in SUPPLY.source
    assert SUPPLY.length == pytest.approx(L_SUPPLY)
    np.testing.assert_allclose(SUPPLY.as_array(), [MODEL_TABLE[k] for k in MODEL_TABLE], rtol=5e-5)


def test_supply_equals_congruence_transform_of_original_matrices() -> None:
    """M' = HᵀMH, D' = HᵀDH with the docs/model.md §2 shift x_p (independent of the code's formulas)."""
    m_mat, d_mat = _original_matrices()
    lever = -L_SUPPLY / 2.0
    m22, m23, m33 = m_mat[1, 1], m_mat[1, 2], m_mat[2, 2]
    x_p = (lever * m23 - m33) / (lever * m22 - m23)
    h = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -x_p], [0.0, 0.0, 1.0]])
    m_new = h.T @ m_mat @ h
    d_new = h.T @ d_mat @ h
    expected = {
        "m11": m_new[0, 0],
        "m22": m_new[1, 1],
        "m23": m_new[1, 2],
        "m33": m_new[2, 2],
        "d11": d_new[0, 0],
        "d22": d_new[1, 1],
        "d23": d_new[1, 2],
        "d32": d_new[2, 1],
        "d33": d_new[2, 2],
    }
    # the congruence keeps M symmetric
    assert m_new[1, 2] == pytest.approx(m_new[2, 1], rel=1e-14)
    for key, value in expected.items():
        assert getattr(SUPPLY, key) == pytest.approx(value, rel=1e-10), key


def test_origin_shift_is_7_929_m() -> None:
    m_mat, _ = _original_matrices()
    # m23' = m23 − x_p·m22  ⇒  x_p = (m23 − m23')/m22
    x_p = (m_mat[1, 2] - SUPPLY.m23) / m_mat[1, 1]
    assert x_p == pytest.approx(7.929, abs=5e-4)


def test_rudder_force_does_not_accelerate_sway_after_shift() -> None:
    """A lateral force at the rudder (x = −L/2 in the original frame) gives M⁻¹B with zero sway row.

    In the shifted frame the rudder sits at l' = −L/2 − x_p; a unit lateral force
    there is the generalized force [0, 1, l'] and a surge thrust is [1, 0, 0].
    """
    m_orig, _ = _original_matrices()
    x_p = (m_orig[1, 2] - SUPPLY.m23) / m_orig[1, 1]
    lever_new = -L_SUPPLY / 2.0 - x_p
    m_new = np.array([[SUPPLY.m11, 0.0, 0.0], [0.0, SUPPLY.m22, SUPPLY.m23], [0.0, SUPPLY.m23, SUPPLY.m33]])
    b = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, lever_new]])
    acc = np.linalg.solve(m_new, b)
    assert abs(acc[1, 1]) < 1e-9 * abs(acc[2, 1])  # no sway acceleration from the rudder
    assert acc[1, 0] == 0.0 and acc[2, 0] == 0.0  # thrust only accelerates surge
    assert abs(acc[2, 1]) > 0.0  # but the rudder does turn the vessel
    # Sanity: in the original frame the same rudder *does* accelerate sway, so the
    # assertion above is not vacuous.
    acc_orig = np.linalg.solve(m_orig, np.array([0.0, 1.0, -L_SUPPLY / 2.0]))
    assert abs(acc_orig[1]) > 0.1 * abs(acc_orig[2]) * L_SUPPLY


def test_supply_mass_matrix_and_damping_are_positive_definite() -> None:
    m_mat = np.array([[SUPPLY.m11, 0, 0], [0, SUPPLY.m22, SUPPLY.m23], [0, SUPPLY.m23, SUPPLY.m33]])
    d_mat = np.array([[SUPPLY.d11, 0, 0], [0, SUPPLY.d22, SUPPLY.d23], [0, SUPPLY.d32, SUPPLY.d33]])
    assert np.all(np.linalg.eigvalsh(m_mat) > 0)
    assert np.all(np.linalg.eigvalsh(0.5 * (d_mat + d_mat.T)) > 0)
    assert SUPPLY.lam == pytest.approx(np.linalg.det(m_mat[1:, 1:]), rel=1e-12)


# --------------------------------------------------------------- X(u), Y(u), C_v
def test_sway_coefficients_at_5_mps_match_spec() -> None:
    a5 = _sway_yaw_system(_fields(SUPPLY), 5.0)
    x5, y5 = a5[0, 1], a5[0, 0]
    assert x5 == pytest.approx(-2.947, abs=5e-4)
    assert y5 == pytest.approx(-0.0802, abs=5e-5)
    assert SUPPLY.sway_coupling(5.0) == pytest.approx(-2.947, abs=5e-4)
    assert SUPPLY.sway_damping(5.0) == pytest.approx(-0.0802, abs=5e-5)


@pytest.mark.parametrize("u", [0.0, 1.0, 3.0, 4.2, 5.0, 6.5, 7.0, 12.0])
def test_sway_coefficients_match_model_matrices(u: float) -> None:
    a = _sway_yaw_system(_fields(SUPPLY), u)
    assert SUPPLY.sway_coupling(u) == pytest.approx(a[0, 1], rel=1e-10, abs=1e-14)
    assert SUPPLY.sway_damping(u) == pytest.approx(a[0, 0], rel=1e-10, abs=1e-14)


def test_sway_is_damped_on_the_speed_band() -> None:
    for u in np.linspace(3.0, 7.0, 41):
        assert _sway_yaw_system(_fields(SUPPLY), u)[0, 0] < 0.0
    assert np.all(SUPPLY.sway_damping(np.linspace(3.0, 7.0, 41)) < 0.0)


def test_sway_ratio_bound_is_37_7_m() -> None:
    grid = np.linspace(3.0, 7.0, 4001)
    ratios = [abs(a[0, 1] / a[0, 0]) for a in (_sway_yaw_system(_fields(SUPPLY), u) for u in grid)]
    independent = max(ratios)
    assert independent == pytest.approx(37.7, abs=0.05)
    assert SUPPLY.sway_ratio_bound(3.0, 7.0) == pytest.approx(independent, rel=1e-6)


def test_steady_turn_sway_equals_ratio_bound_times_yaw_rate() -> None:
    """Hold u and r fixed: v → −X/Y·r (docs/model.md §1); |v|/|r| at U_max is the bound."""
    f = _fields(SUPPLY)
    a = _sway_yaw_system(f, 7.0)
    r = 0.01
    # v̇ = a00·v + a01·r = 0 in steady state
    v_ss = -a[0, 1] * r / a[0, 0]
    assert abs(v_ss) / r == pytest.approx(SUPPLY.sway_ratio_bound(3.0, 7.0), rel=1e-6)


# ------------------------------------------------------------ validate_speed_band
def test_validate_speed_band_accepts_paper_setting() -> None:
    assert SUPPLY.validate_speed_band(3.0, 7.0, 70.0) is None


@pytest.mark.parametrize("delta", [30.0, 37.0, 1.0])
def test_validate_speed_band_rejects_short_lookahead(delta: float) -> None:
    with pytest.raises(ParameterError, match=rf"Δ = {delta}") as info:
        SUPPLY.validate_speed_band(3.0, 7.0, delta)
    assert "37.69" in str(info.value)  # names the bound too


def test_validate_speed_band_boundary_is_strict() -> None:
    bound = SUPPLY.sway_ratio_bound(3.0, 7.0)
    with pytest.raises(ParameterError):
        SUPPLY.validate_speed_band(3.0, 7.0, bound)
    SUPPLY.validate_speed_band(3.0, 7.0, bound * (1.0 + 1e-9))


def test_validate_speed_band_rejects_undamped_sway_cybership2() -> None:
    cs2 = VesselParams(name="cybership2_linear", source="test", length=L_CS2, **CYBERSHIP2_LINEAR)
    # Froude-equivalent of the supply vessel's [3, 7] m/s band
    scale = math.sqrt(L_CS2 / L_SUPPLY)
    u_min, u_max = 3.0 * scale, 7.0 * scale
    # independent check that Y(u) > 0 on this band (so rejection is the right answer)
    y_max = _sway_yaw_system(CYBERSHIP2_LINEAR, u_max)[0, 0]
    assert y_max > 0.0 and _sway_yaw_system(CYBERSHIP2_LINEAR, u_min)[0, 0] > 0.0
    with pytest.raises(ParameterError, match="not damped") as info:
        cs2.validate_speed_band(u_min, u_max, 1000.0)  # huge Δ: only Y can fail
    msg = str(info.value)
    assert "cybership2_linear" in msg
    assert f"{y_max:.4g}" in msg  # the offending value of Y is named


def test_validate_speed_band_rejects_negative_sway_damping() -> None:
    bad = dataclasses.replace(SUPPLY, name="undamped", d22=-1.0e6)
    assert _sway_yaw_system(_fields(bad), 5.0)[0, 0] > 0.0
    with pytest.raises(ParameterError, match=r"Y\(u="):
        bad.validate_speed_band(3.0, 7.0, 70.0)


# ---------------------------------------------------------- VesselParams checks
def _toy(**overrides: float) -> VesselParams:
    base = dict(m11=1.0, m22=2.0, m23=0.5, m33=3.0, d11=1.0, d22=1.0, d23=0.0, d32=0.0, d33=1.0)
    base.update(overrides)
    return VesselParams(name="toy", source="test", **base)


def test_toy_parameters_are_accepted() -> None:
    p = _toy()
    assert p.lam == pytest.approx(2.0 * 3.0 - 0.25)


@pytest.mark.parametrize("m23", [1.0 * math.sqrt(6.0) * 1.01, -3.0, math.sqrt(6.0) + 1e-6])
def test_rejects_non_positive_definite_mass(m23: float) -> None:
    with pytest.raises(ParameterError, match="positive definite"):
        _toy(m23=m23)


def test_rejects_singular_mass() -> None:
    with pytest.raises(ParameterError, match="Λ"):
        _toy(m22=1.0, m33=1.0, m23=1.0)  # Λ = 0 exactly


@pytest.mark.parametrize("key", list(MODEL_TABLE))
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_rejects_non_finite_entries(key: str, value: float) -> None:
    with pytest.raises(ParameterError, match=key):
        _toy(**{key: value})


@pytest.mark.parametrize("key", ["m11", "m22", "m33", "d11"])
@pytest.mark.parametrize("value", [0.0, -1.0])
def test_rejects_non_positive_diagonal(key: str, value: float) -> None:
    with pytest.raises(ParameterError, match=rf"{key} must be finite and > 0, got {value!r}"):
        _toy(**{key: value})


def test_parameter_error_is_value_error() -> None:
    assert issubclass(ParameterError, ValueError)


# ------------------------------------------------------------------------ Gains
def test_default_gains_are_the_papers() -> None:
    g = Gains()
    assert (g.k_u, g.k_psi, g.k_r, g.delta, g.a) == (0.5, 0.5, 5.0, 70.0, 1.0)  # docs/model.md §5


@pytest.mark.parametrize("value", [0.0, -70.0, math.nan, math.inf])
def test_gains_reject_bad_lookahead(value: float) -> None:
    with pytest.raises(ParameterError, match="delta") as info:
        Gains(delta=value)
    assert "Δ" in str(info.value)


@pytest.mark.parametrize("key", ["k_u", "k_psi", "k_r", "a"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, -math.inf, math.inf])
def test_gains_reject_non_positive(key: str, value: float) -> None:
    with pytest.raises(ParameterError, match=key):
        Gains(**{key: value})


@pytest.mark.parametrize("value", [np.float32(70.0), np.int64(70)])
def test_gains_accept_positive_numpy_scalars(value: object) -> None:
    assert Gains(delta=value).delta == 70.0


# -------------------------------------------------------------------- get_vessel
def test_get_vessel_unknown_name_lists_known() -> None:
    with pytest.raises(ValueError, match=r"'nope'.*supply"):
        get_vessel("nope")
