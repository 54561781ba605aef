"""Communication as a resource: message counters, event-triggered broadcasting, budgets, the transmit action.

Each check compares the env with an independent truth: counts that follow from the schedule, the graph
and the bucket's arithmetic; the trigger rule re-evaluated from the recorded vessel states; binomial
bounds for random loss; periodic broadcasting for δ = 0; the derived steady-state bound of the spread.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baselines.engine import episode_reports
from baselines.evaluate import main as evaluate_main
from baselines.evaluate import policy_config, reference_options
from baselines.reference import ReferencePolicy
from marine_formation_env.channel import ChannelConfig
from marine_formation_env.core import MESSAGE_KEYS, FormationCore
from marine_formation_env.env import parallel_env
from marine_formation_env.errors import ConfigError
from marine_formation_env.graph import spread_bound
from marine_formation_env.scenarios import make_config, sample_initial_states
from marine_formation_env.vector import MarineFormationVectorEnv

SHORT = {"horizon": 30.0, "action_level": "speed"}


def run_core(config, steps, seed=0, num_envs=2, actions=None, backend="auto"):
    """Step the reference (or fixed ``actions``) for ``steps`` periods; per step its StepOutput and the states."""
    core = FormationCore(config, num_envs=num_envs, backend=backend)
    seeds = [seed + b for b in range(num_envs)]
    core.seed_channel(seeds)
    obs = core.reset(sample_initial_states(config, [np.random.default_rng(s) for s in seeds]))
    reference = None if actions is not None or config.transmit else ReferencePolicy(config, extrapolate=True)
    outs, states, times = [], [core.state.copy()], [core.time.copy()]
    for _ in range(steps):
        act = actions if reference is None else reference.act_batch(obs.reshape(-1, obs.shape[-1]))
        out = core.step(np.asarray(act).reshape(num_envs, config.n_vessels, config.action_dim))
        obs = out.observation
        outs.append(out)
        states.append(core.state.copy())
        times.append(core.time.copy())
    return core, outs, np.array(states), np.array(times)


def counts(outs, key):
    """``(steps, B, N)`` of one counter."""
    return np.array([out.messages[key] for out in outs])


# --------------------------------------------------------------------------- counters


def test_ideal_links_count_one_broadcast_per_period_reaching_each_out_neighbour():
    cfg = make_config("paper", **SHORT)
    _, outs, _, _ = run_core(cfg, 20)
    out_degree = cfg.graph.adjacency.sum(axis=0)  # A[j, i]: i transmits to j
    assert np.all(counts(outs, "messages_sent") == 1)
    assert np.all(counts(outs, "messages_delivered") == out_degree)
    assert np.all(counts(outs, "bits_sent") == cfg.channel.message_bits)
    for key in ("messages_dropped_loss", "messages_dropped_range", "messages_dropped_schedule"):
        assert not counts(outs, key).any()


def test_the_channel_path_counts_as_the_ideal_links_do():
    """A channel that impairs nothing (δ = 0 triggers at every period) counts what the ideal links count."""
    ideal = run_core(make_config("paper", **SHORT), 15)[1]
    channel = run_core(make_config("paper", channel={"event_threshold": 0.0}, **SHORT), 15)[1]
    for key in MESSAGE_KEYS:
        np.testing.assert_array_equal(counts(ideal, key), counts(channel, key), err_msg=key)


def test_tdma_counts_one_broadcast_per_vessel_per_frame():
    cfg = make_config("radio", **SHORT)  # 0.5 s slots, three vessels: each vessel every 1.5 s = 3 periods
    _, outs, _, _ = run_core(cfg, 30)
    sent = counts(outs, "messages_sent")  # steps 1..30
    steps = np.arange(1, 31)[:, None, None]
    expected = (steps % 3 == np.arange(3)).astype(int)
    np.testing.assert_array_equal(sent, np.broadcast_to(expected, sent.shape))


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_loss_counts_follow_the_loss_probability():
    """Bernoulli loss p = 0.3 on every link: the lost share of link messages is p within 4 binomial sigmas."""
    cfg = make_config("paper", channel={"loss": 0.3}, **SHORT)
    _, outs, _, _ = run_core(cfg, 60, num_envs=8)
    lost, delivered = counts(outs, "messages_dropped_loss").sum(), counts(outs, "messages_delivered").sum()
    total = lost + delivered
    assert total == (counts(outs, "messages_sent") * cfg.graph.adjacency.sum(axis=0)).sum()  # a link each
    share = lost / total
    assert abs(share - 0.3) < 4 * math.sqrt(0.3 * 0.7 / total)


def test_links_out_of_range_count_as_dropped_by_range():
    cfg = make_config("paper", channel={"range": 1.0}, **SHORT)  # the vessels start tens of metres apart
    _, outs, _, _ = run_core(cfg, 10)
    out_degree = cfg.graph.adjacency.sum(axis=0)
    np.testing.assert_array_equal(counts(outs, "messages_dropped_range"), np.broadcast_to(out_degree, (10, 2, 3)))
    assert not counts(outs, "messages_delivered").any()


def test_message_bits_scale_the_bits_on_the_channel():
    cfg = make_config("paper", channel={"message_bits": 200}, **SHORT)
    _, outs, _, _ = run_core(cfg, 5)
    np.testing.assert_array_equal(counts(outs, "bits_sent"), 200 * counts(outs, "messages_sent"))


# --------------------------------------------------------------------------- event triggering


@pytest.mark.parametrize(
    "scenario, channel",
    [
        ("paper", {}),
        ("acoustic", {}),
        ("radio", {"failure_rate": 0.05, "recovery_rate": 0.2}),
        ("paper", {"loss": 0.2, "latency": 1.0, "jitter": 0.5, "period": 1.0}),
    ],
)
def test_threshold_zero_equals_periodic_broadcasting_exactly(scenario, channel):
    """δ = 0 and τ_min = dt: the same observations, rewards and counters bit for bit (loss, latency, TDMA)."""
    overrides = {**SHORT, "horizon": 20.0}
    periodic = make_config(scenario, channel=channel, **overrides)
    event = make_config(scenario, channel={**channel, "event_threshold": 0.0, "min_interval": periodic.dt}, **overrides)
    if scenario == "paper" and not channel:  # ideal links run no channel: compare a channel that impairs nothing
        periodic = make_config(scenario, channel={"latency": 0.0, "range": 1e9}, **overrides)
    a, b = run_core(periodic, 40)[1], run_core(event, 40)[1]
    for out_a, out_b in zip(a, b, strict=True):
        np.testing.assert_array_equal(out_a.observation, out_b.observation)
        np.testing.assert_array_equal(out_a.reward, out_b.reward)
        for key in MESSAGE_KEYS:
            np.testing.assert_array_equal(out_a.messages[key], out_b.messages[key])


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_threshold_zero_equals_periodic_on_a_switching_graph():
    schedule = [[10.0, "paper"], [10.0, "complete"]]
    overrides = {**SHORT, "horizon": 40.0, "topology_schedule": schedule}
    a = run_core(make_config("paper", **overrides), 60)[1]
    b = run_core(make_config("paper", channel={"event_threshold": 0.0}, **overrides), 60)[1]
    for out_a, out_b in zip(a, b, strict=True):
        np.testing.assert_array_equal(out_a.observation, out_b.observation)
        np.testing.assert_array_equal(out_a.messages["messages_delivered"], out_b.messages["messages_delivered"])


def test_each_vessel_broadcasts_exactly_when_the_prediction_error_reaches_the_threshold():
    """The trigger re-evaluated from the recorded states: θ = x − D_x and ẋ = u cos ψ − v sin ψ (the paper's
    straight path, ideal links), the neighbours' prediction from the last broadcast, τ_min = 2 periods."""
    delta = 0.5
    cfg = make_config("paper", channel={"event_threshold": delta, "min_interval": 1.0}, **SHORT)
    _, outs, states, times = run_core(cfg, 60, num_envs=1)
    sent = counts(outs, "messages_sent")[:, 0]  # (steps, N), step k + 1
    x, psi, u, v = states[..., 0], states[..., 2], states[..., 3], states[..., 4]
    theta = (x - cfg.formation[:, 0])[:, 0]
    xdot = (u * np.cos(psi) - v * np.sin(psi))[:, 0]
    t = times[:, 0]
    last = np.zeros(3, dtype=int)  # every vessel broadcasts at reset (step 0)
    for k in range(1, 61):
        error = np.maximum(
            np.abs(theta[k] - (theta[last, range(3)] + xdot[last, range(3)] * (t[k] - t[last]))),
            np.abs(xdot[k] - xdot[last, range(3)]),
        )
        due = (error >= delta) & (k - last >= 2)
        # a decision within rounding of the threshold may go either way: the rule is evaluated by other code
        clear = np.abs(error - delta) > 1e-9
        np.testing.assert_array_equal(sent[k - 1][clear], due[clear], err_msg=f"step {k}")
        last = np.where(sent[k - 1] == 1, k, last)
    assert 3 < sent.sum() < 60 * 3  # some broadcasts, far fewer than periodic


def test_min_interval_and_heartbeat_bound_the_gaps_between_broadcasts():
    cfg = make_config("paper", channel={"event_threshold": 0.0, "min_interval": 2.0, "heartbeat": 2.0}, **SHORT)
    _, outs, _, _ = run_core(cfg, 40)
    sent = counts(outs, "messages_sent")
    steps = np.arange(1, 41)
    np.testing.assert_array_equal(sent, np.broadcast_to((steps % 4 == 0)[:, None, None], sent.shape))
    beat = make_config("paper", channel={"event_threshold": math.inf, "heartbeat": 3.0}, **SHORT)
    sent = counts(run_core(beat, 40)[1], "messages_sent")  # δ = inf: the heartbeat alone, every 6 periods
    np.testing.assert_array_equal(sent, np.broadcast_to((steps % 6 == 0)[:, None, None], sent.shape))


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_event_triggered_steady_spread_stays_within_the_derived_bound():
    """With ideal links the paper's law settles where each vessel's neighbours are known within δ: the final
    spread stays within ``spread_bound`` (grounded Laplacian, marine_formation_env.graph), and the bound is
    not vacuous: it grows with δ and the measured spread does too."""
    spreads = []
    for delta in (1.0, 4.0):
        cfg = make_config("paper", channel={"event_threshold": delta}, horizon=300.0)
        metrics, _ = episode_reports(ReferencePolicy(cfg, extrapolate=True), cfg, [0, 1])
        final = max(m["final_coordination_spread"] for m in metrics)
        assert final <= spread_bound(cfg.graph, delta)
        spreads.append(final)
    assert spread_bound(make_config("paper").graph, 1.0) == pytest.approx(2.5)  # worked out in docs/channel.md
    assert spreads[1] > spreads[0]


# --------------------------------------------------------------------------- budgets


def test_the_token_bucket_releases_what_its_arithmetic_allows():
    """paper_budget: 384 bit full at reset, 24 bit per 0.5 s period, 96 bit a message: periodic broadcasting
    sends at steps 0-4, then every fourth step; cumulative sends N(k) = min(k + 1, ⌊(384 + 24k) / 96⌋)."""
    cfg = make_config("paper_budget", **SHORT)
    _, outs, _, _ = run_core(cfg, 40)
    sent = counts(outs, "messages_sent")
    cumulative = 1 + np.cumsum(sent, axis=0)  # the reset instant's broadcast first
    k = np.arange(1, 41)
    expected = np.minimum(k + 1, (384 + 24 * k) // 96)
    np.testing.assert_array_equal(cumulative, np.broadcast_to(expected[:, None, None], sent.shape))
    blocked = counts(outs, "messages_dropped_budget")
    np.testing.assert_array_equal(blocked + sent, counts(outs, "messages_attempted"))


@pytest.mark.parametrize("name, periodic_rate", [("paper_budget", 2.0), ("acoustic_budget", 1.0 / 12.0)])
def test_the_budget_presets_are_exceeded_several_times_over_by_periodic_broadcasting(name, periodic_rate):
    ch = make_config(name).channel
    allowed = ch.budget_rate / ch.message_bits  # messages per second in the long run
    assert periodic_rate / allowed >= 3


# --------------------------------------------------------------------------- the transmit action


def _track(states, cfg):
    """``θ = x − D_x`` and ``ẋ = u cos ψ − v sin ψ`` of recorded states ``(..., N, 6)`` (docs/model.md, (20))."""
    x, psi, u, v = (states[..., k] for k in (0, 2, 3, 4))
    return x - cfg.formation[:, 0], u * np.cos(psi) - v * np.sin(psi)


def test_transmit_decides_and_the_observation_says_budget_age_and_drift():
    cfg = make_config("paper_budget", transmit=True, **SHORT)
    assert cfg.action_dim == 2 and cfg.control_dim == 1
    assert cfg.sensor_noise.is_zero  # what a vessel sends is its state
    silent = np.tile([0.0, -1.0], (2, 3, 1))  # speed command 0, never transmit
    _, outs, states, times = run_core(cfg, 8, actions=silent)
    assert not counts(outs, "messages_attempted").any()  # only the reset instant's broadcast
    obs = outs[-1].observation
    np.testing.assert_allclose(obs[..., -3], np.minimum(384 - 96 + 8 * 24, 384) / 384)  # bucket refilled
    np.testing.assert_allclose(obs[..., -2], np.broadcast_to(times[-1][:, None], (2, 3)))  # since reset
    # the drift: what the others predict from the reset instant's broadcast, θ_0 + ẋ_0·t, against θ, ẋ now
    (theta0, xdot0), (theta, xdot) = _track(states[0], cfg), _track(states[-1], cfg)
    drift = np.maximum(np.abs(theta - theta0 - xdot0 * times[-1][:, None]), np.abs(xdot - xdot0))
    assert 0.01 < drift.min() and drift.max() < 10.0  # neither 0 nor at the bound: the check can tell
    np.testing.assert_allclose(obs[..., -1], drift, rtol=1e-5, atol=1e-5)  # float32 observations
    loud = np.tile([0.0, 1.0], (2, 3, 1))
    loud_outs = run_core(cfg, 8, actions=loud)[1]
    sent = counts(loud_outs, "messages_sent")
    for out, now in zip(loud_outs, sent, strict=True):  # a vessel that has just broadcast is predicted exactly
        assert np.all(out.observation[..., -1][now == 1] == 0.0)
        assert np.all(out.observation[..., -1][now == 0] > 0.0)
    budget_only = make_config("paper_budget", **SHORT)
    periodic = counts(run_core(budget_only, 8, actions=np.zeros((2, 3, 1)))[1], "messages_sent")
    np.testing.assert_array_equal(sent, periodic)  # always transmitting is periodic broadcasting under the budget


def test_transmit_outside_the_tdma_slot_is_dropped_by_schedule():
    cfg = make_config("radio", transmit=True, **SHORT)
    _, outs, _, _ = run_core(cfg, 12, actions=np.tile([0.0, 1.0], (2, 3, 1)))
    attempted, sent = counts(outs, "messages_attempted"), counts(outs, "messages_sent")
    assert np.all(attempted == 1)
    np.testing.assert_array_equal(counts(outs, "messages_dropped_schedule"), attempted - sent)
    assert sent.sum() == 12 * 2  # one slot per period, in two formations


def test_message_cost_charges_each_broadcast():
    cost = make_config("paper_budget", reward={"message_cost": 0.01}, **SHORT)
    free = make_config("paper_budget", **SHORT)
    actions = np.zeros((2, 3, 1))
    with_cost, without = run_core(cost, 6, actions=actions)[1], run_core(free, 6, actions=actions)[1]
    for a, b in zip(with_cost, without, strict=True):
        np.testing.assert_allclose(a.reward - b.reward, -0.01 * a.messages["messages_sent"])
        np.testing.assert_allclose(a.components["communication"], -0.01 * a.messages["messages_sent"])


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_every_front_end_reports_the_counters():
    env = parallel_env("acoustic", **SHORT)
    _, infos = env.reset(seed=0)
    assert all(key in infos["vessel_0"] for key in MESSAGE_KEYS)
    _, _, _, _, infos = env.step({agent: np.zeros(1) for agent in env.agents})
    assert isinstance(infos["vessel_0"]["messages_sent"], int)
    venv = MarineFormationVectorEnv(2, "acoustic", layout="joint", **SHORT)
    _, infos = venv.reset(seed=0)
    _, _, _, _, infos = venv.step(np.zeros((2, 3)))
    assert infos["messages_sent"].shape == (2,)
    venv.close()


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_evaluation_reports_messages_per_vessel_per_second():
    cfg = make_config("radio", **SHORT)
    metrics, _ = episode_reports(ReferencePolicy(cfg), cfg, [0])
    # TDMA: one broadcast per vessel every 1.5 s: 20 in the 30 s after reset
    assert metrics[0]["message_rate"] == pytest.approx(20 / 30.0)
    assert metrics[0]["bit_rate"] == pytest.approx(20 / 30.0 * 96)


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_reference_event_option_runs_the_extrapolating_reference_with_event_triggering(capsys):
    assert reference_options("reference:event=0.5") == {"extrapolate": True}
    cfg = policy_config("reference:event=0.5", make_config("acoustic"))
    assert cfg.channel.event_threshold == 0.5 and cfg.channel.tdma_slot == 4.0
    assert evaluate_main(["--scenario", "paper", "--policy", "reference", "--policy", "reference:event=2",
                          "--set", "horizon=40", "--quiet"]) == 0  # fmt: skip


# --------------------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    "channel, words",
    [
        ({"event_threshold": -0.1}, "event_threshold"),
        ({"event_threshold": float("nan")}, "event_threshold"),
        ({"event_threshold": 0.5, "min_interval": 0.7}, "channel.min_interval = 0.7 s"),
        ({"event_threshold": 0.5, "heartbeat": 0.25}, "heartbeat"),
        ({"min_interval": 1.0}, "event_threshold"),
        ({"budget_rate": 0.0}, "budget_rate"),
        ({"budget_rate": -5.0}, "budget_rate"),
        ({"budget_rate": 10.0, "budget_burst": 50.0}, "budget_burst = 50.0"),
        ({"budget_burst": 200.0}, "budget_rate"),
        ({"message_bits": 0}, "message_bits"),
        ({"event_threshold": math.inf}, "heartbeat"),
    ],
)
def test_bad_traffic_settings_are_refused_naming_the_value(channel, words):
    with pytest.raises(ConfigError, match=words.replace(".", r"\.").replace("(", r"\(")):
        make_config("paper", channel=channel)


def test_a_policy_that_does_not_send_transmit_is_refused():
    env = parallel_env("paper_budget", transmit=True, **SHORT)
    with pytest.raises(ValueError, match="does not send the transmit action"):
        ReferencePolicy(env)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="transmit=True"):
        env.step({agent: np.zeros(1) for agent in env.agents})
    with pytest.raises(ConfigError, match="transmit"):
        make_config("paper", transmit="yes")


def test_the_evaluation_refuses_the_reference_on_a_transmit_scenario_before_any_episode(monkeypatch, capsys):
    import baselines.evaluate as evaluation

    ran = []
    monkeypatch.setattr(evaluation, "episode_reports", lambda *args, **kwargs: ran.append(args) or ([], []))
    with pytest.raises(SystemExit):
        evaluate_main(["--scenario", "paper_budget", "--set", "transmit=true", "--set", "action_level=speed",
                       "--policy", "random", "--policy", "reference", "--episodes", "1", "--quiet"])  # fmt: skip
    assert "does not send the transmit action" in capsys.readouterr().err
    assert ran == []  # the random policy, listed first, did not run either


def test_channel_config_defaults_are_the_ideal_links():
    assert ChannelConfig().is_ideal and ChannelConfig(message_bits=200).is_ideal
    assert not ChannelConfig(event_threshold=0.0).is_ideal


@pytest.mark.backend_independent
def test_compiled_and_numpy_backends_count_alike():
    """Periodic broadcasting with loss, TDMA and a budget: the same draws, the same counters in both backends
    (whole numbers: exactly). Event triggering decides on floating-point errors that may differ in the last
    bit between backends, so there the totals agree to a message per formation and vessel, not exactly."""
    pytest.importorskip("numba")
    for name, channel, exact in (("acoustic_budget", {}, True), ("radio", {"event_threshold": 0.5}, False)):
        cfg = make_config(name, channel=channel, **SHORT)
        fast = run_core(cfg, 50, backend="numba")[1]
        slow = run_core(cfg, 50, backend="numpy")[1]
        for key in MESSAGE_KEYS:
            a, b = counts(fast, key), counts(slow, key)
            if exact:
                np.testing.assert_array_equal(a, b, err_msg=key)
            else:
                assert np.abs(a.sum(axis=0) - b.sum(axis=0)).max() <= (96 if key == "bits_sent" else 1), key


@pytest.mark.backend_independent
def test_compiled_and_numpy_backends_observe_the_transmit_entries_alike():
    """Random transmit decisions over TDMA links with a budget and sensor noise: the budget left, the age and
    the drift (of the noisy measurement the channel sent) agree within float32 rounding, on both paths of the
    compiled backend (its kernel's step and the numpy reset)."""
    pytest.importorskip("numba")
    cfg = make_config("acoustic_budget", transmit=True, sensor_noise={"position": 0.5, "speed": 0.05}, **SHORT)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1.0, 1.0, (2, 3, 2)) for _ in range(40)]
    observed = []
    for backend in ("numba", "numpy"):
        core = FormationCore(cfg, num_envs=2, backend=backend)
        core.seed_channel([0, 1])
        obs = [core.reset(sample_initial_states(cfg, [np.random.default_rng(s) for s in (0, 1)]))]
        obs += [core.step(a).observation for a in actions]
        observed.append(np.array(obs)[..., -3:])
    fast, slow = observed
    assert 0.0 < slow[..., 2].mean() < 10.0  # the drift is neither always 0 nor always at its bound
    np.testing.assert_allclose(fast, slow, rtol=1e-5, atol=1e-5)


@pytest.mark.backend_independent  # the compiled pass covers it; test_backends the agreement
def test_the_transmit_views_pass_the_gymnasium_and_pettingzoo_checkers():
    import warnings

    import gymnasium
    from gymnasium.utils.env_checker import check_env
    from pettingzoo.test import parallel_api_test

    env = gymnasium.make("MarineFormation-v1", scenario="acoustic_budget", transmit=True, horizon=30.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    parallel_api_test(parallel_env("paper_budget", transmit=True, horizon=30.0), num_cycles=80)
