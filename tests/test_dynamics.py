"""Tests of :mod:`marine_formation_env.dynamics` (paper eqs. 1-4, docs/model.md §1).

Independent truths: the model written as matrices straight from the paper
(``M ν̇ + C(ν)ν + Dν = M[τ_u, 0, τ_r]ᵀ`` solved with ``np.linalg.solve``),
``scipy.integrate.solve_ivp``, closed-form decays and ``scipy.linalg.expm``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from independent_model import model_rhs
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from marine_formation_env.dynamics import PSI, R, U, V, X, Y, rk4_step, vessel_rhs, wrap_angle
from marine_formation_env.params import SUPPLY, VesselParams

pytestmark = pytest.mark.backend_independent


def random_params(rng: np.random.Generator) -> VesselParams:
    """A random valid parameter set (M > 0, arbitrary-signed off-diagonal damping)."""
    m22 = rng.uniform(0.5, 3.0)
    m33 = rng.uniform(0.5, 3.0)
    m23 = rng.uniform(-0.9, 0.9) * math.sqrt(m22 * m33)
    return VesselParams(
        name="random",
        source="test",
        m11=rng.uniform(0.5, 3.0),
        m22=m22,
        m23=m23,
        m33=m33,
        d11=rng.uniform(0.1, 2.0),
        d22=rng.uniform(0.1, 2.0),
        d23=rng.uniform(-1.0, 1.0),
        d32=rng.uniform(-1.0, 1.0),
        d33=rng.uniform(0.1, 2.0),
    )


def random_state(rng: np.random.Generator) -> np.ndarray:
    return np.array(
        [
            rng.uniform(-500, 500),
            rng.uniform(-500, 500),
            rng.uniform(-4.0, 4.0),
            rng.uniform(-2.0, 9.0),
            rng.uniform(-2.0, 2.0),
            rng.uniform(-0.2, 0.2),
        ]
    )


# -------------------------------------------------------------- (a) vessel_rhs
def test_column_indices() -> None:
    assert (X, Y, PSI, U, V, R) == (0, 1, 2, 3, 4, 5)


def test_vessel_rhs_matches_matrix_model_supply() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):
        s = random_state(rng)
        tu, tr = rng.normal(0, 0.1), rng.normal(0, 0.01)
        got = vessel_rhs(SUPPLY, s, np.float64(tu), np.float64(tr))
        want = model_rhs(SUPPLY, s, tu, tr)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-13)


def test_vessel_rhs_matches_matrix_model_random_params() -> None:
    rng = np.random.default_rng(2)
    for _ in range(100):
        p = random_params(rng)
        s = random_state(rng)
        tu, tr = rng.normal(), rng.normal()
        np.testing.assert_allclose(vessel_rhs(p, s, tu, tr), model_rhs(p, s, tu, tr), rtol=1e-9, atol=1e-12)


def test_inputs_enter_only_surge_and_yaw() -> None:
    """M⁻¹Bu = [τ_u, 0, τ_r]ᵀ: ∂(rhs)/∂τ_u = e_u, ∂(rhs)/∂τ_r = e_r, exactly linear."""
    rng = np.random.default_rng(3)
    s = random_state(rng)
    base = vessel_rhs(SUPPLY, s, 0.0, 0.0)
    d_u = vessel_rhs(SUPPLY, s, 0.7, 0.0) - base
    d_r = vessel_rhs(SUPPLY, s, 0.0, -0.3) - base
    np.testing.assert_allclose(d_u, [0, 0, 0, 0.7, 0, 0], atol=1e-12)
    np.testing.assert_allclose(d_r, [0, 0, 0, 0, 0, -0.3], atol=1e-12)


def test_kinematics_rotate_body_velocity() -> None:
    # ψ = 90°: surge moves +y, sway moves −x
    s = np.array([0.0, 0.0, math.pi / 2, 2.0, 0.5, 0.1])
    d = vessel_rhs(SUPPLY, s, 0.0, 0.0)
    np.testing.assert_allclose(d[:3], [-0.5, 2.0, 0.1], atol=1e-12)


def test_vessel_rhs_batched_shapes() -> None:
    rng = np.random.default_rng(4)
    states = np.stack([[random_state(rng) for _ in range(3)] for _ in range(2)])  # (2, 3, 6)
    tu = rng.normal(size=(2, 3))
    tr = rng.normal(size=(2, 3)) * 0.01
    out = vessel_rhs(SUPPLY, states, tu, tr)
    assert out.shape == (2, 3, 6)
    for b in range(2):
        for n in range(3):
            np.testing.assert_allclose(
                out[b, n], model_rhs(SUPPLY, states[b, n], tu[b, n], tr[b, n]), rtol=1e-9, atol=1e-13
            )


# ---------------------------------------------------------------- (b) rk4_step
TU_CONST, TR_CONST = 0.05, -0.002
X0 = np.array([10.0, -5.0, 0.4, 4.0, 0.3, 0.02])


def _rk4_final(h: float, t_end: float = 20.0) -> np.ndarray:
    steps = round(t_end / h)
    assert abs(steps * h - t_end) < 1e-12
    s = X0.copy()
    for _ in range(steps):
        s = rk4_step(lambda _t, y: vessel_rhs(SUPPLY, y, TU_CONST, TR_CONST), s, h)
    return s


@pytest.fixture(scope="module")
def scipy_reference() -> np.ndarray:
    sol = solve_ivp(
        lambda t, y: model_rhs(SUPPLY, y, TU_CONST, TR_CONST),
        (0.0, 20.0),
        X0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    assert sol.success
    return sol.y[:, -1]


def test_rk4_matches_solve_ivp(scipy_reference: np.ndarray) -> None:
    loose = solve_ivp(lambda t, y: model_rhs(SUPPLY, y, TU_CONST, TR_CONST), (0.0, 20.0), X0, rtol=1e-10, atol=1e-10).y[
        :, -1
    ]
    final = _rk4_final(0.1)
    np.testing.assert_allclose(final, scipy_reference, rtol=0, atol=1e-8)
    np.testing.assert_allclose(final, loose, rtol=0, atol=1e-7)
    # and the vessel actually moved / turned (not a trivial trajectory)
    assert np.linalg.norm(final[:2] - X0[:2]) > 50.0


def test_rk4_is_fourth_order(scipy_reference: np.ndarray) -> None:
    hs = [2.0, 1.0, 0.5, 0.25]
    errors = np.array([np.max(np.abs(_rk4_final(h) - scipy_reference)) for h in hs])
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(errors > 1e-9), errors  # above the reference's own error
    assert np.all((orders > 3.5) & (orders < 4.5)), orders


def test_rk4_one_step_on_linear_ode_matches_taylor_polynomial() -> None:
    """For ẏ = A y, one RK4 step is exactly Σ_{k≤4} (hA)^k/k! applied to y."""
    a = np.array([[0.0, 1.0], [-2.0, -0.3]])
    y0 = np.array([1.0, -0.5])
    h = 0.37
    ha = h * a
    poly = np.eye(2) + ha + ha @ ha / 2 + ha @ ha @ ha / 6 + ha @ ha @ ha @ ha / 24
    np.testing.assert_allclose(rk4_step(lambda _t, y: y @ a.T, y0, h), poly @ y0, rtol=1e-14, atol=1e-15)


# --------------------------------------------------------- (c) batched = looped
def test_batched_step_equals_single_steps() -> None:
    rng = np.random.default_rng(5)
    b, n = 4, 3
    states = np.stack([[random_state(rng) for _ in range(n)] for _ in range(b)])
    tu = rng.normal(0, 0.1, size=(b, n))
    tr = rng.normal(0, 0.01, size=(b, n))
    h = 0.2
    batched = rk4_step(lambda _t, y: vessel_rhs(SUPPLY, y, tu, tr), states, h)
    assert batched.shape == (b, n, 6)
    for i in range(b):
        for j in range(n):
            single = rk4_step(lambda _t, y, i=i, j=j: vessel_rhs(SUPPLY, y, tu[i, j], tr[i, j]), states[i, j], h)
            np.testing.assert_allclose(batched[i, j], single, rtol=1e-13, atol=1e-12)
    # the inputs are not modified in place
    assert np.all(np.isfinite(states))


def test_rk4_does_not_mutate_state() -> None:
    s = X0.copy()
    rk4_step(lambda _t, y: vessel_rhs(SUPPLY, y, 0.1, 0.0), s, 0.5)
    np.testing.assert_array_equal(s, X0)


# ------------------------------------------------------------- (d) free decay
def test_free_surge_decay_is_exponential() -> None:
    u0, psi0 = 6.0, 0.7
    k = SUPPLY.d11 / SUPPLY.m11
    s = np.array([5.0, -3.0, psi0, u0, 0.0, 0.0])
    h, steps = 0.5, 400
    for _ in range(steps):
        s = rk4_step(lambda _t, y: vessel_rhs(SUPPLY, y, 0.0, 0.0), s, h)
    t = h * steps
    dist = u0 / k * (1.0 - math.exp(-k * t))
    assert s[U] == pytest.approx(u0 * math.exp(-k * t), rel=1e-10)
    assert s[X] == pytest.approx(5.0 + dist * math.cos(psi0), rel=1e-10)
    assert s[Y] == pytest.approx(-3.0 + dist * math.sin(psi0), rel=1e-10)
    assert s[PSI] == psi0 and s[V] == 0.0 and s[R] == 0.0


def test_free_surge_decay_along_x_keeps_y() -> None:
    s = np.array([0.0, 12.0, 0.0, 5.0, 0.0, 0.0])
    for _ in range(100):
        s = rk4_step(lambda _t, y: vessel_rhs(SUPPLY, y, 0.0, 0.0), s, 1.0)
    assert s[Y] == 12.0 and s[PSI] == 0.0
    assert s[U] == pytest.approx(5.0 * math.exp(-SUPPLY.d11 / SUPPLY.m11 * 100.0), rel=1e-9)


def test_sway_yaw_decay_at_zero_surge_matches_expm() -> None:
    """At u = 0 the (v, r) dynamics are linear: ν̇_sub = −M_sub⁻¹ D_sub ν_sub.

    u stays 0 only if the centripetal surge term (m22 v + m23 r) r / m11 is
    cancelled, so τ_u = −(m22 v + m23 r) r / m11 (from the paper's C(ν)), τ_r = 0.
    ψ is the integral of r, so the augmented system [v, r, ψ] is linear too.
    """
    p = SUPPLY
    m_sub = np.array([[p.m22, p.m23], [p.m23, p.m33]])
    d_sub = np.array([[p.d22, p.d23], [p.d32, p.d33]])
    a_aug = np.zeros((3, 3))
    a_aug[:2, :2] = -np.linalg.solve(m_sub, d_sub)
    a_aug[2, 1] = 1.0

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        tau_u = -(p.m22 * y[..., V] + p.m23 * y[..., R]) * y[..., R] / p.m11
        return vessel_rhs(p, y, tau_u, 0.0)

    s = np.array([0.0, 0.0, 0.1, 0.0, 0.8, 0.03])
    h = 0.25
    for step in range(1, 241):
        s = rk4_step(rhs, s, h)
        if step % 40 == 0:
            t = step * h
            want = expm(a_aug * t) @ np.array([0.8, 0.03, 0.1])
            np.testing.assert_allclose([s[V], s[R], s[PSI]], want, rtol=1e-8, atol=1e-11)
            assert abs(s[U]) < 1e-12
    assert abs(s[V]) < 0.3 * 0.8  # it did decay (the test is not vacuous)


# --------------------------------------------------------------- (e) wrap_angle
ANGLES = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(ANGLES)
def test_wrap_angle_range_and_equivalence(a: float) -> None:
    w = float(wrap_angle(a))
    assert -math.pi <= w < math.pi
    # same direction as a (equivalent modulo 2π)
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-1e3, max_value=1e3, allow_nan=False), st.integers(min_value=-50, max_value=50))
def test_wrap_angle_is_2pi_periodic(a: float, k: int) -> None:
    d = float(wrap_angle(a + 2.0 * math.pi * k)) - float(wrap_angle(a))
    # equal, or differing by a full turn right at the ±π cut
    assert min(abs(d), abs(abs(d) - 2.0 * math.pi)) < 1e-9


def test_wrap_angle_known_values() -> None:
    np.testing.assert_allclose(
        wrap_angle(np.array([0.0, 1.0, -1.0, 3 * math.pi / 2, -3 * math.pi / 2, 7.0, 2 * math.pi])),
        [0.0, 1.0, -1.0, -math.pi / 2, math.pi / 2, 7.0 - 2 * math.pi, 0.0],
        atol=1e-15,
    )
    assert float(wrap_angle(math.pi)) == pytest.approx(-math.pi)  # π maps to −π: range is [−π, π)
    assert wrap_angle(np.zeros((2, 3))).shape == (2, 3)


def test_wrap_angle_just_below_minus_pi_stays_in_half_open_range() -> None:
    a = np.nextafter(-math.pi, -math.inf)  # −π − 4.4e-16
    assert float(wrap_angle(a)) < math.pi
