"""``drop_inputs``: observation entries a TorchRL policy does not read (``training.inputs.InputMask``).

Truth: the entries' positions from the layout's definition (own part, then one
slot per other vessel), and the mask's one claim: an entry it drops cannot move
the policy's action, in torch or in the numpy export, while an entry it keeps
can. So at zero error every vessel commands the same, whoever it hears and
whatever its lane.
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines.pretrained import SLOT_WEIGHTS, MLPPolicy, load_pretrained
from marine_formation_env.rules import OWN_FEATURES, OWN_SIZE, SLOT_FEATURES, SLOT_SIZE

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from training.export import export_run  # noqa: E402
from training.inputs import InputMask, dropped_mask  # noqa: E402
from training.torchrl_networks import load_torch_policy  # noqa: E402
from training.torchrl_ppo import main as torchrl_main  # noqa: E402

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)

DROPPED = ["lane_offset", "linked", "age"]


def test_the_mask_zeroes_the_named_own_entry_and_the_named_entries_of_every_slot():
    mask = dropped_mask(OWN_SIZE + 3 * SLOT_SIZE, DROPPED)
    zeros = [OWN_FEATURES.index("lane_offset")] + [
        OWN_SIZE + k * SLOT_SIZE + SLOT_FEATURES.index(name) for k in range(3) for name in ("linked", "age")
    ]
    expected = np.ones(OWN_SIZE + 3 * SLOT_SIZE)
    expected[zeros] = 0.0
    np.testing.assert_array_equal(mask, expected)
    np.testing.assert_array_equal(dropped_mask(OWN_SIZE + SLOT_SIZE, []), np.ones(OWN_SIZE + SLOT_SIZE))
    with pytest.raises(ValueError, match=r"unknown observation entries \['speed'\]"):
        dropped_mask(OWN_SIZE + SLOT_SIZE, ["speed"])
    with pytest.raises(ValueError, match="an observation of size 12 is not 10 \\+ 4·slots"):
        dropped_mask(12, ["age"])


def test_an_mlp_policy_s_input_mask_is_checked_and_kept_in_its_file():
    dim = OWN_SIZE + SLOT_SIZE
    weights, biases = [np.eye(dim)[:, :2]], [np.zeros(2)]
    mask = dropped_mask(dim, DROPPED)
    policy = MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 2, input_mask=mask)
    np.testing.assert_array_equal(MLPPolicy.from_arrays(policy.arrays(), 2).input_mask, mask)
    plain = MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 2)
    assert "input_mask" not in plain.arrays() and MLPPolicy.from_arrays(plain.arrays(), 2).input_mask is None
    for bad in (np.ones(dim - 1), np.full(dim, 0.5)):
        with pytest.raises(ValueError, match=f"input_mask must be {dim} zeros and ones"):
            MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 2, input_mask=bad)
    features = {name: np.zeros((1, 1)) for name in SLOT_WEIGHTS}  # any slots network: it takes any size
    with pytest.raises(ValueError, match="input_mask applies to an MLP of one observation size, not to a slots"):
        MLPPolicy(weights, biases, np.zeros(dim), np.ones(dim), np.inf, "clip", 2, features, input_mask=mask)


@pytest.fixture(scope="module")
def dropped_run(tmp_path_factory):
    """A tiny force-level run of the paper's scenario that drops the lane offset, the link bits and the ages."""
    run = tmp_path_factory.mktemp("drop") / "run"
    argv = ["--seed", "3", "--out", str(run), "--no-progress", "--set", "env_kwargs.action_level=force"]
    for item in ["n_envs=4", "frames_per_batch=40", "total_frames=80", "minibatch_size=20", "n_epochs=1",
                 "eval_episodes=1", "hidden=[16, 16]", "normalize_observations=true", "distribution=normal",
                 "scale=state_independent", f"drop_inputs={DROPPED!r}"]:  # fmt: skip
        argv += ["--set", item]
    assert torchrl_main(argv) == 0
    return run


def _observations(rng: np.random.Generator) -> np.ndarray:
    """Observations of the paper's team (n = 3, two slots) with every entry drawn at random, ``(8, 18)``."""
    return rng.uniform(-20.0, 20.0, (8, OWN_SIZE + 2 * SLOT_SIZE)).astype(np.float32)


def test_a_dropped_entry_moves_neither_the_trained_policy_nor_its_export_and_a_kept_one_does(dropped_run, tmp_path):
    original, config = load_torch_policy(dropped_run)
    assert config["drop_inputs"] == DROPPED and isinstance(original.trunk[0], InputMask)
    export_run(dropped_run, "dropped", "smoke", tmp_path)
    exported, _ = load_pretrained("dropped", tmp_path)
    rng = np.random.default_rng(0)
    obs = _observations(rng)
    changed = obs.copy()
    changed[:, OWN_FEATURES.index("lane_offset")] = rng.choice([-100.0, 50.0, 450.0], len(obs))
    for k in range(2):
        changed[:, OWN_SIZE + k * SLOT_SIZE + SLOT_FEATURES.index("linked")] = rng.integers(0, 2, len(obs))
        changed[:, OWN_SIZE + k * SLOT_SIZE + SLOT_FEATURES.index("age")] = rng.uniform(0.0, 12.0, len(obs))
    kept = obs.copy()
    kept[:, OWN_FEATURES.index("cross_track_error")] += 15.0
    for policy in (original, exported):
        # the masked inputs are equal; float32 kernels may still round rows of a batch differently (1e-8 seen)
        np.testing.assert_allclose(policy.act_batch(changed), policy.act_batch(obs), rtol=0, atol=1e-6)
        assert not np.allclose(policy.act_batch(kept), policy.act_batch(obs))
    # float32 torch against the float64 export
    np.testing.assert_allclose(exported.act_batch(obs), original.act_batch(obs), atol=2e-6)


def test_at_zero_error_every_vessel_commands_the_same_whoever_it_hears(dropped_run):
    """The paper's team sailing in formation: every error 0, the lanes 50 m apart, vessel 1 hearing no one,
    vessel 0 hearing vessel 1, vessel 2 hearing both (links in slots 0 and 1 as the preset's graph has them)."""
    policy, _ = load_torch_policy(dropped_run)
    obs = np.zeros((3, OWN_SIZE + 2 * SLOT_SIZE), dtype=np.float32)
    obs[:, OWN_FEATURES.index("surge")] = obs[:, OWN_FEATURES.index("desired_speed")] = 5.0
    obs[:, OWN_FEATURES.index("lane_offset")] = [50.0, 0.0, -50.0]
    linked = OWN_SIZE + SLOT_FEATURES.index("linked")
    obs[0, linked] = 1.0
    obs[2, [linked, linked + SLOT_SIZE]] = 1.0
    actions = policy.act_batch(obs)
    # equal inputs after the mask; float32 kernels round the rows of a batch differently (7e-9 seen), while an
    # action that reads the link bits or the lanes differs by about 1e-2 (docs/results.md, paper_force)
    np.testing.assert_allclose(actions, np.broadcast_to(actions[1], actions.shape), rtol=0, atol=1e-6)
