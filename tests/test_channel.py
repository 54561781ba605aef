"""The communication channel: ideal limit, loss, latency, ages, TDMA, range, switching, seeds.

Truth comes from the recorded physical states and from the definitions of the
channel (module docstring of ``marine_formation_env.channel``), computed here
independently: which step a message was sent at, what θ and ẋ the sender had
then, and what the receiver's observation must therefore show.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import marine_formation_env
from baselines import ReferencePolicy
from marine_formation_env.channel import BlockStream, ChannelConfig, GilbertElliott, channel_streams
from marine_formation_env.core import FormationCore
from marine_formation_env.graph import CommGraph
from marine_formation_env.observations import ObservationLayout
from marine_formation_env.scenarios import ConfigError, make_config
from marine_formation_env.vector import MarineFormationVectorEnv

#: A channel that takes the channel code path but impairs nothing.
TRANSPARENT = {"range": 1e12}


def _run_core(cfg, steps, actions_seed=0, b=1, channel_seed=5):
    """Step a core with random actions; return (states (T+1, B, N, 6), observations (T+1, B, N, D), times)."""
    core = FormationCore(cfg, b)
    rng = np.random.default_rng(actions_seed)
    core.seed_channel([channel_seed + k for k in range(b)])
    obs = [core.reset(np.broadcast_to(cfg.initial_state, (b, cfg.n_vessels, 6)).copy())]
    states, times = [core.state.copy()], [core.time.copy()]
    for _ in range(steps):
        out = core.step(rng.uniform(-1, 1, (b, cfg.n_vessels, cfg.action_dim)))
        obs.append(out.observation)
        states.append(core.state.copy())
        times.append(core.time.copy())
    return np.array(states), np.array(obs), np.array(times), core


def _theta_xdot(cfg, state):
    """θ = x − D_x and ẋ (still water) from states ``(..., N, 6)``, written from the definitions."""
    theta = state[..., 0] - cfg.formation[:, 0]
    xdot = state[..., 3] * np.cos(state[..., 2]) - state[..., 4] * np.sin(state[..., 2])
    return theta, xdot


def _slots(cfg, obs):
    return ObservationLayout(cfg.n_vessels).split(obs)[1]


# ---------------------------------------------------------------- ideal limit
@pytest.mark.parametrize("level", ["speed", "guidance", "force"])
def test_transparent_channel_is_bit_identical_to_ideal_links(level):
    ideal = make_config("paper", action_level=level, init_noise={"x": 30.0, "y": 10.0})
    transparent = make_config("paper", action_level=level, init_noise={"x": 30.0, "y": 10.0}, channel=TRANSPARENT)
    s0, o0, _, core0 = _run_core(ideal, 150, b=2)
    s1, o1, _, core1 = _run_core(transparent, 150, b=2)
    assert core0.channel is None and core1.channel is not None  # two different code paths
    assert np.array_equal(s0, s1)
    assert np.array_equal(o0, o1)


def test_default_channel_is_ideal_and_draws_nothing():
    cfg = make_config("paper")
    assert cfg.channel.is_ideal and cfg.ideal_observations
    assert FormationCore(cfg).channel is None


# ------------------------------------------------------------------------ loss
def test_loss_one_on_a_link_equals_the_link_being_absent():
    # paper graph: 1 → 0, 1 → 2, 0 → 2; lose everything on 0 → 2 (A[j=2, i=0])
    loss = np.zeros((3, 3))
    loss[2, 0] = 1.0
    lossy = make_config("paper", channel={"loss": loss.tolist()})
    absent = make_config("paper", topology=CommGraph.from_links(3, [(1, 0), (1, 2)]))
    s_a, o_a, _, _ = _run_with_reference(lossy)
    s_b, o_b, _, _ = _run_with_reference(absent)
    assert np.array_equal(o_a, o_b)
    assert np.array_equal(s_a, s_b)
    # and the lost link really carried information: with it, vessel 2 behaves differently
    s_c, _, _, _ = _run_with_reference(make_config("paper"))
    assert np.abs(s_c - s_a).max() > 1.0


def _run_with_reference(cfg, steps=300, channel_seed=3):
    core = FormationCore(cfg, 1)
    core.seed_channel([channel_seed])
    policy = ReferencePolicy(cfg)
    obs = core.reset(cfg.initial_state)
    observations, states, times = [obs.copy()], [core.state.copy()], [core.time.copy()]
    for _ in range(steps):
        out = core.step(policy.act_batch(obs))
        obs = out.observation
        observations.append(obs.copy())
        states.append(core.state.copy())
        times.append(core.time.copy())
    return np.array(states), np.array(observations), np.array(times), core


def test_loss_probability_one_everywhere_empties_every_slot():
    cfg = make_config("paper", channel={"loss": 1.0})
    _, obs, _, _ = _run_core(cfg, 20)
    assert not np.any(_slots(cfg, obs))


@pytest.mark.parametrize("p", [0.2, 0.6])
def test_bernoulli_loss_rate_and_runs(p):
    """Per message lost with probability p: loss fraction p, runs of losses of mean length 1/(1−p)."""
    cfg = make_config("paper", topology="complete", channel={"loss": p, **TRANSPARENT})
    rows = _loss_indicator(cfg, 300)
    lost = np.concatenate(rows)
    assert lost.mean() == pytest.approx(p, abs=4 * math.sqrt(p * (1 - p) / lost.size))
    runs = _run_lengths(rows)
    assert runs.mean() == pytest.approx(1 / (1 - p), rel=0.08)


def test_gilbert_elliott_loss_rate_and_burst_length():
    """Bad spells (all lost) last 1/p_bad_to_good messages on average; long-run loss = stationary P(bad)."""
    ge = GilbertElliott(p_good_to_bad=0.05, p_bad_to_good=0.25, loss_good=0.0, loss_bad=1.0)
    cfg = make_config("paper", topology="complete", channel={"burst": ge, **TRANSPARENT})
    rows = _loss_indicator(cfg, 500, b=24)
    assert ge.mean_loss == pytest.approx(0.05 / 0.30)
    assert np.concatenate(rows).mean() == pytest.approx(ge.mean_loss, abs=0.02)
    runs = _run_lengths(rows)
    assert runs.mean() == pytest.approx(1 / 0.25, rel=0.1)
    # bursty: far longer runs than independent loss at the same rate (1/(1−p) ≈ 1.2)
    assert runs.mean() > 3.0


def _loss_indicator(cfg, steps, b=16):
    """One row per (formation, link), in time order: was this period's message lost?

    With zero latency and a message every period, a delivered message shows
    age 0 in the slot at once; an older age means this period's message was
    lost. Rows start at each link's first delivery (before it nothing is known).
    """
    _, obs, _, _ = _run_core(cfg, steps, b=b)
    slots = _slots(cfg, obs)  # (T+1, B, N, N−1, 4)
    linked, age = slots[..., 0], slots[..., 3]
    lost = (age > 0).reshape(len(age), -1).T
    first = np.argmax(linked.reshape(len(linked), -1).T > 0, axis=1)
    return [row[k + 1 :] for row, k in zip(lost, first, strict=True)]


def _run_lengths(rows):
    """Lengths of the runs of True in each row, without the runs cut by a row's ends."""
    lengths = []
    for row in rows:
        padded = np.concatenate([[0], np.asarray(row, dtype=int), [0]])
        edges = np.flatnonzero(np.diff(padded))
        starts, ends = edges[::2], edges[1::2]
        inside = (starts > 0) & (ends < len(row))
        lengths.extend((ends - starts)[inside])
    return np.array(lengths, dtype=float)


# ------------------------------------------------------------ latency and ages
@pytest.mark.parametrize("k", [1, 3, 7])
def test_latency_of_k_control_periods_delays_by_exactly_k(k):
    cfg = make_config("paper", action_level="speed", channel={"latency": k * 0.5})
    states, obs, times, _ = _run_core(cfg, 60)
    theta, xdot = _theta_xdot(cfg, states[:, 0])
    slots = _slots(cfg, obs)[:, 0]
    layout = ObservationLayout(3)
    adjacency = cfg.graph.adjacency
    for m in range(len(times)):
        for j in range(3):
            for slot, i in enumerate(layout.slot_vessels(j)):
                link, d_theta, d_xdot, age = slots[m, j, slot]
                if not adjacency[j, i] or m < k:
                    assert (link, d_theta, d_xdot, age) == (0, 0, 0, 0)
                    continue
                assert link == 1
                assert age == np.float32(k * 0.5)
                assert d_theta == np.float32(theta[m, j] - theta[m - k, i])
                assert d_xdot == np.float32(xdot[m, j] - xdot[m - k, i])


def test_fractional_latency_rounds_up_to_the_next_control_instant():
    """0.6 s at dt = 0.5 s: a message arrives after 0.6 s, so it is seen 2 periods (1.0 s) after sending."""
    cfg = make_config("paper", channel={"latency": 0.6})
    _, obs, _, _ = _run_core(cfg, 10)
    slots = _slots(cfg, obs)[:, 0]
    assert not slots[1, ..., 0].any()  # at t = 0.5 s nothing can have arrived
    ages = slots[2:, ..., 3][slots[2:, ..., 0] == 1]
    assert ages.size and np.all(ages == np.float32(1.0))


@pytest.mark.parametrize("period_steps", [2, 5])
def test_ages_with_a_transmission_period(period_steps):
    """Every vessel transmits at k·T_tx; zero latency: the age is (m mod P)·dt."""
    cfg = make_config("paper", action_level="force", channel={"period": period_steps * 0.1})
    _, obs, times, _ = _run_core(cfg, 40)
    slots = _slots(cfg, obs)[:, 0]
    for m in range(len(times)):
        linked = slots[m, ..., 0] == 1
        expected = np.float32((m % period_steps) * 0.1)
        np.testing.assert_allclose(slots[m, ..., 3][linked], expected, atol=1e-6)


@pytest.mark.parametrize("n", [3, 5])
def test_tdma_one_transmitter_per_slot_round_robin(n):
    slot_steps = 2
    cfg = make_config("paper", n_vessels=n, topology="complete", channel={"tdma_slot": slot_steps * 0.5})
    _, _, _, core = _run_core(cfg, 0)
    senders = []
    for _ in range(60):
        senders.append(core.channel.transmitted[0].copy())
        core.step(np.zeros((1, n, 1)))
    senders = np.array(senders)
    assert senders.sum(axis=1).max() == 1  # never two transmitters at one instant
    frame = n * slot_steps
    for i in range(n):  # vessel i owns the slot starting at i·S in every frame
        assert np.array_equal(np.flatnonzero(senders[:, i]), np.arange(i * slot_steps, 60, frame))


def test_tdma_ages_from_the_observations():
    """Independent check from what vessels see: fresh (age 0) data come from one sender per instant."""
    n, slot_steps = 4, 1
    cfg = make_config("paper", n_vessels=n, topology="complete", channel={"tdma_slot": 0.5})
    _, obs, times, _ = _run_core(cfg, 30)
    slots = _slots(cfg, obs)[:, 0]
    layout = ObservationLayout(n)
    for m in range(len(times)):
        fresh = {
            layout.slot_vessels(j)[s]
            for j in range(n)
            for s in range(n - 1)
            if slots[m, j, s, 0] and slots[m, j, s, 3] == 0
        }
        assert fresh == {m % n}
        # every held message is as old as the last slot of its sender
        for j in range(n):
            for s, i in enumerate(layout.slot_vessels(j)):
                if slots[m, j, s, 0]:
                    last = m - ((m - i * slot_steps) % (n * slot_steps))
                    assert slots[m, j, s, 3] == pytest.approx((m - last) * 0.5, abs=1e-5)


def test_late_message_never_replaces_a_newer_one():
    """With large jitter messages overtake each other; the held one is always the newest sent so far."""
    cfg = make_config("paper", channel={"latency": 0.5, "jitter": 3.0})
    _, obs, times, _ = _run_core(cfg, 200)
    slots = _slots(cfg, obs)[:, 0]
    age = slots[..., 3]
    linked = slots[..., 0] == 1
    # the send time t − age of the held message never decreases on a link
    sent = np.where(linked, times[:, 0, None, None] - age, np.nan)
    layout = ObservationLayout(3)
    for j in range(3):
        for s, i in enumerate(layout.slot_vessels(j)):
            if not cfg.graph.adjacency[j, i]:
                continue
            series = sent[:, j, s][~np.isnan(sent[:, j, s])]
            assert series.size > 100 and np.all(np.diff(series) >= -1e-4)
    assert np.any(np.diff(age[:, 0, 0]) > 0.5)  # messages did arrive out of order or not at all some periods
    assert age.max() <= 0.5 + 3.0 + 0.5 + 1e-5  # never older than the worst delay plus one period


# ------------------------------------------------------- range and switching
def test_range_limited_links_follow_the_distances():
    cfg = make_config("paper", formation="column", topology="complete", initial_state=None, channel={"range": 150.0})
    states, obs, _, _ = _run_core(cfg, 30)
    slots = _slots(cfg, obs)[:, 0]
    layout = ObservationLayout(3)
    for m in range(len(states)):
        pos = states[m, 0, :, :2]
        for j in range(3):
            for s, i in enumerate(layout.slot_vessels(j)):
                in_range = np.hypot(*(pos[j] - pos[i])) <= 150.0
                assert slots[m, j, s, 0] == float(in_range)
    assert slots[..., 0].min() == 0 and slots[..., 0].max() == 1  # both cases occur (100 m vs 200 m apart)


def test_switching_schedule_sets_the_links():
    chain, ring = CommGraph.from_links(3, [(0, 1), (1, 2)]), CommGraph.from_links(3, [(0, 1), (1, 2), (2, 0)])
    cfg = make_config("paper", topology_schedule=[(5.0, chain), (2.5, ring)])
    assert cfg.graph.links == ring.links  # the union
    _, obs, times, _ = _run_core(cfg, 60)
    slots = _slots(cfg, obs)[:, 0]
    layout = ObservationLayout(3)
    for m, t in enumerate(times[:, 0]):
        graph = chain if (t % 7.5) < 5.0 - 1e-9 else ring
        for j in range(3):
            for s, i in enumerate(layout.slot_vessels(j)):
                assert slots[m, j, s, 0] == float(graph.adjacency[j, i]), (t, j, i)


def test_random_link_failures_and_recovery():
    """Down fraction of a link → λ/(λ+μ) (per period: p_f/(p_f+p_r)); mean down time 1/μ."""
    lam, mu = 0.05, 0.2
    cfg = make_config("paper", topology="complete", channel={"failure_rate": lam, "recovery_rate": mu})
    _, obs, _, _ = _run_core(cfg, 500, b=48)
    down = _slots(cfg, obs)[1:, ..., 0] == 0
    p_f, p_r = -math.expm1(-lam * 0.5), -math.expm1(-mu * 0.5)
    # every link starts live: skip the first 100 periods (p_f + p_r ≈ 0.12 per period: long mixed)
    assert down[100:].mean() == pytest.approx(p_f / (p_f + p_r), abs=0.03)
    runs = _run_lengths(down.reshape(len(down), -1).T)
    assert runs.mean() * 0.5 == pytest.approx(0.5 / p_r, rel=0.12)


# ------------------------------------------------------------ seeds and noise
def test_channel_seeds_reproduce_runs_and_differ_between_seeds():
    def episode(seed, channel_seed=None):
        env = marine_formation_env.parallel_env("acoustic")
        policy = ReferencePolicy(env)
        options = None if channel_seed is None else {"channel_seed": channel_seed}
        obs, _ = env.reset(seed=seed, options=options)
        trace = []
        for _ in range(120):
            obs, *_ = env.step(policy.act(obs))
            trace.append(np.concatenate(list(obs.values())))
        return np.array(trace)

    a, b = episode(11), episode(11)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, episode(12))
    # the channel stream alone: same reset seed, another channel seed
    assert not np.array_equal(a, episode(11, channel_seed=99))
    assert np.array_equal(episode(11, channel_seed=99), episode(11, channel_seed=99))


def test_channel_stream_is_separate_from_the_initial_state_stream():
    uniform, normal = channel_streams(4)
    assert not np.array_equal(uniform.random(5), np.random.default_rng(4).random(5))
    assert not np.array_equal(normal.random(5), channel_streams(4)[0].random(5))
    # an impaired channel does not change the initial states drawn from the same seed
    noisy = {"init_noise": {"x": 30.0}, "initial_state": None}
    e1 = marine_formation_env.parallel_env("paper", **noisy)
    e2 = marine_formation_env.parallel_env("acoustic", **noisy)
    e1.reset(seed=8)
    e2.reset(seed=8)
    assert np.array_equal(e1.vessel_states, e2.vessel_states)


@pytest.mark.parametrize("normal", [False, True])
def test_block_streams_serve_the_same_numbers_whatever_the_block_size(normal):
    streams = [BlockStream(3, 5, normal=normal, max_floats=m) for m in (1, 60, 10**6)]
    assert [s.block for s in streams] == [2, 4, 64]
    for s in streams:
        for b in range(3):
            s.seed(b, np.random.default_rng(100 + b))
    rng = np.random.default_rng(0)
    for _ in range(150):  # formations advance unevenly, as with resets
        ids = np.flatnonzero(rng.random(3) < 0.7)
        # the compiled step asks for two unread rows where a formation restarts: refilling early keeps the order
        streams[int(rng.integers(3))].refill(ids, rows=2)
        rows = [s.take(ids) for s in streams]
        assert np.array_equal(rows[0], rows[1]) and np.array_equal(rows[0], rows[2])
    with pytest.raises(ValueError, match="rows must be in"):
        streams[0].refill(rows=3)
    first = BlockStream(1, 5, normal=normal)
    first.seed(0, np.random.default_rng(100))
    direct = np.random.default_rng(100)
    expected = direct.standard_normal((2, 5)) if normal else direct.random((2, 5))
    assert np.array_equal(np.concatenate([first.take(np.array([0])), first.take(np.array([0]))]), expected)


def test_vector_env_formation_reproduces_the_parallel_env_with_its_seed():
    b = 3
    noise = {"sensor_noise": {"position": 1.0, "speed": 0.05}}
    venv = MarineFormationVectorEnv(num_envs=b, scenario="acoustic", layout="joint", **noise)
    obs_v, _ = venv.reset(seed=20)
    policy = ReferencePolicy(venv.config)
    singles = [marine_formation_env.parallel_env("acoustic", **noise) for _ in range(b)]
    obs_s = [env.reset(seed=20 + k)[0] for k, env in enumerate(singles)]
    for _ in range(60):
        for k in range(b):
            np.testing.assert_array_equal(obs_v[k], np.concatenate([obs_s[k][a] for a in singles[k].possible_agents]))
        actions = policy.act_batch(obs_v.reshape(b, 3, -1))
        obs_v, *_ = venv.step(actions.reshape(b, -1))
        obs_s = [env.step(policy.act(o))[0] for env, o in zip(singles, obs_s, strict=True)]


def test_sensor_noise_statistics_and_that_only_observations_are_noisy():
    cfg = make_config("paper", sensor_noise={"position": 2.0, "heading": 0.01, "speed": 0.1, "yaw_rate": 0.001})
    states, obs, _, _ = _run_core(cfg, 250, b=16)
    clean = make_config("paper")
    s_clean, o_clean, _, _ = _run_core(clean, 250, b=16)
    assert np.array_equal(states, s_clean)  # the physics does not see the noise (random actions, same seed)
    own_err = obs[..., :5].astype(float) - o_clean[..., :5].astype(float)
    np.testing.assert_allclose(own_err.std(axis=(0, 1, 2)), [2.0, 0.01, 0.1, 0.1, 0.001], rtol=0.05)
    assert np.all(np.abs(own_err.mean(axis=(0, 1, 2))) < [0.1, 5e-4, 5e-3, 5e-3, 5e-5])


# ------------------------------------------------ the reference under impairments
def test_extrapolation_recovers_the_current_difference_for_constant_velocities():
    """Constant velocities: θ_i(now) = θ_i(t_s) + ẋ_i·age exactly, so the extrapolated s_j is the true one."""
    cfg = make_config("paper", channel={"latency": 1.5})
    layout = ObservationLayout(3)
    obs = np.zeros(layout.dim)
    u_j, u_i, age = 5.2, 4.6, 3.0
    true_gap = 12.0  # θ_j − θ_i now
    obs[:10] = [0.0, 0.0, u_j, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0]
    # vessel 2 receives from 0 and 1 (paper graph); both slots hold a 3 s old message of speed u_i
    for s in range(2):
        base = 10 + 4 * s
        stale_gap = true_gap + u_i * age  # θ_j(now) − θ_i(now − age)
        obs[base : base + 4] = [1.0, stale_gap, u_j - u_i, age]
    plain = ReferencePolicy(cfg).commands(obs)["u_c"]
    extrap = ReferencePolicy(cfg, extrapolate=True).commands(obs)["u_c"]
    a = cfg.gains.a
    assert extrap == pytest.approx(5.0 - (2 * a / math.pi) * math.atan(2 * true_gap))
    assert plain == pytest.approx(5.0 - (2 * a / math.pi) * math.atan(2 * (true_gap + u_i * age)))


def test_reference_under_radio_converges_with_extrapolation():
    """Documented bounds (docs/results.md): extrapolating reference under `radio` settles; final errors < 1 cm."""
    env = marine_formation_env.parallel_env("radio")
    from baselines.engine import run_episode
    from baselines.metrics import episode_metrics

    for seed in range(3):
        m = episode_metrics(run_episode(env, ReferencePolicy(env, extrapolate=True), seed=seed), env.config)
        assert m["final_coordination_spread"] < 0.01
        assert m["final_cross_track_max"] < 0.01
        assert m["final_speed_error_max"] < 0.01
        assert m["settling_time"] is not None and m["settling_time"] < 200.0


def test_plain_reference_under_radio_holds_the_predicted_lag():
    """Without extrapolation a follower sees its leader where it was ``age`` seconds ago.

    Averaged over the cycle, g(s_j) = 0 needs Σ_i (θ_j − θ_i + u_d·ā) = 0 with the
    mean age ā. Paper graph, TDMA 3 × 0.5 s, one period of latency, no loss:
    ages cycle 0.5, 1.0, 1.5 s, ā = 1 s. Vessel 0 (hears 1) lags by u_d·ā = 5 m,
    vessel 2 (hears 0 and 1) settles at the mean of theirs minus u_d·ā: 7.5 m
    behind vessel 1. The spread therefore hovers around 7.5 m.
    """
    cfg = make_config("radio", channel={"loss": 0.0})
    states, _, times, _ = _run_with_reference(cfg, steps=800)
    theta = states[:, 0, :, 0] - cfg.formation[:, 0]
    late = times[:, 0] >= 200.0
    lag0 = np.mean(theta[late, 1] - theta[late, 0])
    lag2 = np.mean(theta[late, 1] - theta[late, 2])
    assert lag0 == pytest.approx(5.0, rel=0.1)
    assert lag2 == pytest.approx(7.5, rel=0.1)


# --------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("channel", "match"),
    [
        ({"loss": -0.1}, r"channel.loss .*\[0, 1\], got -0.1"),
        ({"loss": 1.5}, r"channel.loss .*got 1.5"),
        ({"loss": float("nan")}, r"channel.loss .*got nan"),
        ({"loss": [[0, 0], [0, 0]]}, r"channel.loss .*shape \(3, 3\)"),
        ({"latency": -1.0}, r"channel.latency must be a finite number ≥ 0, got -1.0"),
        ({"jitter": -0.5}, r"channel.jitter .*got -0.5"),
        ({"latency": float("inf")}, r"channel.latency .*got inf"),
        ({"period": 0.0}, r"channel.period .*> 0, got 0.0"),
        ({"period": 0.7}, r"channel.period = 0.7 s must be a whole number of control periods dt = 0.5"),
        ({"tdma_slot": 0.25}, r"channel.tdma_slot = 0.25 s"),
        ({"tdma_slot": 1.0, "period": 2.0}, r"either channel.period"),
        ({"range": 0.0}, r"channel.range .*got 0.0"),
        ({"range": -5}, r"channel.range .*got -5"),
        ({"failure_rate": -1.0}, r"channel.failure_rate .*got -1.0"),
        ({"burst": {"p_good_to_bad": 1.2}}, r"channel.burst.p_good_to_bad .*got 1.2"),
        ({"burst": {"p_good_to_bad": 0.0, "p_bad_to_good": 0.0}}, r"p_good_to_bad \+ p_bad_to_good > 0"),
        ({"burst": {"p_gb": 0.1}}, r"unknown channel.burst key\(s\) \['p_gb'\]"),
        ({"burst": {"p_good_to_bad": 0.1}, "loss": 0.2}, r"either channel.loss"),
        ({"latncy": 1.0}, r"unknown channel key\(s\) \['latncy'\]"),
    ],
)
def test_malformed_channel_settings_raise_clear_errors(channel, match):
    with pytest.raises(ConfigError, match=match):
        make_config("paper", channel=channel)


def test_malformed_channel_object_and_schedules():
    with pytest.raises(ConfigError, match="channel must be a ChannelConfig or a mapping"):
        make_config("paper", channel=0.3)
    with pytest.raises(ConfigError, match=r"channel.loss must be a probability in \[0, 1\], got 2"):
        ChannelConfig(loss=2)
    with pytest.raises(ConfigError, match=r"topology_schedule\[0\].dwell \[s\] must be a finite number > 0"):
        make_config("paper", topology_schedule=[(0.0, "paper")])
    with pytest.raises(ConfigError, match=r"topology_schedule\[1\]: unknown"):
        make_config("paper", topology_schedule=[(5.0, "paper"), (5.0, "spiral")])
    with pytest.raises(ConfigError, match=r"topology_schedule\[0\] must be a \(dwell_seconds, graph\) pair"):
        make_config("paper", topology_schedule=["paper"])
    with pytest.raises(ConfigError, match="either topology"):
        make_config("paper", topology="ring", topology_schedule=[(5.0, "paper")])
    # jointly reachable is enough, but the union must have a globally reachable node
    lone = CommGraph.from_links(3, [(0, 1)])
    with pytest.raises(ConfigError, match="globally reachable"):
        make_config("paper", topology_schedule=[(5.0, lone), (5.0, lone)])


def test_presets_are_scenarios_with_their_documented_numbers():
    acoustic, radio, current = (make_config(name) for name in ("acoustic", "radio", "current"))
    assert acoustic.channel.tdma_slot == 4.0 and acoustic.channel.latency == 1.0 and acoustic.channel.jitter == 1.0
    assert acoustic.channel.burst.mean_loss == pytest.approx(0.2, abs=0.01)
    assert acoustic.channel.range == 2000.0
    assert radio.channel.loss == 0.05 and radio.channel.tdma_slot == 0.5 and radio.channel.latency == 0.05
    assert current.current.speed == 0.5 and current.current.direction == pytest.approx(math.pi / 2)
    for cfg in (acoustic, radio, current):
        assert cfg.graph.name == "paper" and np.array_equal(cfg.initial_state, make_config("paper").initial_state)
    # overrides merge into the preset's channel
    slower = make_config("acoustic", channel={"latency": 3.0})
    assert slower.channel.latency == 3.0 and slower.channel.tdma_slot == 4.0
    assert marine_formation_env.parallel_env(scenario="acoustic").config.channel == acoustic.channel


def test_gymnasium_checker_passes_on_the_acoustic_preset():
    import gymnasium
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("MarineFormation-v1", scenario="acoustic", horizon=30.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)


def test_vector_autoreset_restarts_the_channel():
    """After an autoreset nothing of the previous episode arrives: every held message is younger than the episode."""
    venv = MarineFormationVectorEnv(num_envs=2, scenario="acoustic", horizon=10.0, autoreset_mode="SameStep")
    venv.reset(seed=0)
    layout = ObservationLayout(3)
    resets = 0
    for _ in range(60):
        obs, _, terminated, truncated, _ = venv.step(np.zeros(venv.action_space.shape))
        resets += int(np.sum(terminated | truncated))
        _, slots = layout.split(obs.reshape(2, 3, -1))
        for b in range(2):
            elapsed = venv.core.time[b]
            linked = slots[b, ..., 0] == 1
            assert np.all(slots[b, ..., 3][linked] <= elapsed + 1e-6)
            if elapsed == 0.0:  # just reset: with 1-2 s latency nothing can have arrived yet
                assert not slots[b].any()
    assert resets >= 4
    empty = FormationCore(venv.config, 2)
    empty.reset(venv.config.initial_state, env_ids=np.array([], dtype=int))  # resetting no formation is fine


def test_latency_longer_than_the_episode_delivers_nothing_and_costs_no_memory():
    cfg = make_config("paper", horizon=20.0, channel={"latency": 1e6})
    _, obs, _, core = _run_core(cfg, 60)  # past the horizon too (the core keeps stepping)
    assert core.channel.depth == cfg.max_steps + 1
    assert not np.any(_slots(cfg, obs))


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
@pytest.mark.parametrize("scenario", ["acoustic", "radio", "current"])
def test_presets_pass_the_pettingzoo_api_test(scenario):
    env = marine_formation_env.parallel_env(scenario, horizon=60.0)
    parallel_api_test(env, num_cycles=150)


def test_no_message_is_seen_before_it_could_have_arrived():
    """Acoustic TDMA with a 20 s latency: every held message is at least 20 s old, and nothing arrives before 20 s."""
    env = marine_formation_env.parallel_env("acoustic", channel={"latency": 20.0})
    space = env.observation_space("vessel_0")
    obs, _ = env.reset(seed=1)
    seen = 0
    for _ in range(200):
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
        for o in obs.values():
            assert space.contains(o)
            linked, ages = o[10::4], o[13::4]
            assert np.all(ages[linked == 0] == 0)
            fresh = ages[linked == 1]
            assert np.all(fresh >= 20.0)
            seen += fresh.size
        if env.time < 20.0:
            assert all(not o[10::4].any() for o in obs.values())
    assert seen > 0


def test_next_arrival_is_the_first_instant_a_pending_message_arrives():
    """The (B,) shortcut the compiled channel reads instead of each formation's ring: at every instant it
    equals the earliest arrival among the messages on their way, recomputed here from the ring itself
    (a message in slot s arrives at the first step' > step with step' ≡ s mod depth), on both backends,
    with formations that restart at different instants."""
    from marine_formation_env.channel import NEVER

    cfg = make_config("paper", action_level="force", channel={"latency": 0.3, "jitter": 0.9, "loss": 0.2})
    b = 6
    core = FormationCore(cfg, b)
    core.seed_channel(list(range(b)))
    core.reset(np.broadcast_to(cfg.initial_state, (b, cfg.n_vessels, 6)).copy())
    ch, rng = core.channel, np.random.default_rng(3)
    checked = 0
    for k in range(60):
        restart = rng.random(b) < 0.1 if k % 7 == 3 else None
        initial = None if restart is None else np.broadcast_to(cfg.initial_state, (int(restart.sum()), 3, 6))
        core.step(rng.uniform(-0.3, 0.3, (b, cfg.n_vessels, cfg.action_dim)), restart, initial)
        for f in range(b):
            slots = np.flatnonzero(ch.pend_valid[f].any(axis=(1, 2)))
            step = int(core.steps[f])
            expected = min((step + (s - step) % ch.depth for s in slots), default=NEVER)
            assert ch.next_arrival[f] == expected, (k, f, slots, step)
            checked += expected != NEVER
    assert checked > 50  # messages were on their way most of the time
