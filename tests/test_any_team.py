"""One policy for any team: the slot network, teams side by side in one SB3 VecEnv, its export.

Truth: what a set function over the heard slots must satisfy whatever its
weights (the same features under any order of the slots and any number of
empty slots), the torch extractor and its numpy copy computing the same
function, and each team's own ``SharedPolicyVecEnv`` stepped alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch
from gymnasium import spaces

from baselines.pretrained import (
    OWN_SCALE,
    SLOT_SCALE,
    MLPPolicy,
    load_pretrained,
    own_inputs,
    slot_features,
)
from marine_formation_env import parallel_env
from marine_formation_env.rules import (
    CURVATURE,
    CURVATURE_AHEAD,
    LANE_OFFSET,
    OWN_SIZE,
    SLOT_SIZE,
)
from training import train as train_module
from training.config import TrainConfigError, load_config, team_overrides, validate
from training.export import _sb3_slot_features, export_run
from training.learned import load_learned_policy
from training.slot_policy import SlotFeatures
from training.vec_env import SharedPolicyVecEnv, TeamsVecEnv

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

REPO = Path(__file__).resolve().parents[1]
ANY_N = REPO / "training" / "configs" / "any_n_speed_ppo.yaml"


def _observations(rng: np.random.Generator, batch: int, slots: int) -> np.ndarray:
    own = rng.normal(size=(batch, OWN_SIZE)) * np.array([20, 0.5, 5, 1, 0.1, 5, 0.1, 0.003, 0.003, 50])
    slot = rng.normal(size=(batch, slots, SLOT_SIZE)) * np.array([1, 30, 2, 5])
    slot[..., 0] = rng.random((batch, slots)) < 0.6  # link bits
    slot[slot[..., 0] == 0] = 0.0  # a slot not heard is all zeros, as the env gives it
    return np.concatenate([own, slot.reshape(batch, -1)], axis=1)


def _extractor(slots: int, seed: int = 0) -> SlotFeatures:
    torch.manual_seed(seed)
    box = spaces.Box(-np.inf, np.inf, (OWN_SIZE + SLOT_SIZE * slots,), np.float32)
    return SlotFeatures(box, hidden=16)


def _numpy_weights(extractor: SlotFeatures) -> dict[str, np.ndarray]:
    def pair(module):
        return module.weight.detach().double().numpy().T, module.bias.detach().double().numpy()

    out = {}
    out["message_w0"], out["message_b0"] = pair(extractor.message[0])
    out["message_w1"], out["message_b1"] = pair(extractor.message[2])
    out["own_w0"], out["own_b0"] = pair(extractor.own[0])
    return out


def test_the_numpy_slot_features_are_the_torch_extractor_s():
    extractor = _extractor(5)
    obs = _observations(np.random.default_rng(0), 64, 5)
    with torch.no_grad():
        theirs = extractor(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(slot_features(obs, _numpy_weights(extractor)), theirs, atol=2e-5)  # float32 rounding
    assert theirs.shape == (64, 48)


def test_with_transmit_entries_the_own_layer_reads_them_and_the_messages_do_not():
    torch.manual_seed(4)
    box = spaces.Box(-np.inf, np.inf, (OWN_SIZE + SLOT_SIZE * 2 + 3,), np.float32)
    extractor = SlotFeatures(box, hidden=16)
    weights = _numpy_weights(extractor)
    assert weights["own_w0"].shape == (OWN_SIZE + 3, 16)
    rng = np.random.default_rng(4)
    plain = _observations(rng, 32, 2)
    traffic = np.column_stack([rng.random(32), 40.0 * rng.random(32), 10.0 * rng.random(32)])  # share, s, m
    obs = np.concatenate([plain, traffic], axis=1)
    features = slot_features(obs, weights)
    # ψ by hand: one tanh layer over the own inputs and the traffic entries at their scales (share as it is,
    # seconds by 10, metres as they are)
    own_in = np.concatenate([own_inputs(plain[:, :OWN_SIZE]), traffic / [1.0, 10.0, 1.0]], axis=1)
    np.testing.assert_allclose(features[:, :16], np.tanh(own_in @ weights["own_w0"] + weights["own_b0"]), atol=1e-12)
    no_traffic = {**weights, "own_w0": weights["own_w0"][:OWN_SIZE]}
    np.testing.assert_allclose(features[:, 16:], slot_features(plain, no_traffic)[:, 16:], atol=1e-12)
    with torch.no_grad():
        theirs = extractor(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(theirs, features, atol=2e-5)  # float32 rounding
    with pytest.raises(ValueError, match="reads 13 own inputs, this observation of size 18 has 10 \\+ 0"):
        slot_features(plain, weights)


def _agreeing(rng: np.random.Generator, batch: int, slots: int) -> tuple[np.ndarray, np.ndarray]:
    """Observations whose heard neighbours all agree (Δθ predicted to now = 0, Δẋ = 0), and the same own parts
    hearing no one. The own part has ψ = v = κ = 0, so ẋ_i = u and a message of age τ agrees at Δθ = u·τ."""
    obs = _observations(rng, batch, slots)
    own = obs[:, :OWN_SIZE]
    own[:, [1, 3, CURVATURE, CURVATURE_AHEAD]] = 0.0
    slot = obs[:, OWN_SIZE:].reshape(batch, slots, SLOT_SIZE)
    slot[..., 3] = np.abs(slot[..., 3]) * slot[..., 0]  # ages ≥ 0 where heard
    slot[..., 2] = 0.0
    slot[..., 1] = own[:, None, 2] * slot[..., 3]  # u·τ: 0 over an ideal link (τ = 0)
    slot[:, 0, :] = [1.0, 0.0, 0.0, 0.0]  # at least one heard, over an ideal link
    alone = np.concatenate([own, np.zeros((batch, slots * SLOT_SIZE))], axis=1)
    return np.concatenate([own, slot.reshape(batch, -1)], axis=1), alone


def test_zero_at_agreement_makes_neighbours_that_agree_read_as_no_neighbours_in_torch_and_numpy():
    torch.manual_seed(3)
    box = spaces.Box(-np.inf, np.inf, (OWN_SIZE + SLOT_SIZE * 5,), np.float32)
    extractor = SlotFeatures(box, hidden=16, zero_at_agreement=True)
    weights = _sb3_slot_features(type("Net", (), {"features_extractor": extractor})())
    assert float(weights["zero_at_agreement"]) == 1.0
    agreeing, alone = _agreeing(np.random.default_rng(3), 32, 5)
    # what the paper's law (20) does: a sum over in-neighbours of terms that vanish at agreement, so a follower
    # whose leader agrees commands what the leader, hearing no one, commands (no steady offset per link)
    features = slot_features(agreeing, weights)
    np.testing.assert_allclose(features, slot_features(alone, weights), atol=1e-12)
    np.testing.assert_allclose(features[:, 16:], 0.0, atol=1e-12)  # the sum and the mean of the messages
    with torch.no_grad():
        theirs = extractor(torch.as_tensor(agreeing, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(theirs, features, atol=2e-5)  # float32 rounding
    # a neighbour that does not agree still counts, in torch and numpy alike
    disagreeing = agreeing.copy()
    disagreeing[:, OWN_SIZE + 1] = 3.0  # the first slot's Δθ: 3 m
    away = slot_features(disagreeing, weights)
    assert (np.abs(away[:, 16:] - features[:, 16:]).max(axis=1) > 1e-3).all()
    with torch.no_grad():
        theirs = extractor(torch.as_tensor(disagreeing, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(theirs, away, atol=2e-5)
    # without the option (the default), agreeing neighbours shift the features: the offset the option removes
    plain = _numpy_weights(_extractor(5, seed=3))
    assert np.abs(slot_features(agreeing, plain) - slot_features(alone, plain)).max() > 1e-3
    for bad in (1, "yes", None, 0.0):
        with pytest.raises(ValueError, match=f"zero_at_agreement must be True or False, got {bad!r}"):
            SlotFeatures(box, zero_at_agreement=bad)


def test_with_every_option_each_message_is_phi_of_the_slot_minus_phi_of_an_agreeing_slot_by_hand():
    """The messages written out from the definitions (module docstring), on aged links with Δẋ ≠ 0."""
    torch.manual_seed(5)
    box = spaces.Box(-np.inf, np.inf, (OWN_SIZE + SLOT_SIZE * 4,), np.float32)
    extractor = SlotFeatures(box, hidden=8, zero_at_agreement=True)
    weights = _sb3_slot_features(type("Net", (), {"features_extractor": extractor})())
    rng = np.random.default_rng(5)
    obs = _observations(rng, 16, 4)
    obs[:, OWN_SIZE + 3 :: SLOT_SIZE] = np.abs(obs[:, OWN_SIZE + 3 :: SLOT_SIZE])  # ages ≥ 0
    own, slot = obs[:, :OWN_SIZE], obs[:, OWN_SIZE:].reshape(16, 4, SLOT_SIZE)
    e, psi, u, v, kappa, lane = own[:, 0], own[:, 1], own[:, 2], own[:, 3], own[:, CURVATURE], own[:, LANE_OFFSET]
    x_dot = (u * np.cos(psi) - v * np.sin(psi)) / (1.0 - kappa * (lane + e))
    gap = slot[..., 1] - (x_dot[:, None] - slot[..., 2]) * slot[..., 3]  # Δθ predicted to now [m]
    own_in = np.column_stack([*own[:, :LANE_OFFSET].T, kappa * lane]) / OWN_SCALE
    link, vel, age = slot[..., 0], slot[..., 2] / SLOT_SCALE[2], slot[..., 3] / SLOT_SCALE[3]

    def phi(*columns):
        x = np.concatenate([np.repeat(own_in[:, None, :], 4, axis=1), np.stack(columns, axis=-1)], axis=-1)
        h = np.tanh(x @ weights["message_w0"] + weights["message_b0"])
        return np.tanh(h @ weights["message_w1"] + weights["message_b1"])

    zero = np.zeros_like(gap)
    m = (phi(link, gap / SLOT_SCALE[1], vel, age) - phi(link, zero, zero, age)) * link[..., None]
    heard = np.maximum(link.sum(axis=1), 1.0)[:, None]
    features = slot_features(obs, weights)
    np.testing.assert_allclose(features[:, 8:16], m.sum(axis=1), atol=1e-12)
    np.testing.assert_allclose(features[:, 16:], m.sum(axis=1) / heard, atol=1e-12)
    with torch.no_grad():
        theirs = extractor(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(theirs, features, atol=5e-5)  # float32 rounding
    # a pretrained file carries every option, and bad option values in a file are refused by name
    dim = obs.shape[1]
    policy = MLPPolicy([np.ones((24, 1)) / 24], [np.zeros(1)], np.zeros(dim), np.ones(dim), np.inf, "clip", 1, weights)
    again = MLPPolicy.from_arrays(policy.arrays(), 1)
    np.testing.assert_array_equal(again.act_batch(obs), policy.act_batch(obs))
    assert sorted(again.features) == sorted(weights)
    for name, value, message in (
        ("zero_at_agreement", np.array(0.0), "zero_at_agreement must be 1 if present"),
        ("speed_error_scale", np.array(0.2), "unknown \\['speed_error_scale'\\]"),  # an option no longer read
        ("agreement", np.array(1.0), "unknown \\['agreement'\\]"),
    ):
        with pytest.raises(ValueError, match=message):
            MLPPolicy.from_arrays({**policy.arrays(), f"features_{name}": value}, 1)


def test_the_features_ignore_the_order_of_the_slots_and_empty_padding():
    weights = _numpy_weights(_extractor(5, seed=1))
    rng = np.random.default_rng(1)
    obs = _observations(rng, 32, 5)
    features = slot_features(obs, weights)
    own, slots = obs[:, :OWN_SIZE], obs[:, OWN_SIZE:].reshape(32, 5, SLOT_SIZE)
    shuffled = np.concatenate([own, slots[:, rng.permutation(5)].reshape(32, -1)], axis=1)
    padded = np.concatenate([obs, np.zeros((32, 7 * SLOT_SIZE))], axis=1)
    np.testing.assert_allclose(slot_features(shuffled, weights), features, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(slot_features(padded, weights), features, rtol=1e-12, atol=1e-12)
    # a slot's content matters only when it is heard: change what an unheard slot holds, nothing changes
    silent = slots.copy()
    silent[..., 0] = 0.0
    alone = np.concatenate([own, silent.reshape(32, -1)], axis=1)
    nothing = np.concatenate([own, np.zeros((32, 5 * SLOT_SIZE))], axis=1)
    np.testing.assert_allclose(slot_features(alone, weights), slot_features(nothing, weights), atol=1e-12)
    with pytest.raises(ValueError, match="an observation of size 12 is not 10 \\+ 4·slots"):
        slot_features(obs[:, :12], weights)


def test_the_lane_offset_counts_only_through_the_path_s_curvature():
    # a team of 20 on the paper's straight path: lane offsets up to hundreds of metres, which no team of 3 to 6
    # shows; the features must not see them (κ = 0), while on a bend (κ ≠ 0) the offset still matters
    weights = _numpy_weights(_extractor(5, seed=2))
    obs, _ = parallel_env("paper", n_vessels=20, topology="chain", init_noise={"x": 40.0}).reset(seed=4)
    stacked = np.stack(list(obs.values()))
    assert np.ptp(stacked[:, LANE_OFFSET]) > 800.0 and np.all(stacked[:, CURVATURE] == 0.0)
    centred = stacked.copy()
    centred[:, LANE_OFFSET] = 0.0
    np.testing.assert_array_equal(slot_features(centred, weights), slot_features(stacked, weights))
    bend = _observations(np.random.default_rng(3), 8, 5)
    bend[:, CURVATURE] = 1.0 / 300.0
    inner, outer = bend.copy(), bend.copy()
    inner[:, LANE_OFFSET], outer[:, LANE_OFFSET] = -25.0, 25.0
    assert np.abs(slot_features(inner, weights) - slot_features(outer, weights)).max() > 1e-3


def test_a_stale_message_reads_as_the_fresh_one_at_constant_speeds():
    # vessel j at 5.2 m/s hears i (4.6 m/s) 3 s late: the slot holds θ_j(now) − θ_i(now − 3 s) = gap + 4.6·3.
    # The network predicts i's position now, so with its weights on the age entry itself set to 0 it must act
    # as on what an ideal link gives (gap, age 0); read as current, the stale Δθ is another input
    weights = _numpy_weights(_extractor(2, seed=4))
    weights["message_w0"][OWN_SIZE + 3] = 0.0  # the age input's row
    u_j, u_i, age, gap = 5.2, 4.6, 3.0, 12.0
    own = [0.0, 0.0, u_j, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 25.0]
    stale = np.array([*own, 1.0, gap + u_i * age, u_j - u_i, age, 0.0, 0.0, 0.0, 0.0])
    fresh = np.array([*own, 1.0, gap, u_j - u_i, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(slot_features(stale, weights), slot_features(fresh, weights), atol=1e-12)
    read_as_current = stale.copy()
    read_as_current[OWN_SIZE + 3] = 0.0
    assert np.abs(slot_features(read_as_current, weights) - slot_features(fresh, weights)).max() > 1e-3


def test_teams_side_by_side_step_as_each_team_alone():
    kwargs = [
        {"n_vessels": 3, "topology": "ring", "observation_slots": 4, "horizon": 5.0, "init_noise": {"x": 10.0}},
        {"n_vessels": 5, "topology": "random", "observation_slots": 4, "horizon": 6.0, "init_noise": {"x": 10.0}},
    ]
    together = TeamsVecEnv([SharedPolicyVecEnv(2, "paper", **kw) for kw in kwargs])
    alone = [SharedPolicyVecEnv(2, "paper", **kw) for kw in kwargs]
    assert together.num_envs == 6 + 10
    seeds = together.seed(7)  # formation b of team k starts from 7 + 100 000·k + b
    assert seeds == [7] * 3 + [8] * 3 + [100_007] * 5 + [100_008] * 5
    alone[0].seed(7)
    alone[1].seed(7 + TeamsVecEnv.SEED_STRIDE)
    obs = together.reset()
    np.testing.assert_array_equal(obs, np.concatenate([env.reset() for env in alone]))
    rng = np.random.default_rng(0)
    for _ in range(14):  # through both teams' episode ends (10 and 12 steps)
        actions = rng.uniform(-1, 1, (16, 1)).astype(np.float32)
        obs, reward, done, infos = together.step(actions)
        parts = [alone[0].step(actions[:6]), alone[1].step(actions[6:])]
        np.testing.assert_array_equal(obs, np.concatenate([p[0] for p in parts]))
        np.testing.assert_array_equal(reward, np.concatenate([p[1] for p in parts]))
        np.testing.assert_array_equal(done, np.concatenate([p[2] for p in parts]))
        assert [sorted(i) for i in infos] == [sorted(i) for p in parts for i in p[3]]
    # the space holds every team's (their bounds differ with the workspace)
    for env in alone:
        assert np.all(together.observation_space.low <= env.observation_space.low)
        assert np.all(together.observation_space.high >= env.observation_space.high)
    with pytest.raises(ValueError, match="pad with observation_slots"):
        TeamsVecEnv(
            [
                SharedPolicyVecEnv(1, "paper", topology="ring"),
                SharedPolicyVecEnv(1, "paper", n_vessels=4, topology="ring"),
            ]
        )


def test_the_any_team_config_pads_every_team_to_the_largest():
    resolved = validate(load_config(ANY_N))
    teams = team_overrides(resolved)
    assert {scenario for scenario, _ in teams} == {"paper"}  # no team names a preset: the config's
    assert sorted({kw["n_vessels"] for _, kw in teams}) == [3, 4, 5, 6]
    assert {kw["observation_slots"] for _, kw in teams} == {5}
    with pytest.raises(TrainConfigError, match="teams must be a list of mappings"):
        validate({**load_config(ANY_N), "teams": "all of them"})
    with pytest.raises(TrainConfigError, match=r"teams\[1\]: .*n_vessels must be an integer ≥ 2, got 1"):
        validate({**load_config(ANY_N), "teams": [{"n_vessels": 3}, {"n_vessels": 1}]})
    # the scenario of evaluations and exports gets the teams' length: an SB3 model trained on the teams can act in it
    speed = load_config(REPO / "training" / "configs" / "paper_speed_ppo.yaml")
    mixed = validate({**speed, "teams": [{"n_vessels": 3}, {"n_vessels": 4, "topology": "ring"}]})
    assert mixed["env_kwargs"]["observation_slots"] == 3
    assert [kw["observation_slots"] for _, kw in team_overrides(mixed)] == [3, 3]
    with pytest.raises(TrainConfigError, match=r"teams\[1\] has observation_slots = 7 .* env_kwargs .* 3"):
        validate({**speed, "teams": [{"n_vessels": 3}, {"n_vessels": 4, "topology": "ring", "observation_slots": 7}]})
    with pytest.raises(TrainConfigError, match="'slots' reads the link bits of raw observations"):
        validate({**speed, "policy_kwargs": {"features_extractor_class": "slots"}})  # normalize: true
    with pytest.raises(TrainConfigError, match="features_extractor_class must be one of \\['slots'\\], got 'gnn'"):
        validate({**load_config(ANY_N), "policy_kwargs": {"features_extractor_class": "gnn"}})


def test_a_team_that_names_a_preset_trains_on_that_preset_with_its_overrides():
    speed = load_config(REPO / "training" / "configs" / "paper_speed_ppo.yaml")
    teams = [{"n_vessels": 3}, {"scenario": "acoustic", "n_vessels": 4, "topology": "ring"}]
    resolved = validate({**speed, "n_envs": 1, "normalize": False, "teams": teams})
    (first, _), (second, acoustic) = team_overrides(resolved)
    assert (first, second) == ("paper", "acoustic") and "scenario" not in acoustic
    venv = train_module.build_env(resolved, seed=0)
    built = [team.config for team in venv.teams]
    venv.close()
    preset = parallel_env("acoustic").config.channel
    assert built[0].channel.is_ideal  # the config's scenario: ideal links
    # the acoustic preset's link (its TDMA slot and bursts), with the team's own size and graph and env_kwargs' level
    assert built[1].channel == preset and built[1].n_vessels == 4 and built[1].action_level == "speed"
    assert built[1].topology.name == "ring"
    with pytest.raises(TrainConfigError, match=r"teams\[1\]: unknown scenario 'lake'; known scenarios: \["):
        validate({**speed, "teams": [{"n_vessels": 3}, {"scenario": "lake"}]})


def test_a_policy_trained_on_small_teams_exports_and_acts_in_a_team_of_20(tmp_path, monkeypatch):
    torch.set_num_threads(1)
    run = tmp_path / "run"
    argv = ["--config", str(ANY_N), "--seed", "0", "--quiet", "--out", str(run)]
    for item in ["n_timesteps=2000", "n_envs=1", "env_kwargs.horizon=20.0", "batch_size=576", "checkpoint_freq=0"]:
        argv += ["--set", item]
    assert train_module.main(argv) == 0
    export_run(run, "any_team", "smoke", tmp_path / "shipped")
    portable, info = load_pretrained("any_team", tmp_path / "shipped")
    assert info.kind == "slots" and info.n_vessels is None and info.observation_dim is None
    trained, _ = load_learned_policy(run)
    env = parallel_env("paper", n_vessels=6, topology="random", observation_slots=5, init_noise={"x": 40.0})
    obs, _ = env.reset(seed=1)
    stacked = np.stack(list(obs.values()))
    np.testing.assert_allclose(portable.act_batch(stacked), trained.act_batch(stacked), atol=2e-5)
    big = parallel_env("paper", n_vessels=20, topology="ring", init_noise={"x": 40.0})
    obs, _ = big.reset(seed=1)
    stacked = np.stack(list(obs.values()))
    assert stacked.shape == (20, OWN_SIZE + 19 * SLOT_SIZE)
    actions = portable.act_batch(stacked)
    assert actions.shape == (20, 1) and np.all(np.abs(actions) <= 1.0)
    # the run folder's SB3 model acts in the team of 20 too (through the network, not SB3's shape-checked predict)
    np.testing.assert_allclose(trained.act_batch(stacked), actions, atol=2e-5)
    # from the command line, on another team size: the header's padding is not carried over
    import baselines.pretrained as pretrained
    from baselines import evaluate as evaluate_module

    monkeypatch.setattr(pretrained, "PRETRAINED_DIR", tmp_path / "shipped")
    args = ["--policy", "pretrained:any_team", "--policy", "reference", "--set", "n_vessels=12", "--set",
            "topology=chain", "--set", "horizon=10.0", "--quiet", "--json", str(tmp_path / "twelve.json")]  # fmt: skip
    assert evaluate_module.main(args) == 0
    assert '"n_vessels": 12' in (tmp_path / "twelve.json").read_text()
    args[1] = str(run / "model.zip")  # the run folder's model, on the team of 12 as well
    assert evaluate_module.main([*args[:-1], str(tmp_path / "twelve_run.json")]) == 0
    exported, direct = (json.loads((tmp_path / name).read_text()) for name in ("twelve.json", "twelve_run.json"))
    assert direct["config"]["n_vessels"] == 12 and str(run / "model.zip") in direct["policies"]
    # the same network in torch and in numpy: actions agree to float32 rounding (above), so over 10 s do the returns
    returns = [
        [episode["return"] for episode in report["policies"][label]["episodes"]]
        for report, label in ((exported, "pretrained:any_team"), (direct, str(run / "model.zip")))
    ]
    np.testing.assert_allclose(returns[1], returns[0], rtol=1e-4)
    # the same observations padded to 30 slots act the same: the network reads the heard slots only
    padded = np.concatenate([stacked, np.zeros((20, 11 * SLOT_SIZE))], axis=1)
    np.testing.assert_allclose(portable.act_batch(padded), actions, atol=1e-6)


def test_train_reward_shapes_every_team_s_training_env_and_nothing_else():
    # every weight 0 and no terminal penalty: each team's training reward is exactly 0 at every step, whatever the
    # policy does, while env_kwargs (the scenario of evaluations and exports) keeps the benchmark's reward
    zero = {"cross_track": 0.0, "heading": 0.0, "coordination": 0.0, "speed": 0.0, "terminal_penalty": False}
    resolved = validate({**load_config(ANY_N), "n_envs": 1, "normalize": False, "train_reward": zero})
    assert "reward" not in resolved["env_kwargs"]
    venv = train_module.build_env(resolved, seed=3)
    venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(5):
        _, rewards, _, _ = venv.step(rng.uniform(-1, 1, (venv.num_envs, 1)).astype(np.float32))
        assert rewards.shape == (sum(kw["n_vessels"] for _, kw in team_overrides(resolved)),)
        assert np.all(rewards == 0.0)
    venv.close()
    unshaped = train_module.build_env({**resolved, "train_reward": {}}, seed=3)
    unshaped.reset()
    _, rewards, _, _ = unshaped.step(np.zeros((unshaped.num_envs, 1), np.float32))
    assert np.all(rewards < 0.0)  # the benchmark's bounded costs are > 0 off the lanes
    unshaped.close()
    with pytest.raises(TrainConfigError, match="train_reward must be a mapping of reward fields, got 5"):
        validate({**load_config(ANY_N), "train_reward": 5})
    with pytest.raises(TrainConfigError, match="sigma_coordination must be a finite number > 0, got 0"):
        validate({**load_config(ANY_N), "train_reward": {"sigma_coordination": 0}})
