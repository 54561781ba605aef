"""Residual policies (``baselines.residual``) and their training (``residual: true``).

Truth: the paper's controller itself and the gate's closed form. A residual
policy whose learned part outputs zero must act, step for step, as
``ReferencePolicy(extrapolate=True)`` on the same observations; in formation
(no cross-track error, no coordination error) it must be that controller
whatever the learned part says; far from formation the correction passes
(and ±2 saturates); the gate must be 1 − exp(−e² − Δθ²) of hand-set errors.
The controller part reading a padded observation (empty slots) must act as the
controller reading the team's own observation, since an empty slot carries no
link. The training env must apply the same rule, which an episode driven
directly by the reference's actions checks.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from baselines.engine import episode_reports
from baselines.pretrained import MLPPolicy, PretrainedInfo, load_pretrained, save_pretrained
from baselines.reference import ReferencePolicy
from baselines.residual import ResidualPolicy, correction_gate, residual_actions
from marine_formation_env import parallel_env
from marine_formation_env.rules import COORDINATION, CROSS_TRACK, DESIRED_SPEED, LINK, SURGE
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent  # each comparison runs one backend on both sides

REPO = Path(__file__).resolve().parents[1]


class _Constant:
    """A learned part that outputs ``value`` for every observation (any team)."""

    observation_dim = None
    action_dim = 1

    def __init__(self, value: float) -> None:
        self.value = value

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        return np.full((*np.shape(obs)[:-1], 1), self.value, dtype=np.float32)


def _stacked(observations: dict[str, np.ndarray]) -> np.ndarray:
    return np.stack(list(observations.values()))


def test_the_controller_part_reads_a_padded_observation_as_the_team_s_own():
    own_env = parallel_env("acoustic", action_level="speed")
    padded_env = parallel_env("acoustic", action_level="speed", observation_slots=7)
    own = ReferencePolicy(own_env, extrapolate=True)
    any_team = ReferencePolicy(padded_env, extrapolate=True, any_team=True)
    obs_own, _ = own_env.reset(seed=3)
    obs_padded, _ = padded_env.reset(seed=3)
    for _ in range(30):  # a few stale messages: the extrapolation is at work
        a_own, a_padded = own.act_batch(_stacked(obs_own)), any_team.act_batch(_stacked(obs_padded))
        # the same arithmetic plus empty slots that add exact zeros
        np.testing.assert_allclose(a_padded, a_own, rtol=0, atol=1e-12)
        # and the same controller reads the team's unpadded observation too
        np.testing.assert_allclose(any_team.act_batch(_stacked(obs_own)), a_own, rtol=0, atol=1e-12)
        actions = dict(zip(obs_own, a_own, strict=True))
        obs_own, *_ = own_env.step(actions)
        obs_padded, *_ = padded_env.step(actions)


def test_the_controller_part_refuses_an_observation_that_is_no_team_s():
    policy = ReferencePolicy(parallel_env("paper", action_level="speed"), any_team=True)
    with pytest.raises(ValueError, match=r"10 own entries and 4 per slot .*got shape \(2, 16\)"):
        policy.act_batch(np.zeros((2, 16)))
    with pytest.raises(TypeError, match="any_team must be True or False, got 1"):
        ReferencePolicy(parallel_env("paper"), any_team=1)


@pytest.mark.parametrize("scenario", ["paper", "acoustic"])
def test_a_residual_policy_at_zero_is_the_extrapolating_reference(scenario):
    config = make_config(scenario, action_level="speed")
    seeds = [11, 12]
    residual, _ = episode_reports(ResidualPolicy(_Constant(0.0), config), config, seeds)
    reference, _ = episode_reports(ReferencePolicy(config, extrapolate=True), config, seeds)
    for mine, theirs in zip(residual, reference, strict=True):
        assert mine["return"] == pytest.approx(theirs["return"], rel=1e-12)
        assert mine["success"] == theirs["success"]


def _hand_set(e: float, gaps: list[float], linked: list[float]) -> np.ndarray:
    """One observation of a vessel on the straight path at u = u_d = 5 m/s, heading along it, with cross-track
    error ``e`` and fresh slots (age 0, same speed) at coordination errors ``gaps`` and link bits ``linked``."""
    own = np.zeros(10)
    own[CROSS_TRACK], own[SURGE], own[DESIRED_SPEED] = e, 5.0, 5.0
    slots = np.zeros((len(gaps), 4))
    slots[:, LINK], slots[:, COORDINATION] = linked, gaps
    return np.concatenate([own, slots.ravel()])


def test_the_gate_is_its_closed_form_and_ignores_unlinked_slots():
    obs = np.stack(
        [
            _hand_set(0.0, [0.0, 0.0], [1, 1]),
            _hand_set(1.0, [0.0, 0.0], [1, 1]),
            _hand_set(0.5, [-2.0, 0.3], [1, 1]),
            _hand_set(0.0, [50.0, 0.0], [0, 1]),  # the unlinked slot's error is not the vessel's to know
        ]
    )
    own, slots = obs[:, :10], obs[:, 10:].reshape(len(obs), -1, 4)
    expected = [0.0, 1.0 - np.exp(-1.0), 1.0 - np.exp(-0.25 - 4.0), 0.0]
    np.testing.assert_allclose(correction_gate(own, slots), expected, rtol=1e-14, atol=0)


def test_in_formation_the_policy_is_the_controller_and_far_from_it_the_correction_passes():
    config = make_config("paper", action_level="speed")
    reference = ReferencePolicy(config, extrapolate=True)
    in_formation = _hand_set(0.0, [0.0, 0.0], [1, 1])[None]
    for value in (0.3, -2.0, 2.0):
        np.testing.assert_array_equal(
            ResidualPolicy(_Constant(value), config).act_batch(in_formation), reference.act_batch(in_formation)
        )
    far = _hand_set(30.0, [-20.0, 25.0], [1, 1])[None]  # γ = 1 − e^-1525: 1 in double precision
    base = reference.act_batch(far)
    assert np.all(np.abs(base) < 1.0)  # inside the speed band: the sum below is not clipped
    np.testing.assert_allclose(ResidualPolicy(_Constant(0.25), config).act_batch(far), base + 0.25, atol=1e-7)
    assert np.all(ResidualPolicy(_Constant(2.0), config).act_batch(far) == 1.0)
    assert np.all(ResidualPolicy(_Constant(-2.0), config).act_batch(far) == -1.0)
    assert residual_actions(reference, far, np.array([[0.1]])).dtype == np.float32


def test_a_pretrained_file_with_a_residual_header_loads_as_the_composite(tmp_path):
    zero = MLPPolicy([np.zeros((18, 4)), np.zeros((4, 1))], [np.zeros(4), np.zeros(1)], 0.0, 1.0, np.inf, "clip", 1)
    info = PretrainedInfo(
        name="zero_residual",
        scenario="radio",
        env_kwargs={"action_level": "speed"},
        action_level="speed",
        n_vessels=3,
        observation_dim=18,
        action_dim=1,
        residual=True,
    )
    save_pretrained(zero, info, tmp_path)
    policy, loaded = load_pretrained("zero_residual", tmp_path)
    assert loaded.residual and isinstance(policy, ResidualPolicy) and policy.info == loaded
    env = parallel_env("radio", action_level="speed")
    obs = _stacked(env.reset(seed=5)[0])
    np.testing.assert_array_equal(policy.act_batch(obs), ReferencePolicy(env, extrapolate=True).act_batch(obs))
    save_pretrained(zero, PretrainedInfo(**{**info.__dict__, "name": "plain", "residual": False}), tmp_path)
    assert isinstance(load_pretrained("plain", tmp_path)[0], MLPPolicy)


def test_the_residual_training_env_adds_the_reference_s_action():
    pytest.importorskip("stable_baselines3")
    from training.vec_env import ResidualVecEnv, SharedPolicyVecEnv

    config = make_config("acoustic", action_level="speed")
    residual = ResidualVecEnv(SharedPolicyVecEnv(2, "acoustic", action_level="speed"), config)
    direct = SharedPolicyVecEnv(2, "acoustic", action_level="speed")
    reference = ReferencePolicy(config, extrapolate=True)
    for venv in (residual, direct):
        venv.seed(7)
    obs_r, obs_d = residual.reset(), direct.reset()
    for _ in range(40):
        residual.step_async(np.zeros((residual.num_envs, 1), dtype=np.float32))
        direct.step_async(reference.act_batch(obs_d))
        (obs_r, rew_r, _, _), (obs_d, rew_d, _, _) = residual.step_wait(), direct.step_wait()
        np.testing.assert_array_equal(obs_r, obs_d)
        np.testing.assert_array_equal(rew_r, rew_d)
    with pytest.raises(RuntimeError, match="before reset"):
        ResidualVecEnv(SharedPolicyVecEnv(1, "paper", action_level="speed"), config).step_async(np.zeros((3, 1)))


def test_residual_in_a_training_config_is_checked():
    pytest.importorskip("stable_baselines3")
    from training.config import TrainConfigError, validate

    with pytest.raises(TrainConfigError, match="residual must be true or false, got 'yes'"):
        validate({"residual": "yes", "env_kwargs": {"action_level": "speed"}})
    with pytest.raises(TrainConfigError, match="reference sends no transmit entry"):
        validate({"residual": True, "scenario": "paper_budget", "env_kwargs": {"transmit": True}})


def test_a_residual_run_exports_and_loads_as_the_same_composite(tmp_path):
    pytest.importorskip("stable_baselines3")
    import torch

    from training import train as train_module
    from training.export import export_run
    from training.learned import load_learned_policy

    torch.set_num_threads(1)
    run = tmp_path / "run"
    sets = ["n_timesteps=600", "n_envs=2", "n_steps=64", "batch_size=128", "eval_freq=0", "eval_episodes=1",
            "checkpoint_freq=0", "env_kwargs.horizon=20.0", "residual=true"]  # fmt: skip
    argv = ["--config", str(REPO / "training" / "configs" / "paper_speed_ppo.yaml"), "--quiet", "--out", str(run)]
    for item in sets:
        argv += ["--set", item]
    assert train_module.main(argv) == 0
    original, config = load_learned_policy(run)
    assert config["residual"] is True and isinstance(original, ResidualPolicy)
    export_run(run, "residual_tiny", "smoke", tmp_path / "shipped")
    exported, info = load_pretrained("residual_tiny", tmp_path / "shipped")
    assert info.residual and isinstance(exported, ResidualPolicy)
    assert json.loads(info.to_json())["residual"] is True
    env = parallel_env("paper", action_level="speed")
    obs = np.concatenate([_stacked(env.reset(seed=s)[0]) for s in range(4)])
    # torch float32 against numpy float64 in the learned part; the controller part is the same numpy code
    np.testing.assert_allclose(exported.act_batch(obs), original.act_batch(obs), atol=2e-5)
