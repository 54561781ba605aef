"""Episode metrics against values known by construction (baselines.metrics)."""

from __future__ import annotations

import numpy as np
import pytest

from baselines.engine import run_episode
from baselines.metrics import action_change, action_change_by_entry, episode_metrics
from baselines.rollout import BatchPolicy
from marine_formation_env.env import parallel_env


class SteadySpeedFlippingHeading(BatchPolicy):
    """A constant speed command and a heading command that flips between −1 and +1 every period."""

    def __init__(self) -> None:
        self.sign = 1.0

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        self.sign = -self.sign
        out = np.empty((*obs.shape[:-1], 2))
        out[..., 0] = 0.3
        out[..., 1] = self.sign
        return out


def test_action_change_per_entry_names_the_command_that_chatters():
    env = parallel_env("paper", action_level="guidance", horizon=10.0)
    metrics = episode_metrics(run_episode(env, SteadySpeedFlippingHeading(), seed=0), env.config)
    assert metrics["steps"] >= 2
    # |(+1) − (−1)| = 2 at every period for ψ_d, 0 for the constant u_c; the overall mean is their mean
    assert metrics["action_change_u_c"] == 0.0
    assert metrics["action_change_psi_d"] == pytest.approx(2.0, abs=1e-12)
    assert metrics["action_change"] == pytest.approx(1.0, abs=1e-12)
    assert "action_change_tau_u" not in metrics


def test_action_change_by_entry_of_hand_made_actions():
    # two vessels, three periods: entry 0 moves by 0.5 then 0.25 on both vessels, entry 1 stays
    actions = np.array([[[0.0, 0.1], [0.0, 0.1]], [[0.5, 0.1], [0.5, 0.1]], [[0.25, 0.1], [0.25, 0.1]]])
    np.testing.assert_allclose(action_change_by_entry(actions), [0.375, 0.0], atol=1e-15)
    assert action_change(actions) == pytest.approx(0.1875, abs=1e-15)
    np.testing.assert_array_equal(action_change_by_entry(actions[:1]), [0.0, 0.0])


def test_action_change_by_entry_refuses_a_shape_without_vessels():
    with pytest.raises(ValueError, match=r"\(T, n, A\), got \(3, 2\)"):
        action_change_by_entry(np.zeros((3, 2)))
