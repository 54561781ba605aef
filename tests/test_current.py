"""Ocean currents: the kinematics against independent truth, and LOS against integral LOS.

* A constant irrotational current leaves the kinetics in relative velocities
  unchanged, so under the same inputs a vessel's path is the still-water path
  shifted by V_c·t (exact).
* A slowly varying current: the env against scipy's solve_ivp of the
  independent matrix model (tests/independent_model.py) plus V_c(t).
* Plain LOS in a cross current V settles off the path. With the guidance-level
  heading loop (ψ → ψ_d = −atan(e/Δ)) and no sway at equilibrium, holding the
  path needs u·sin ψ = −V, so e = Δ·V/√(u² − V²). With the speed-level path
  follower the model-based feed-forwards, which believe ẏ = u·sin ψ = −V
  while the true ẏ is 0, add terms. With D = e² + Δ², ψ̇_LOS = Δ·V/D and
  ψ̈_LOS = 2·Δ·e·V²/D², the yaw loop's equilibrium (r = 0, ṙ = 0, so
  r_d = −ṙ_d/k_r with ṙ_d = ψ̈_LOS + k_ψ·ψ̇_LOS) solves
  ψ̇_LOS − k_ψ·(ψ + atan(e/Δ)) = −(ψ̈_LOS + k_ψ·ψ̇_LOS)/k_r, ψ = −asin(V/u)
  (brentq here).
* Integral LOS drives e to zero.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import marine_formation_env
from baselines import ReferencePolicy
from baselines.engine import run_episode
from baselines.metrics import episode_metrics
from marine_formation_env.core import FormationCore
from marine_formation_env.scenarios import ConfigError, make_config
from tests.independent_model import model_rhs

V_CROSS = 0.5  # the `current` preset [m/s], towards +y


def _force_run(cfg, steps, tau=(0.4, 0.02)):
    core = FormationCore(cfg, 1)
    core.reset(cfg.initial_state)
    actions = np.zeros((1, cfg.n_vessels, 2))
    actions[..., 0], actions[..., 1] = tau[0] / cfg.tau_u_max, tau[1] / cfg.tau_r_max
    states = [core.state[0].copy()]
    for _ in range(steps):
        core.step(actions)
        states.append(core.state[0].copy())
    return np.array(states), actions


def test_constant_current_shifts_the_still_water_path_by_v_t():
    still = make_config("paper", action_level="force")
    moving = make_config("paper", action_level="force", current={"speed": 0.7, "direction": 2.3})
    s0, _ = _force_run(still, 300)
    s1, _ = _force_run(moving, 300)
    t = np.arange(301) * still.dt
    shift = 0.7 * np.stack([np.cos(2.3) * t, np.sin(2.3) * t], axis=-1)
    np.testing.assert_allclose(s1[..., :2], s0[..., :2] + shift[:, None, :], atol=1e-8)
    np.testing.assert_allclose(s1[..., 2:], s0[..., 2:], atol=1e-10)


def test_slowly_varying_current_against_scipy():
    cfg = make_config(
        "paper", action_level="force", current={"speed": 0.4, "direction": 1.0, "amplitude": 0.3, "period": 120.0}
    )
    states, actions = _force_run(cfg, 600)
    tau_u, tau_r = actions[0, 0, 0] * cfg.tau_u_max, actions[0, 0, 1] * cfg.tau_r_max

    def rhs(t, y):
        magnitude = 0.4 + 0.3 * math.sin(2 * math.pi * t / 120.0)
        return model_rhs(cfg.params, y, tau_u, tau_r) + np.array(
            [magnitude * math.cos(1.0), magnitude * math.sin(1.0), 0, 0, 0, 0]
        )

    t_end = 600 * cfg.dt
    sol = solve_ivp(rhs, (0.0, t_end), cfg.initial_state[0], rtol=1e-10, atol=1e-10, t_eval=[t_end])
    np.testing.assert_allclose(states[-1, 0], sol.y[:, -1], rtol=1e-6, atol=1e-5)


def _final_cross_track(level, **reference):
    env = marine_formation_env.parallel_env("current", action_level=level)
    traj = run_episode(env, ReferencePolicy(env, **reference), seed=0)
    return traj, episode_metrics(traj, env.config), env.config


def test_plain_los_at_guidance_level_settles_at_the_analytic_offset():
    traj, metrics, cfg = _final_cross_track("guidance")
    delta, u = cfg.gains.delta, cfg.u_d.mean
    expected = delta * V_CROSS / math.sqrt(u * u - V_CROSS * V_CROSS)  # 7.035 m, towards +y
    e = traj.state[-1, :, 1] - cfg.formation[:, 1]
    np.testing.assert_allclose(e, expected, rtol=1e-3)
    assert metrics["final_cross_track_max"] > 7.0


def test_plain_los_path_follower_settles_at_its_equilibrium():
    traj, _, cfg = _final_cross_track("speed")
    g, u = cfg.gains, cfg.u_d.mean
    psi = -math.asin(V_CROSS / u)

    def balance(e):
        d = e * e + g.delta**2
        los_rate = g.delta * V_CROSS / d
        los_acc = 2.0 * g.delta * e * V_CROSS**2 / d**2
        r_d = los_rate - g.k_psi * (psi + math.atan(e / g.delta))
        return r_d + (los_acc + g.k_psi * los_rate) / g.k_r

    expected = brentq(balance, 0.0, 50.0)
    e = traj.state[-1, :, 1] - cfg.formation[:, 1]
    np.testing.assert_allclose(e, expected, rtol=1e-3)
    assert expected > 5.0  # a large steady error the paper's LOS cannot remove


@pytest.mark.parametrize("level", ["guidance", "force"])
def test_integral_los_drives_the_cross_track_error_to_zero(level):
    _, plain, _ = _final_cross_track(level)
    _, ilos, _ = _final_cross_track(level, integral_los=1.0)
    assert plain["final_cross_track_max"] > 5.0
    assert ilos["final_cross_track_max"] < 0.05
    assert ilos["final_coordination_spread"] < 0.01
    assert ilos["success"]  # course over ground along the path, speeds u = u_d


def test_integral_los_in_the_speed_levels_path_follower():
    """The scenario's los_integral_gain makes the built-in LOS integral: the policy only coordinates."""
    _, plain, _ = _final_cross_track("speed")
    env = marine_formation_env.parallel_env("current", los_integral_gain=1.0)
    traj = run_episode(env, ReferencePolicy(env), seed=0)
    ilos = episode_metrics(traj, env.config)
    assert plain["final_cross_track_max"] > 8.0
    assert ilos["final_cross_track_max"] < 0.05 and ilos["success"]
    # in still water the equilibrium is the paper's (e = 0, e_int = 0); the integrator
    # charged during the transient drains slowly (7.8 mm left at 400 s)
    still = marine_formation_env.parallel_env("paper", los_integral_gain=1.0)
    m = episode_metrics(run_episode(still, ReferencePolicy(still), seed=0), still.config)
    assert m["final_cross_track_max"] < 0.05 and m["final_coordination_spread"] < 1e-6 and m["success"]


def test_integral_los_needs_a_steering_level_and_a_positive_gain():
    env = marine_formation_env.parallel_env("current")
    with pytest.raises(ValueError, match="integral_los needs action_level 'guidance' or 'force'"):
        ReferencePolicy(env, integral_los=1.0)
    with pytest.raises(ValueError, match=r"integral_los must be a gain σ > 0 \[m/s\] or None, got -1"):
        ReferencePolicy(marine_formation_env.parallel_env("current", action_level="guidance"), integral_los=-1)


def test_integral_los_state_resets_between_episodes():
    env = marine_formation_env.parallel_env("current", action_level="guidance", horizon=60.0)
    policy = ReferencePolicy(env, integral_los=1.0)
    first = run_episode(env, policy, seed=0)
    second = run_episode(env, policy, seed=0)
    assert np.array_equal(first.state, second.state)


@pytest.mark.parametrize(
    ("current", "match"),
    [
        ({"speed": -0.2}, r"current.speed must be a finite number ≥ 0, got -0.2"),
        ({"speed": float("nan")}, r"current.speed .*got nan"),
        ({"period": 0.0}, r"current.period must be a finite number > 0, got 0.0"),
        ({"speed": 2.5, "amplitude": 0.6}, r"current speed \+ amplitude = 3.1 m/s must stay below u_min = 3"),
        ({"sped": 1.0}, r"unknown current key\(s\) \['sped'\]"),
    ],
)
def test_malformed_currents_raise_clear_errors(current, match):
    with pytest.raises(ConfigError, match=match):
        make_config("paper", current=current)


def test_los_integral_gain_is_validated():
    with pytest.raises(ConfigError, match=r"scenario.los_integral_gain must be a finite number ≥ 0, got -1"):
        make_config("current", los_integral_gain=-1.0)
    with pytest.raises(ConfigError, match="applies to the speed level's built-in LOS; at action_level 'guidance'"):
        make_config("current", action_level="guidance", los_integral_gain=1.0)


def test_malformed_sensor_noise_raises():
    with pytest.raises(ConfigError, match=r"sensor_noise.position must be a finite number ≥ 0, got -1"):
        make_config("paper", sensor_noise={"position": -1})
