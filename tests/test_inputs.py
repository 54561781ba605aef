"""The slot network's fixed input map, as an MLP's inputs (``training.torchrl_ppo``'s ``inputs: predicted``).

Truth: a neighbour's along-path position moved on by its speed times the
message's age (hand-computed), the map reducing to a rescaling over an ideal
link (age 0), the torch module and its numpy twin computing the same
function, and an exported run acting as the TorchRL policy it came from.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from baselines.pretrained import OWN_SCALE, SLOT_SCALE, MLPPolicy, load_pretrained, predicted_inputs
from marine_formation_env import parallel_env
from marine_formation_env.rules import CURVATURE, LANE_OFFSET, OWN_SIZE, SLOT_SIZE

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)


def _own(e=0.0, psi=0.0, u=5.0, v=0.0, kappa=0.0, d_y=0.0) -> np.ndarray:
    own = np.zeros(OWN_SIZE)
    own[[0, 1, 2, 3]] = e, psi, u, v
    own[CURVATURE], own[LANE_OFFSET] = kappa, d_y
    return own


def test_a_stale_slot_is_moved_on_by_the_neighbour_s_speed_times_its_age():
    # own along-path rate 5 m/s; the neighbour was 10 m ahead of its place in the formation (Δθ = θ_j − θ_i = −10)
    # and 1 m/s slower (Δẋ = ẋ_j − ẋ_i = 1) 2.5 s ago: it has since sailed 4 m/s · 2.5 s = 10 m, so Δθ now is −20
    obs = np.concatenate([_own(), [1.0, -10.0, 1.0, 2.5]])
    out = predicted_inputs(obs)
    assert out.shape == obs.shape
    np.testing.assert_allclose(out[OWN_SIZE:], np.array([1.0, -20.0, 1.0, 2.5]) / SLOT_SCALE, rtol=1e-12)
    # heading 60° off the path: the own along-path rate is u·cos ψ = 2.5 m/s, so the neighbour's is 1.5 m/s
    obs = np.concatenate([_own(psi=np.pi / 3), [1.0, -10.0, 1.0, 2.0]])
    assert predicted_inputs(obs)[OWN_SIZE + 1] * SLOT_SCALE[1] == pytest.approx(-10.0 - 1.5 * 2.0, rel=1e-12)


def test_over_an_ideal_link_the_map_only_rescales_and_reads_the_lane_offset_through_the_curvature():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(5, OWN_SIZE + 3 * SLOT_SIZE)) * 10.0
    obs[:, OWN_SIZE + 3 :: SLOT_SIZE] = 0.0  # every age 0
    expected = obs.copy()
    expected[:, LANE_OFFSET] = obs[:, CURVATURE] * obs[:, LANE_OFFSET]
    expected /= np.concatenate([OWN_SCALE, np.tile(SLOT_SCALE, 3)])
    np.testing.assert_allclose(predicted_inputs(obs), expected, rtol=1e-12)


def test_a_size_that_is_not_own_plus_slots_is_refused_by_both_twins():
    with pytest.raises(ValueError, match="an observation of size 12 is not 10 \\+ 4·slots"):
        predicted_inputs(np.zeros(12))
    torch = pytest.importorskip("torch")
    from training.inputs import PredictedInputs

    with pytest.raises(ValueError, match="an observation of size 12 is not 10 \\+ 4·slots"):
        PredictedInputs()(torch.zeros(2, 12))


def test_the_torch_module_is_the_numpy_map():
    torch = pytest.importorskip("torch")
    from training.inputs import PredictedInputs

    obs = _acoustic_observations()
    assert np.any(obs[..., OWN_SIZE + 3 :: SLOT_SIZE] > 0)  # stale messages, so the prediction matters
    theirs = PredictedInputs()(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    # float32 against float64 on inputs of tens of metres: agree to float32 rounding
    np.testing.assert_allclose(theirs, predicted_inputs(obs), rtol=1e-5, atol=1e-6)


def test_a_policy_file_keeps_what_its_network_reads():
    rng = np.random.default_rng(1)
    dim = OWN_SIZE + 2 * SLOT_SIZE
    weights, biases = [rng.normal(size=(dim, 8)), rng.normal(size=(8, 1))], [rng.normal(size=8), rng.normal(size=1)]
    policy = MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 1, inputs="predicted")
    again = MLPPolicy.from_arrays(policy.arrays(), 1)
    obs = _acoustic_observations()
    assert again.inputs == "predicted"
    np.testing.assert_array_equal(again.act_batch(obs), policy.act_batch(obs))
    raw = MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 1)
    assert "inputs" not in raw.arrays() and MLPPolicy.from_arrays(raw.arrays(), 1).inputs == "raw"
    assert not np.allclose(raw.act_batch(obs), policy.act_batch(obs))
    with pytest.raises(ValueError, match="inputs must be one of \\['raw', 'predicted'\\], got 'scaled'"):
        MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 1, inputs="scaled")


def test_an_exported_run_with_predicted_inputs_acts_as_its_torchrl_policy(tmp_path):
    pytest.importorskip("torchrl")
    from training.export import export_run
    from training.inputs import PredictedInputs
    from training.torchrl_networks import load_torch_policy
    from training.torchrl_ppo import main as torchrl_main

    run = tmp_path / "run"
    argv = ["--out", str(run), "--no-progress", "--set", "scenario=acoustic", "--set", "inputs=predicted"]
    for item in ["n_envs=4", "frames_per_batch=40", "total_frames=80", "minibatch_size=20", "n_epochs=1",
                 "eval_episodes=1", "hidden=[16, 16]", "env_kwargs.horizon=4.0", "env_kwargs.action_level=speed",
                 "distribution=normal"]:  # fmt: skip
        argv += ["--set", item]
    assert torchrl_main(argv) == 0
    original, config = load_torch_policy(run)
    assert config["inputs"] == "predicted" and isinstance(original.trunk[0], PredictedInputs)
    assert json.loads((run / "evaluation.json").read_text())["learned_return"] < 0
    export_run(run, "torchrl_predicted", "smoke", tmp_path / "shipped")
    exported, _ = load_pretrained("torchrl_predicted", tmp_path / "shipped")
    assert exported.inputs == "predicted"
    obs = _acoustic_observations()
    np.testing.assert_allclose(exported.act_batch(obs), original.act_batch(obs), atol=2e-5)  # float32 rounding


def test_inputs_predicted_and_the_running_norm_are_refused_together(tmp_path, capsys):
    pytest.importorskip("torchrl")
    from training.torchrl_ppo import main as torchrl_main

    with pytest.raises(SystemExit) as stop:
        torchrl_main(
            ["--out", str(tmp_path / "x"), "--set", "inputs=predicted", "--set", "normalize_observations=true"]
        )
    assert stop.value.code == 2
    assert "inputs: predicted divides by fixed scales" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def _acoustic_observations() -> np.ndarray:
    """Every vessel's observation after 30 s of the ``acoustic`` preset (messages seconds old), ``(3·k, dim)``."""
    env = parallel_env("acoustic", action_level="speed")
    obs, _ = env.reset(seed=3)
    seen = []
    for step in range(60):
        obs, *_ = env.step({agent: np.zeros(1, np.float32) for agent in env.agents})
        if step % 10 == 9:
            seen.append(np.stack(list(obs.values())))
    return np.concatenate(seen).astype(np.float64)


def test_with_transmit_the_budget_the_time_since_broadcast_and_the_drift_pass_through_at_their_scale():
    # budget left 25 %, 7 s since broadcast, the neighbours' prediction 0.3 m off
    obs = np.concatenate([_own(), [1.0, -10.0, 1.0, 2.5], [0.25, 7.0, 0.3]])
    out = predicted_inputs(obs)
    np.testing.assert_allclose(out[:-3], predicted_inputs(obs[:-3]), rtol=1e-12)
    np.testing.assert_allclose(out[-3:], [0.25, 0.7, 0.3], rtol=1e-12)  # TRAFFIC_SCALE: seconds by 10, else as is
    torch = pytest.importorskip("torch")
    from training.inputs import PredictedInputs

    theirs = PredictedInputs()(torch.as_tensor(obs[None], dtype=torch.float32)).numpy()[0]
    np.testing.assert_allclose(theirs, out, rtol=1e-5, atol=1e-6)
