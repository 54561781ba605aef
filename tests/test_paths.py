"""Curved paths (docs/paths.md): geometry against analytic formulas, the projection, the
validation, the observations on a curved path, and the reference controller's convergence.

The independent continuous-time integration of the curved-path closed loop is in
tests/test_curved_continuous.py.
"""

from __future__ import annotations

import math
import os
import subprocess

import numpy as np
import pytest

import marine_formation_env
from baselines import ReferencePolicy
from baselines.engine import evaluate_episodes
from baselines.metrics import episode_metrics
from marine_formation_env.paths import (
    CirclePath,
    LawnmowerPath,
    StraightPath,
    WaypointPath,
    make_path,
)
from marine_formation_env.scenarios import ConfigError, make_config, path_to_inertial

PAPER_D = np.array([[-100.0, 50.0], [0.0, 0.0], [-100.0, -50.0]])


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize(("turn", "sign"), [("left", 1.0), ("right", -1.0)])
def test_circle_frame_matches_the_analytic_circle(turn, sign):
    """P(ℓ) = (R sin(ℓ/R), ±R(1 − cos(ℓ/R))), γ = ±ℓ/R, κ = ±1/R, for ℓ of either sign and past a lap."""
    radius = 350.0
    ell = np.linspace(-1500.0, 4000.0, 777)
    x, y, gamma, kappa = CirclePath(radius, turn).frame(ell)
    np.testing.assert_allclose(x, radius * np.sin(ell / radius), atol=1e-9)
    np.testing.assert_allclose(y, sign * radius * (1.0 - np.cos(ell / radius)), atol=1e-9)
    np.testing.assert_allclose(gamma, sign * ell / radius, atol=1e-12)
    np.testing.assert_array_equal(kappa, sign / radius)


def test_straight_path_is_the_x_axis_and_its_frame_is_the_inertial_frame():
    ell = np.array([-3.0, 0.0, 12.5])
    x, y, gamma, kappa = StraightPath().frame(ell)
    assert np.array_equal(x, ell) and not y.any() and not gamma.any() and not kappa.any()
    state = np.array([[-50.0, 20.0, 0.3, 3.0, 0.1, 0.01]])
    assert np.array_equal(path_to_inertial(StraightPath(), state), state)


def test_lawnmower_route_has_the_analytic_length_joints_and_headings():
    """Legs L, spacing S = 2R: the route is legs shortened by R at each turned end plus half circles."""
    legs, length, radius = 4, 2000.0, 300.0
    path = LawnmowerPath(legs=legs, leg_length=length, spacing=2 * radius, turn_radius=radius)
    expected = 2 * (length - radius) + (legs - 2) * (length - 2 * radius) + (legs - 1) * math.pi * radius
    assert path.length == pytest.approx(expected, rel=1e-12)
    # after the first straight, a half circle to the left brings the route to y = 2R heading −x
    first = length - radius
    x, y, gamma, kappa = path.frame(np.array([first, first + math.pi * radius, first + math.pi * radius + 10.0]))
    np.testing.assert_allclose([x[0], y[0]], [first, 0.0], atol=1e-9)
    np.testing.assert_allclose([x[1], y[1]], [first, 2 * radius], atol=1e-9)
    assert gamma[1] == pytest.approx(math.pi) and kappa[0] == pytest.approx(1.0 / radius)
    np.testing.assert_allclose([x[2], y[2]], [first - 10.0, 2 * radius], atol=1e-9)
    assert kappa[2] == 0.0
    # the second turn goes right (κ < 0), and the last leg ends at its waypoint (0, 3S) heading −x
    assert path.curvature(first + math.pi * radius + (length - 2 * radius) + 1.0) == pytest.approx(-1.0 / radius)
    x_end, y_end, gamma_end, _ = path.frame(path.length)
    np.testing.assert_allclose([x_end, y_end], [0.0, 3 * 2 * radius], atol=1e-8)
    assert math.cos(gamma_end) == pytest.approx(-1.0)


@pytest.mark.parametrize(
    "path",
    [
        LawnmowerPath(legs=3, leg_length=1500.0, spacing=900.0, turn_radius=300.0, first_turn="right"),
        WaypointPath(((0.0, 0.0), (800.0, 0.0), (1400.0, 700.0), (1000.0, 1500.0)), turn_radius=250.0),
        CirclePath(320.0, "right"),
    ],
    ids=["lawnmower", "waypoints", "circle"],
)
def test_path_is_parametrized_by_arc_length_with_continuous_tangent(path):
    """|dP/dℓ| = 1 and dP/dℓ = (cos γ, sin γ) everywhere (central differences), γ continuous across joints."""
    ell = np.linspace(-200.0, 4500.0, 20001)
    h = 1e-3
    xp, yp, _, _ = path.frame(ell + h)
    xm, ym, _, _ = path.frame(ell - h)
    _, _, gamma, _ = path.frame(ell)
    dx, dy = (xp - xm) / (2 * h), (yp - ym) / (2 * h)
    np.testing.assert_allclose(np.hypot(dx, dy), 1.0, atol=1e-6)
    np.testing.assert_allclose(dx, np.cos(gamma), atol=1e-6)
    np.testing.assert_allclose(dy, np.sin(gamma), atol=1e-6)
    assert np.max(np.abs(np.diff(gamma))) < 0.01  # no jump: steps of 0.235 m at R ≥ 250 m turn < 0.001 rad


def test_waypoint_arc_is_tangent_to_both_legs_at_the_fillet_distance():
    """A corner turning by φ is rounded by an arc that meets each leg R·tan(φ/2) from the corner."""
    radius, corner = 200.0, np.array([1000.0, 0.0])
    path = WaypointPath(((0.0, 0.0), tuple(corner), (1000.0 + 600.0, 600.0)), turn_radius=radius)  # φ = 45°
    fillet = radius * math.tan(math.radians(45.0) / 2.0)
    start = 1000.0 - fillet
    x, y, gamma, _ = path.frame(np.array([start, start + radius * math.radians(45.0)]))
    np.testing.assert_allclose([x[0], y[0]], [1000.0 - fillet, 0.0], atol=1e-9)
    end = corner + fillet * np.array([math.cos(math.pi / 4), math.sin(math.pi / 4)])
    np.testing.assert_allclose([x[1], y[1]], end, atol=1e-9)
    assert gamma[1] == pytest.approx(math.pi / 4)


# --------------------------------------------------------------------------- projection


@pytest.mark.parametrize(
    "path",
    [LawnmowerPath(), WaypointPath(((0.0, 0.0), (800.0, 0.0), (1400.0, 700.0)), 250.0), CirclePath(300.0)],
    ids=["lawnmower", "waypoints", "circle"],
)
def test_projection_is_the_nearest_point_of_a_dense_sampling(path):
    """Independent truth: the nearest of 10⁵ sampled path points, for points within 120 m of the path."""
    rng = np.random.default_rng(4)
    ell_true = rng.uniform(0.0, 2500.0, 60)
    px, py, gamma, _ = path.frame(ell_true)
    offset = rng.uniform(-120.0, 120.0, 60)
    x, y = px - offset * np.sin(gamma), py + offset * np.cos(gamma)
    dense = np.linspace(-500.0, 3500.0, 100001)
    sx, sy, _, _ = path.frame(dense)
    nearest = dense[np.argmin(np.hypot(x[:, None] - sx[None], y[:, None] - sy[None]), axis=1)]
    found = path.closest(x, y)
    if isinstance(path, CirclePath):  # the same point on every lap: compare modulo the circumference
        lap = 2 * math.pi * path.radius
        found, nearest = np.mod(found, lap), np.mod(nearest, lap)
        found = np.where(np.abs(found - nearest) > lap / 2, found - np.sign(found - nearest) * lap, found)
    np.testing.assert_allclose(found, nearest, atol=0.05)  # the sampling's spacing
    followed = path.project(x, y, ell_true + rng.uniform(-5.0, 5.0, 60))
    np.testing.assert_allclose(followed, ell_true, atol=1e-7)


def test_projection_follows_the_vessel_without_a_global_search():
    """Around a circle 1.6 times: the followed ℓ grows past 2πR; a global search would wrap to [−πR, πR)."""
    radius = 300.0
    path = CirclePath(radius)
    ell_true = np.linspace(0.0, 1.6 * 2 * math.pi * radius, 3000)  # steps of 1 m
    px, py, gamma, _ = path.frame(ell_true)
    d = 40.0
    x, y = px - d * np.sin(gamma), py + d * np.cos(gamma)
    ell = path.closest(x[0], y[0])
    for k in range(1, len(x)):
        ell = path.project(x[k], y[k], ell)
    assert ell == pytest.approx(ell_true[-1], abs=1e-6)
    lap = 2 * math.pi * radius
    wrapped = (ell_true[-1] + lap / 2) % lap - lap / 2
    assert path.closest(x[-1], y[-1]) == pytest.approx(wrapped, abs=1e-6)


# --------------------------------------------------------------------------- settings and refusals


def test_generalized_assumption_19_refuses_a_tight_turn_naming_the_lane_the_radius_and_the_band():
    with pytest.raises(ConfigError) as err:
        make_config("circle", path={"radius": 290.0})
    message = str(err.value)
    assert "vessel_2" in message and "D_y = -50" in message and "radius 290" in message
    assert "[U_min, U_max] = [3, 7]" in message and "(19)" in message


def test_smallest_admissible_radius_is_300_m_for_the_paper_formation():
    """SPEC §8: (1 + 50/R)·(u_d + a) ≤ U_max ⇔ R ≥ 300 m (u_d = 5, a = 1, U_max = 7)."""
    assert make_config("circle", path={"radius": 300.0}).path.min_radius == 300.0
    with pytest.raises(ConfigError, match=r"\(19\)"):
        make_config("circle", path={"radius": 299.0})
    # the inner lane alone allows 200 m: a right turn puts vessel_0 (D_y = +50) outside
    with pytest.raises(ConfigError, match=r"vessel_0 \(D_y = 50 m\) on the right turn of radius 299"):
        make_config("circle", path={"radius": 299.0, "turn": "right"})


@pytest.mark.parametrize(
    ("path", "match"),
    [
        ({"kind": "spiral"}, "path.kind must be one of"),
        ({"kind": "circle", "radius": -3.0}, "path.radius must be a finite number > 0, got -3.0"),
        ({"kind": "circle", "turn": "up"}, "path.turn must be 'left' or 'right', got 'up'"),
        ({"kind": "circle", "diameter": 3.0}, "unknown key.*diameter"),
        ({"kind": "waypoints", "waypoints": [[0, 0], [100, 0], [0, 0]]}, "turn back on themselves at waypoint 1"),
        ({"kind": "waypoints", "waypoints": [[0, 0], [0, 0]]}, "waypoints 0 and 1 coincide"),
        ({"kind": "waypoints", "waypoints": [[0, 0], [500, 0], [500, 400]], "turn_radius": 450.0}, "leg 1 from"),
        ({"kind": "lawnmower", "spacing": 500.0}, "spacing = 500 m is less than 2·turn_radius = 600 m"),
        ({"kind": "lawnmower", "legs": 0}, "path.legs must be an integer ≥ 1, got 0"),
        (42, "path must be a Path, a kind name or a mapping"),
    ],
)
def test_bad_paths_are_refused_by_name(path, match):
    with pytest.raises(ConfigError, match=match):
        make_config("paper", path=path)


def test_corridor_and_printed_laws_are_checked_against_the_path():
    with pytest.raises(ConfigError, match=r"corridor = 50\.0 applies to curved paths"):
        make_config("paper", corridor=50.0)
    with pytest.raises(ConfigError, match="choose corridor < 250 m"):
        make_config("circle", corridor=260.0)
    with pytest.raises(ConfigError, match="paper_as_printed"):
        make_config("circle", paper_as_printed=True)
    assert make_config("circle").corridor == 125.0  # half of 300 − 50


def test_path_overrides_merge_and_round_trip_through_the_json_description():
    cfg = make_config("survey", path={"legs": 6})
    assert cfg.path == LawnmowerPath(legs=6)  # the preset's other fields kept
    assert make_config("survey", path={"kind": "circle", "radius": 400.0}).path == CirclePath(400.0)
    again = marine_formation_env.scenarios.config_from_dict(cfg.to_dict())
    assert again.path == cfg.path and again.to_dict() == cfg.to_dict()
    assert make_path("circle") == CirclePath()


def test_command_line_sets_a_path_field(tmp_path):
    from baselines.evaluate import main

    out = tmp_path / "circle.json"
    code = main(
        ["--scenario", "circle", "--set", "path.radius=500", "--set", "horizon=20", "--json", str(out), "--quiet"]
    )
    assert code in (0, None)
    import json

    report = json.loads(out.read_text())
    assert report["config"]["path"] == {"kind": "circle", "radius": 500.0, "turn": "left"}
    # where the result comes from: this checkout's commit, the command as typed, the machine
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True)
    assert report["provenance"]["commit"] == head.stdout.strip()
    assert report["provenance"]["command"].startswith(
        "python -m baselines.evaluate --scenario circle --set path.radius"
    )
    assert f"{os.cpu_count()} cores" in report["provenance"]["machine"]


# --------------------------------------------------------------------------- observations on a curved path


def test_circle_observation_holds_path_coordinates_computed_from_the_centre():
    """Independent truth on a circle: ℓ = R·(polar angle about the centre), d = R − |p − c|, γ = ℓ/R."""
    radius = 300.0
    env = marine_formation_env.parallel_env("circle", backend="numpy")
    obs, _ = env.reset(seed=0)
    for _ in range(37):
        obs, *_ = env.step({a: np.array([0.3], dtype=np.float32) for a in env.agents})
    s = env.vessel_states
    rel = s[:, :2] - np.array([0.0, radius])
    angle = np.arctan2(rel[:, 0], -rel[:, 1])  # 0 at the start point (0, 0), counter-clockwise
    ell = radius * angle
    e = radius - np.hypot(rel[:, 0], rel[:, 1]) - PAPER_D[:, 1]
    beta = (s[:, 2] - ell / radius + math.pi) % (2 * math.pi) - math.pi
    metric = 1.0 - (e + PAPER_D[:, 1]) / radius
    ell_dot = (s[:, 3] * np.cos(beta) - s[:, 4] * np.sin(beta)) / metric
    theta = ell - PAPER_D[:, 0]
    for j in range(3):
        o = obs[f"vessel_{j}"]
        np.testing.assert_allclose(o[:2], [e[j], beta[j]], atol=2e-5)
        np.testing.assert_allclose(o[7:10], [1 / radius, 1 / radius, PAPER_D[j, 1]], rtol=1e-6)
        slots = o[10:].reshape(2, 4)
        for k, i in enumerate(((j + 1) % 3, (j + 2) % 3)):
            if slots[k, 0]:
                np.testing.assert_allclose(slots[k, 1:3], [theta[j] - theta[i], ell_dot[j] - ell_dot[i]], atol=1e-4)


def test_curvature_ahead_sees_the_first_turn_coming():
    env = marine_formation_env.parallel_env("survey")
    obs, _ = env.reset(seed=0)
    first_turn = 2000.0 - 300.0
    ell = np.array(env.core.arc[0])
    assert np.all(ell < first_turn - 100.0)  # at the start: no turn within 100 m
    assert all(o[7] == 0.0 and o[8] == 0.0 for o in obs.values())
    policy = ReferencePolicy(env)
    while env.core.arc[0, 1] < first_turn - 60.0:
        obs, *_ = env.step(policy.act(obs))
    o = obs["vessel_1"]
    assert o[7] == 0.0 and o[8] == pytest.approx(1.0 / 300.0)  # the turn 60 m ahead, within the look-ahead


def test_vessel_far_from_its_lane_is_out_of_bounds():
    env = marine_formation_env.parallel_env("circle")
    env.reset(seed=0)
    state = env.vessel_states.copy()
    state[2, 1] -= 200.0  # vessel_2 pushed 200 m outwards, beyond the 125 m corridor
    with pytest.raises(ValueError, match="outside the corridor"):
        env.reset(options={"initial_state": state})


# --------------------------------------------------------------------------- the reference on curved paths


@pytest.mark.parametrize("level", ["speed", "guidance", "force"])
def test_reference_converges_on_the_circle(level):
    """docs/paths.md claims: spread, |e| and the lane-speed error all below 0.05 at the end; u inside the band."""
    cfg = make_config("circle", action_level=level)
    traj = evaluate_episodes(ReferencePolicy(cfg), cfg, seeds=[0])[0]
    m = episode_metrics(traj, cfg)
    assert m["success"] and not m["terminated"]
    assert m["final_coordination_spread"] < 0.05
    assert m["final_cross_track_max"] < 0.05
    assert m["final_speed_error_max"] < 0.05
    u = traj.state[1:, :, 3]  # after the start (the paper's initial state has u = U_min)
    assert cfg.u_min < u.min() and u.max() < cfg.u_max
    # the outer lane (vessel_2, D_y = −50 on a left turn) runs at about (1 + 50/300)·5 in steady turning
    assert u[-1, 2] == pytest.approx((1 + 50 / 300) * 5.0, abs=0.06)  # less the sway's share of the lane speed


@pytest.mark.slow
@pytest.mark.parametrize("level", ["speed", "guidance", "force"])
def test_reference_converges_on_the_survey(level):
    cfg = make_config("survey", action_level=level)
    traj = evaluate_episodes(ReferencePolicy(cfg), cfg, seeds=[0])[0]
    m = episode_metrics(traj, cfg)
    assert m["success"]
    assert max(m["final_coordination_spread"], m["final_cross_track_max"], m["final_speed_error_max"]) < 0.05
    u = traj.state[1:, :, 3]
    assert cfg.u_min < u.min() and u.max() < cfg.u_max


def _final_circle(monkeypatch_crab=None, monkeypatch_lane=None, monkeypatch=None):
    import baselines.reference as reference
    import marine_formation_env.control as control

    if monkeypatch_crab is not None:
        monkeypatch.setattr(control, "turn_crab", monkeypatch_crab)
    if monkeypatch_lane is not None:
        monkeypatch.setattr(reference, "lane_speed", monkeypatch_lane)
    env = marine_formation_env.parallel_env("circle", backend="numpy")  # the laws replaced here are Python's
    policy = ReferencePolicy(env)
    obs, _ = env.reset(seed=0)
    while env.agents:
        obs, *_ = env.step(policy.act(obs))
    core = env.core
    from marine_formation_env.paths import path_coordinates

    s = core.state
    c = path_coordinates(core.config.path, s[..., 0], s[..., 1], s[..., 2], s[..., 3], s[..., 4], core.arc)
    return s[0], c.offset[0] - PAPER_D[:, 1], np.ptp(c.ell[0] - PAPER_D[:, 0]), c.ell_dot[0]


@pytest.mark.slow
def test_plain_laws_leave_the_predicted_offsets_and_the_shipped_ones_remove_them(monkeypatch):
    """docs/paths.md, "The plain generalizations" (SPEC §8's): each one's defect matches its analytic prediction.

    * LOS without the crab angle settles where atan(e/Δ) equals the crab angle: e = Δ·v/u.
    * The lane command (1 − κ·D_y)·w ignores the sway: the projection then moves at w·√(1 + (v/u)²).
    """
    delta = make_config("circle").gains.delta
    state, e, spread, ell_dot = _final_circle()
    print(f"\nshipped: spread {spread:.3g} m, max|e| {np.abs(e).max():.3g} m, ℓ̇ {ell_dot}")
    assert spread < 1e-6 and np.abs(e).max() < 1e-5 and np.allclose(ell_dot, 5.0, atol=1e-6)

    no_crab = lambda p, kappa, u, u_dot, ell_dot, ell_ddot: (0.0 * u, 0.0 * u)
    state, e, spread, ell_dot = _final_circle(no_crab, None, monkeypatch)
    print(f"SPEC LOS: spread {spread:.3g} m, max|e| {np.abs(e).max():.3g} m, ℓ̇ {ell_dot}")
    predicted = delta * state[:, 4] / state[:, 3]  # e = Δ·v/u (sign: LOS aims outward of the sway)
    np.testing.assert_allclose(np.abs(e), np.abs(predicted), rtol=0.02)
    assert np.abs(e).max() > 9.0
    monkeypatch.undo()

    def plain_lane(p, w, w_dot, kappa, d_y):
        return (1.0 - kappa * d_y) * w, (1.0 - kappa * d_y) * w_dot

    state, e, spread, ell_dot = _final_circle(None, plain_lane, monkeypatch)
    print(f"SPEC lane speed: spread {spread:.3g} m, max|e| {np.abs(e).max():.3g} m, ℓ̇ {ell_dot}")
    leader = 1  # vessel_1 has no in-neighbour: w = u_d exactly
    predicted = 5.0 * math.hypot(1.0, state[leader, 4] / state[leader, 3])
    assert ell_dot[leader] == pytest.approx(predicted, rel=1e-4)
    assert ell_dot[leader] - 5.0 > 0.03 and np.abs(e).max() < 1e-4


# --------------------------------------------------------------------------- review findings, kept fixed


def test_a_route_whose_first_turn_uses_up_its_first_leg_still_runs_along_that_leg_before_its_start():
    radius = 100.0
    fillet = radius * math.tan(math.pi / 8)  # the 45° corner's tangent length: the whole first leg
    path = WaypointPath(((0.0, 0.0), (fillet, 0.0), (fillet + 300.0, 300.0)), turn_radius=radius)
    x, y, gamma, kappa = path.frame(np.array([-300.0, -1.0]))
    np.testing.assert_allclose([x[0], y[0], x[1], y[1]], [-300.0, 0.0, -1.0, 0.0], atol=1e-9)
    assert not gamma.any() and not kappa.any()
    assert path.closest(-50.0, 3.0) == pytest.approx(-50.0)


def test_lane_command_is_exact_and_finite_on_a_straight_part_whatever_w():
    from marine_formation_env.control import lane_speed
    from marine_formation_env.params import get_vessel

    w = np.array([-1.0, 0.0, 3.2, 5.0])
    u, u_dot = lane_speed(get_vessel("supply"), w, np.array([0.3, 0.0, -0.1, 0.2]), np.zeros(4), 50.0)
    assert np.array_equal(u, w) and np.array_equal(u_dot, [0.3, 0.0, -0.1, 0.2])
    action = ReferencePolicy(make_config("paper")).act_batch(np.zeros((3, 18)))
    assert np.all(np.isfinite(action))


def test_generalized_assumption_19_counts_the_sway_on_the_slow_side():
    """u_d = 4.2 on a circle of 800 m: (1 − 50/800)·3.2 = 3.0 exactly, the sway of the turn takes 3 mm/s more."""
    with pytest.raises(ConfigError, match=r"from 2\.997 to"):
        make_config("paper", path={"kind": "circle", "radius": 800.0}, u_d={"mean": 4.2})


def test_initial_state_noise_is_drawn_across_the_path_and_the_corridor_holds_every_draw():
    """On a route heading 45°, y-noise of ±60 m is across the path: every start is within |e| ≤ 60 + nominal."""
    from marine_formation_env.scenarios import cross_track_errors, sample_initial_state

    path = {"kind": "waypoints", "waypoints": [[0, 0], [2000, 2000]], "turn_radius": 300.0}
    cfg = make_config("paper", path=path, init_noise={"x": 60.0, "y": 60.0}, corridor=110.0, horizon=10.0)
    rng = np.random.default_rng(0)
    nominal = np.abs(cfg.initial_state[:, 1] - cfg.formation[:, 1])
    for _ in range(300):
        e = cross_track_errors(cfg, sample_initial_state(cfg, rng))
        assert np.all(np.abs(e) <= nominal + 60.0 + 1e-9)
    with pytest.raises(ConfigError, match="outside the corridor"):
        make_config("paper", path=path, init_noise={"y": 80.0}, corridor=110.0)  # 40 m nominal + 80 > 110


def test_rendered_projection_is_the_core_s_even_when_frames_are_far_apart():
    pytest.importorskip("matplotlib")
    env = marine_formation_env.parallel_env("circle", render_mode="rgb_array")
    policy = ReferencePolicy(env)
    obs, _ = env.reset(seed=0)
    for k in range(1, 601):
        obs, *_ = env.step(policy.act(obs))
        if k % 150 == 0:  # 75 s between frames: more than a third of a lap
            env.render()
            np.testing.assert_allclose(env.unwrapped._rendering._renderer._arc, env.core.arc[0], atol=1e-9)
    env.close()


def test_speed_goal_is_through_the_water_with_a_current():
    """The speed error of a curved path is (1 − κ·D_y)·(ℓ̇ − u_d) with ℓ̇ through the water, as u − u_d is."""
    from baselines.metrics import goal_errors

    cfg = make_config("circle", horizon=30.0)
    traj = evaluate_episodes(ReferencePolicy(cfg), cfg, seeds=[0])[0]
    with_current = make_config("circle", horizon=30.0, current={"speed": 0.4, "direction": 0.0})
    np.testing.assert_array_equal(goal_errors(traj, cfg)["speed"], goal_errors(traj, with_current)["speed"])
