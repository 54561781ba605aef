"""Tests of :mod:`marine_formation_env.control` against docs/model.md §3 and the paper's error dynamics.

The plant in the closed-loop tests is an independent implementation of the
paper's model (M, C(ν), D as matrices, ``np.linalg.solve``), not the package's
``vessel_rhs``; the truths are closed-form solutions of the error dynamics
(15)-(16), ``scipy.linalg.expm``, finite differences along ``solve_ivp``
trajectories and the numbers given in docs/model.md §3.
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

from marine_formation_env.control import (
    consensus_speed,
    heading_tracking_inputs,
    heading_yaw_reference,
    los_angle,
    los_yaw_reference,
    path_following_inputs,
    saturation,
    saturation_slope,
    surge_law,
    yaw_law,
)
from marine_formation_env.params import SUPPLY, Gains

pytestmark = pytest.mark.backend_independent

GAINS = Gains()  # paper values (docs/model.md §5)


def _integrate(f, s0: np.ndarray, t_end: float, **kw) -> np.ndarray:
    sol = solve_ivp(f, (0.0, t_end), s0, method="DOP853", rtol=1e-12, atol=1e-12, **kw)
    assert sol.success
    return sol


# ------------------------------------------------- (a) saturation / consensus
@settings(max_examples=300, deadline=None)
@given(
    s=st.floats(min_value=-1e12, max_value=1e12) | st.sampled_from([-1e12, 1e12, 0.0]),
    a=st.floats(min_value=0.1, max_value=5.0),
    u_min=st.floats(min_value=0.1, max_value=10.0),
    width=st.floats(min_value=0.0, max_value=10.0),
    frac=st.floats(min_value=0.0, max_value=1.0),
)
def test_consensus_speed_stays_inside_speed_band(s: float, a: float, u_min: float, width: float, frac: float) -> None:
    """Assumption (19) ⇒ u_c ∈ (U_min, U_max) for every s (docs/model.md §3)."""
    u_max = u_min + 2.0 * a + width
    u_d = u_min + a + frac * width  # u_d ∈ [U_min + a, U_max − a]
    g = float(saturation(s, a))
    assert -a < g < a
    u_c, _ = consensus_speed(np.float64(s), np.float64(0.0), u_d, 0.0, a)
    assert u_min < float(u_c) < u_max


def test_saturation_shape() -> None:
    a = 1.7
    assert float(saturation(0.0, a)) == 0.0
    assert float(saturation(1e12, a)) == pytest.approx(a, rel=1e-9)
    assert float(saturation(-1e12, a)) == pytest.approx(-a, rel=1e-9)
    assert float(saturation(1.0, a)) == pytest.approx(a / 2.0)  # atan(1) = π/4
    s = np.linspace(-50, 50, 101)
    np.testing.assert_allclose(saturation(-s, a), -saturation(s, a), atol=1e-15)  # odd
    assert np.all(np.diff(saturation(s, a)) > 0)  # increasing


def test_consensus_slows_a_vessel_that_is_ahead() -> None:
    """s_j > 0 means vessel j is ahead of its neighbours: it must be commanded slower than u_d."""
    u_c_ahead, _ = consensus_speed(np.array(10.0), np.array(0.0), 5.0, 0.0, 1.0)
    u_c_behind, _ = consensus_speed(np.array(-10.0), np.array(0.0), 5.0, 0.0, 1.0)
    assert u_c_ahead < 5.0 < u_c_behind


# ------------------------------------------------------ (b) slope and u̇_c
@settings(max_examples=200, deadline=None)
@given(s=st.floats(min_value=-1e3, max_value=1e3), a=st.floats(min_value=0.05, max_value=5.0))
def test_saturation_slope_is_the_derivative(s: float, a: float) -> None:
    h = 1e-5 * max(1.0, abs(s))
    fd = (float(saturation(s + h, a)) - float(saturation(s - h, a))) / (2 * h)
    assert float(saturation_slope(s, a)) == pytest.approx(fd, rel=1e-5, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(
    s0=st.floats(-100, 100),
    s_dot=st.floats(-10, 10),
    u_d0=st.floats(3, 7),
    u_d_dot=st.floats(-0.5, 0.5),
    a=st.floats(0.1, 2.0),
)
def test_consensus_rate_is_the_time_derivative(s0: float, s_dot: float, u_d0: float, u_d_dot: float, a: float) -> None:
    """Along s(t) = s0 + ṡ t, u_d(t) = u_d0 + u̇_d t, u̇_c equals d/dt u_c (finite differences)."""
    h = 1e-5  # truncation error ~ h²·|g'''|·|ṡ|³/6 stays below the tolerance for |ṡ| ≤ 10

    def u_c(t: float) -> float:
        return float(consensus_speed(np.float64(s0 + s_dot * t), 0.0, u_d0 + u_d_dot * t, 0.0, a)[0])

    fd = (u_c(h) - u_c(-h)) / (2 * h)
    _, rate = consensus_speed(np.float64(s0), np.float64(s_dot), u_d0, u_d_dot, a)
    assert float(rate) == pytest.approx(fd, rel=1e-6, abs=1e-9)


# ------------------------------------------------------------- (c) surge law
def test_corrected_surge_law_gives_exponential_tracking_at_zero_sway_yaw() -> None:
    """docs/model.md §3: ũ̇ = −(k_u + d11/m11)·ũ at v = r = 0, with a constant u_c."""
    p, k_u, u_c = SUPPLY, GAINS.k_u, 5.0

    def f(t: float, s: np.ndarray) -> np.ndarray:
        tau_u = float(surge_law(p, s[3], s[4], s[5], u_c, 0.0, k_u))
        return model_rhs(p, s, tau_u, 0.0)

    u0 = 3.0
    t_eval = np.linspace(0.0, 20.0, 21)
    sol = _integrate(f, np.array([0.0, 0.0, 0.0, u0, 0.0, 0.0]), 20.0, t_eval=t_eval)
    lam = k_u + p.d11 / p.m11
    np.testing.assert_allclose(sol.y[3] - u_c, (u0 - u_c) * np.exp(-lam * t_eval), rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(sol.y[4:], 0.0, atol=1e-14)  # v and r stay zero


def test_corrected_surge_law_with_turning_and_time_varying_command() -> None:
    """ũ̇ = −(k_u + d11/m11)·ũ holds for any sway/yaw motion and any u_c(t) (the law cancels C(ν))."""
    p, k_u = SUPPLY, GAINS.k_u

    def u_c(t: float) -> tuple[float, float]:
        return 5.0 + 0.8 * math.sin(0.3 * t), 0.8 * 0.3 * math.cos(0.3 * t)

    def f(t: float, s: np.ndarray) -> np.ndarray:
        uc, uc_dot = u_c(t)
        tau_u = float(surge_law(p, s[3], s[4], s[5], uc, uc_dot, k_u))
        tau_r = 0.002 * math.sin(0.5 * t)  # some arbitrary turning
        return model_rhs(p, s, tau_u, tau_r)

    s0 = np.array([0.0, 0.0, 0.2, 6.5, 0.4, 0.03])
    t_eval = np.linspace(0.0, 15.0, 16)
    sol = _integrate(f, s0, 15.0, t_eval=t_eval)
    lam = k_u + p.d11 / p.m11
    u_tilde = sol.y[3] - np.array([u_c(t)[0] for t in t_eval])
    np.testing.assert_allclose(u_tilde, (s0[3] - u_c(0.0)[0]) * np.exp(-lam * t_eval), rtol=1e-7, atol=1e-10)
    assert np.max(np.abs(sol.y[5])) > 0.01  # the vessel really turned


def test_printed_surge_law_settles_below_command() -> None:
    """docs/model.md §3: as printed, u → k_u·u_c/(k_u + d11/m11) = 4.889 m/s at u_c = 5 m/s."""
    p, k_u, u_c = SUPPLY, GAINS.k_u, 5.0
    d_over_m = 7.7071e4 / 6.7644e6  # docs/model.md §2 table
    u_ss = k_u * u_c / (k_u + d_over_m)
    assert u_ss == pytest.approx(4.889, abs=5e-4)

    def f(t: float, s: np.ndarray) -> np.ndarray:
        tau_u = float(surge_law(p, s[3], s[4], s[5], u_c, 0.0, k_u, as_printed=True))
        return model_rhs(p, s, tau_u, 0.0)

    u0 = 3.0
    t_eval = np.array([0.0, 2.0, 5.0, 10.0, 80.0])
    sol = _integrate(f, np.array([0.0, 0.0, 0.0, u0, 0.0, 0.0]), 80.0, t_eval=t_eval)
    lam = k_u + p.d11 / p.m11
    np.testing.assert_allclose(sol.y[3], u_ss + (u0 - u_ss) * np.exp(-lam * t_eval), rtol=1e-7)
    assert sol.y[3, -1] == pytest.approx(4.889, abs=5e-4)
    assert sol.y[3, -1] < u_c - 0.1


# ---------------------------------------------------------------- (d) yaw law
def test_yaw_law_gives_first_order_yaw_rate_error() -> None:
    """ṙ = a_r + τ_r = ṙ_d − k_r·(r − r_d) exactly, for random states (docs/model.md §3, eq. 13)."""
    rng = np.random.default_rng(10)
    for _ in range(200):
        s = np.array([0.0, 0.0, rng.uniform(-3, 3), rng.uniform(-1, 9), rng.uniform(-2, 2), rng.uniform(-0.2, 0.2)])
        r_d, r_d_dot, k_r = rng.uniform(-0.2, 0.2), rng.uniform(-0.05, 0.05), rng.uniform(0.1, 10)
        tau_r = float(yaw_law(SUPPLY, s[3], s[4], s[5], r_d, r_d_dot, k_r))
        tau_u = rng.normal()
        r_dot = model_rhs(SUPPLY, s, tau_u, tau_r)[5]
        assert r_dot == pytest.approx(r_d_dot - k_r * (s[5] - r_d), rel=1e-9, abs=1e-13)


def test_yaw_law_is_batched() -> None:
    rng = np.random.default_rng(11)
    u, v, r = rng.uniform(3, 7, (2, 3)), rng.uniform(-1, 1, (2, 3)), rng.uniform(-0.1, 0.1, (2, 3))
    r_d, r_d_dot = rng.uniform(-0.1, 0.1, (2, 3)), rng.uniform(-0.01, 0.01, (2, 3))
    out = yaw_law(SUPPLY, u, v, r, r_d, r_d_dot, 5.0)
    assert out.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            s = np.array([0, 0, 0, u[i, j], v[i, j], r[i, j]])
            r_dot = model_rhs(SUPPLY, s, 0.0, float(out[i, j]))[5]
            assert r_dot == pytest.approx(r_d_dot[i, j] - 5.0 * (r[i, j] - r_d[i, j]), rel=1e-9, abs=1e-13)


# ------------------------------------------------------- (e) LOS yaw reference
D_Y = 12.0
U_C = 5.0


def _los_closed_loop(as_printed: bool):
    p, g = SUPPLY, GAINS

    def refs(s: np.ndarray) -> tuple[float, float, float]:
        _, y, psi, u, v, r = s
        tau_u = float(surge_law(p, u, v, r, U_C, 0.0, g.k_u, as_printed))
        r_d, r_d_dot = los_yaw_reference(p, y - D_Y, psi, u, v, r, tau_u, g, as_printed)
        return float(r_d), float(r_d_dot), tau_u

    def f(t: float, s: np.ndarray) -> np.ndarray:
        r_d, r_d_dot, tau_u = refs(s)
        tau_r = float(yaw_law(p, s[3], s[4], s[5], r_d, r_d_dot, g.k_r))
        return model_rhs(p, s, tau_u, tau_r)

    return refs, f


def _random_los_states(n: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [
        np.array(
            [
                rng.uniform(-100, 100),
                D_Y + rng.uniform(-100, 100),
                rng.uniform(-0.8, 0.8),
                rng.uniform(3, 7),
                rng.uniform(-0.5, 0.5),
                rng.uniform(-0.05, 0.05),
            ]
        )
        for _ in range(n)
    ]


def _central_difference(f, s0: np.ndarray, func, h: float) -> float:
    kw = dict(method="DOP853", rtol=1e-13, atol=1e-13)
    s_plus = solve_ivp(f, (0.0, h), s0, **kw).y[:, -1]
    s_minus = solve_ivp(f, (0.0, -h), s0, **kw).y[:, -1]
    return (func(s_plus) - func(s_minus)) / (2 * h)


@pytest.mark.parametrize("as_printed", [False, True])
def test_los_r_d_dot_is_the_time_derivative_of_r_d(as_printed: bool) -> None:
    refs, f = _los_closed_loop(as_printed)
    h = 1e-4  # central-difference truncation error ~ h²·r_d'''/6 ≲ 2e-8 here
    for s0 in _random_los_states(6, seed=20 + as_printed):
        _, r_d_dot, _ = refs(s0)
        fd = _central_difference(f, s0, lambda s: refs(s)[0], h)
        assert r_d_dot == pytest.approx(fd, rel=1e-5, abs=1e-7)


@pytest.mark.parametrize("as_printed", [False, True])
def test_los_feed_forward_sign(as_printed: bool) -> None:
    """The corrected feed-forward r_d + k_ψ·(ψ − ψ_LOS) is dψ_LOS/dt; as printed it is −dψ_LOS/dt."""
    refs, f = _los_closed_loop(as_printed)
    sign = -1.0 if as_printed else 1.0
    for s0 in _random_los_states(6, seed=30 + as_printed):
        r_d, _, _ = refs(s0)
        psi_los = float(los_angle(s0[1] - D_Y, GAINS.delta))
        feed = r_d + GAINS.k_psi * (s0[2] - psi_los)
        fd = _central_difference(f, s0, lambda s: float(los_angle(s[1] - D_Y, GAINS.delta)), 1e-4)
        assert abs(fd) > 1e-4  # non-trivial LOS rate
        assert feed == pytest.approx(sign * fd, rel=1e-6, abs=1e-10)


def test_los_angle_values() -> None:
    """(12): ψ_LOS = −atan(e/Δ): steer back towards the path."""
    assert float(los_angle(np.float64(70.0), 70.0)) == pytest.approx(-math.pi / 4)
    assert float(los_angle(np.float64(-70.0), 70.0)) == pytest.approx(math.pi / 4)
    assert float(los_angle(np.float64(0.0), 70.0)) == 0.0
    assert float(los_angle(np.float64(1e9), 70.0)) == pytest.approx(-math.pi / 2, abs=1e-7)


def test_corrected_path_following_gives_papers_error_dynamics() -> None:
    """Eqs. (15)-(16) with the corrected laws: along the closed loop,
    ψ̃̇ = −k_ψ ψ̃ + r̃, r̃̇ = −k_r r̃ and ũ̇ = −(k_u + d11/m11) ũ (compared with expm)."""
    p, g = SUPPLY, GAINS

    def errors(s: np.ndarray) -> np.ndarray:
        _, y, psi, u, v, r = s
        tau_u = float(surge_law(p, u, v, r, U_C, 0.0, g.k_u))
        r_d, _ = los_yaw_reference(p, y - D_Y, psi, u, v, r, tau_u, g)
        psi_tilde = psi - float(los_angle(y - D_Y, g.delta))
        return np.array([psi_tilde, r - float(r_d), u - U_C])

    def f(t: float, s: np.ndarray) -> np.ndarray:
        tau_u, tau_r = path_following_inputs(p, g, s[1] - D_Y, s[2], s[3], s[4], s[5], U_C, 0.0)
        return model_rhs(p, s, float(tau_u), float(tau_r))

    # vessel_1 of the paper scenario (docs/model.md §5) relative to a path at D_Y
    s0 = np.array([-60.0, D_Y + 30.0, 0.3, 3.0, 0.0, 0.0])
    t_eval = np.linspace(0.0, 12.0, 13)
    sol = _integrate(f, s0, 12.0, t_eval=t_eval)
    err0 = errors(s0)
    a = np.array(
        [
            [-g.k_psi, 1.0, 0.0],
            [0.0, -g.k_r, 0.0],
            [0.0, 0.0, -(g.k_u + p.d11 / p.m11)],
        ]
    )
    for k, t in enumerate(t_eval):
        np.testing.assert_allclose(errors(sol.y[:, k]), expm(a * t) @ err0, rtol=1e-6, atol=1e-9)
    assert abs(err0[0]) > 0.5  # a real transient


def test_printed_yaw_reference_violates_16() -> None:
    """docs/model.md §3: with the printed sign, (16) does not hold along the closed loop."""
    p, g = SUPPLY, GAINS

    def f(t: float, s: np.ndarray) -> np.ndarray:
        tau_u, tau_r = path_following_inputs(p, g, s[1] - D_Y, s[2], s[3], s[4], s[5], U_C, 0.0, as_printed=True)
        return model_rhs(p, s, float(tau_u), float(tau_r))

    s0 = np.array([-60.0, D_Y + 30.0, 0.3, 3.0, 0.0, 0.0])
    sol = _integrate(f, s0, 12.0, t_eval=[12.0])
    s_end = sol.y[:, -1]
    psi_tilde_end = s_end[2] - float(los_angle(s_end[1] - D_Y, g.delta))
    # r̃ starts at r − r_d(s0); with (16) ψ̃(12) would be the expm prediction
    _, y, psi, u, v, r = s0
    tau_u = float(surge_law(p, u, v, r, U_C, 0.0, g.k_u, True))
    r_d0, _ = los_yaw_reference(p, y - D_Y, psi, u, v, r, tau_u, g, True)
    psi_tilde0 = psi - float(los_angle(y - D_Y, g.delta))
    a = np.array([[-g.k_psi, 1.0], [0.0, -g.k_r]])
    predicted = (expm(a * 12.0) @ np.array([psi_tilde0, r - float(r_d0)]))[0]
    assert abs(psi_tilde_end - predicted) > 1e-3


# ------------------------------------------------------ (f) heading reference
@pytest.mark.parametrize(
    ("psi", "psi_d", "expected_error"),
    [
        (0.3, 0.1, 0.2),
        (-0.3, 0.1, -0.4),
        (3.1, -3.1, 6.2 - 2 * math.pi),  # the short way round
        (-3.1, 3.1, 2 * math.pi - 6.2),
        (0.0, 0.0, 0.0),
    ],
)
def test_heading_yaw_reference(psi: float, psi_d: float, expected_error: float) -> None:
    k_psi, r = 0.5, 0.07
    r_d, r_d_dot = heading_yaw_reference(np.float64(psi), np.float64(r), np.float64(psi_d), k_psi)
    assert float(r_d) == pytest.approx(-k_psi * expected_error, abs=1e-12)
    assert float(r_d_dot) == pytest.approx(-k_psi * r)  # d/dt of −k_ψ(ψ − ψ_d) with ψ_d held


def test_heading_tracking_closed_loop_is_linear_second_order() -> None:
    """With ψ̃ = ψ − ψ_d: ψ̃̇ = r, ṙ = −k_ψ r − k_r (r + k_ψ ψ̃) (eqs. 13 with r_d = −k_ψ ψ̃)."""
    p, g = SUPPLY, GAINS
    psi_d = -0.4

    def f(t: float, s: np.ndarray) -> np.ndarray:
        tau_u, tau_r = heading_tracking_inputs(p, g, psi_d, s[2], s[3], s[4], s[5], 5.0, 0.0)
        return model_rhs(p, s, float(tau_u), float(tau_r))

    s0 = np.array([0.0, 0.0, 0.5, 4.0, 0.1, 0.02])
    t_eval = np.linspace(0.0, 10.0, 11)
    sol = _integrate(f, s0, 10.0, t_eval=t_eval)
    a = np.array([[0.0, 1.0], [-g.k_r * g.k_psi, -(g.k_psi + g.k_r)]])
    for k, t in enumerate(t_eval):
        want = expm(a * t) @ np.array([s0[2] - psi_d, s0[5]])
        np.testing.assert_allclose([sol.y[2, k] - psi_d, sol.y[5, k]], want, rtol=1e-6, atol=1e-9)
