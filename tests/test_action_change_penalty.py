"""The learner-side smoothness cost (training.vec_env.ActionChangePenalty) against hand-computed values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import VecMonitor

from training import train as train_module
from training.config import TrainConfigError, load_config, validate
from training.vec_env import ActionChangePenalty, SharedPolicyVecEnv, TeamsVecEnv

WEIGHT = 0.8
SPEED_CONFIG = Path(__file__).resolve().parents[1] / "training" / "configs" / "paper_speed_ppo.yaml"


def _chain(venv):
    """The VecEnv wrappers from the outermost in, then the innermost env."""
    out = [venv]
    while hasattr(out[-1], "venv") and not isinstance(out[-1], SharedPolicyVecEnv):
        out.append(out[-1].venv)
    return out


def _twins(**overrides):
    """The same two formations with and without the cost, seeded alike (their env rewards are equal step by step)."""
    plain = SharedPolicyVecEnv(2, "paper", action_level="guidance", **overrides)
    wrapped = ActionChangePenalty(SharedPolicyVecEnv(2, "paper", action_level="guidance", **overrides), WEIGHT, 0.5)
    for venv in (plain, wrapped):
        venv.seed(7)
        venv.reset()
    return plain, wrapped


def _step(venv, actions):
    venv.step_async(actions)
    return venv.step_wait()


def test_the_cost_is_dt_w_mean_absolute_change_of_the_clipped_action():
    plain, wrapped = _twins()
    n = plain.num_envs  # 2 formations × 3 vessels
    first = np.tile([0.2, -0.5], (n, 1))
    second = np.tile([-0.4, 3.0], (n, 1))  # 3.0 is applied as 1.0 (the env clips): changes 0.6 and 1.5
    third = second.copy()
    expected = [0.0, 0.5 * WEIGHT * (0.6 + 1.5) / 2, 0.0]  # nothing at an episode's first period; no change, no cost
    for actions, cost in zip((first, second, third), expected, strict=True):
        _, r_plain, d_plain, _ = _step(plain, actions)
        _, r_wrapped, d_wrapped, infos = _step(wrapped, actions)
        np.testing.assert_array_equal(d_plain, d_wrapped)
        # rewards are float32: the difference is the cost to float32 rounding of values of order 1
        np.testing.assert_allclose(r_plain - r_wrapped, cost, atol=1e-6)
        assert all(info["reward_action_change"] == pytest.approx(-cost, abs=1e-12) for info in infos)


def test_no_cost_at_the_first_period_after_an_autoreset():
    plain, wrapped = _twins(horizon=1.0)  # two control periods of 0.5 s, then the formations restart
    n = plain.num_envs
    actions = [np.full((n, 2), v) for v in (0.1, -0.3, 0.9, 0.5)]
    expected = [0.0, 0.5 * WEIGHT * 0.4, 0.0, 0.5 * WEIGHT * 0.4]
    ends = []
    for a, cost in zip(actions, expected, strict=True):
        _, r_plain, _, _ = _step(plain, a)
        _, r_wrapped, dones, _ = _step(wrapped, a)
        ends.append(bool(dones.all()))
        np.testing.assert_allclose(r_plain - r_wrapped, cost, atol=1e-6)
    assert ends == [False, True, False, True]


def test_build_env_wraps_only_with_a_positive_weight_and_refuses_bad_ones():
    config = load_config(SPEED_CONFIG)
    shaped = train_module.build_env(validate({**config, "n_envs": 1, "action_change_penalty": 0.5}), seed=0)
    plain = train_module.build_env(validate({**config, "n_envs": 1}), seed=0)
    # inside the monitor, so the training returns it logs are the ones the learner optimizes
    assert [type(v) for v in _chain(shaped)][-3:-1] == [VecMonitor, ActionChangePenalty]
    assert ActionChangePenalty not in [type(v) for v in _chain(plain)]
    shaped.close()
    plain.close()
    for bad in (-0.1, "0.5", float("nan"), True):
        with pytest.raises(TrainConfigError, match=f"action_change_penalty must be a number >= 0, got {bad!r}"):
            validate({**config, "action_change_penalty": bad})
    with pytest.raises(ValueError, match="weight must be a number >= 0, got -1"):
        ActionChangePenalty(SharedPolicyVecEnv(1, "paper"), -1, 0.5)
    with pytest.raises(ValueError, match="same control period dt"):
        TeamsVecEnv([SharedPolicyVecEnv(1, "paper"), SharedPolicyVecEnv(1, "paper", dt=0.25)])
