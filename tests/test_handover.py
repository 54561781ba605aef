"""``baselines.handover``: a learned policy for the transient, the paper's controller once settled.

Truth: the success bands of ``baselines.metrics`` applied by hand to
hand-built observations (the cross-track error, a linked neighbour's
coordination error predicted to now as ``Δθ − ẋ_i·age``, the lane speed
error); the hold and the latch, checked against the two parts' own actions; and the
paper's convergence result (the consensus law with LOS path following drives
every error to zero from any initial condition), which a handover must
inherit where the learned policy alone stops centimetres apart.
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines import evaluate as evaluate_module
from baselines.engine import episode_reports
from baselines.handover import HOLD, HandoverPolicy, in_band
from baselines.pretrained import load_pretrained
from baselines.reference import ReferencePolicy
from marine_formation_env import parallel_env
from marine_formation_env.observations import ObservationLayout
from marine_formation_env.rules import (
    CROSS_TRACK,
    CURVATURE,
    DESIRED_SPEED,
    LANE_OFFSET,
    SURGE,
)
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent

LAYOUT = ObservationLayout(3)


def _obs(e=0.0, u=5.0, u_d=5.0, kappa=0.0, d_y=0.0, slots=((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))):
    """One 3-vessel observation: the own part (ψ = v = r = 0) and two slots (linked, Δθ, Δẋ, age)."""
    obs = np.zeros(LAYOUT.dim)
    obs[CROSS_TRACK], obs[SURGE], obs[DESIRED_SPEED], obs[CURVATURE], obs[LANE_OFFSET] = e, u, u_d, kappa, d_y
    for k, slot in enumerate(slots):
        obs[LAYOUT.own + k * LAYOUT.slot : LAYOUT.own + (k + 1) * LAYOUT.slot] = slot
    return obs


@pytest.mark.parametrize(
    ("obs", "inside"),
    [
        (_obs(), True),
        (_obs(e=0.99), True),
        (_obs(e=-1.01), False),  # |e| ≤ 1 m
        (_obs(u=5.09), True),
        (_obs(u=4.89), False),  # |u − u_d| ≤ 0.1 m/s on the straight path
        (_obs(slots=((1.0, 0.95, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))), True),
        (_obs(slots=((1.0, -1.05, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))), False),  # a linked neighbour 1.05 m off
        (_obs(slots=((1.0, 0.0, 0.0, 0.0), (0.0, 30.0, 0.0, 0.0))), True),  # an unlinked slot is not read
        # a 2 s old message of a neighbour at ẋ_i = 5 − 0.1: Δθ now = 10.0 − 4.9·2 = 0.2 m
        (_obs(slots=((1.0, 10.0, 0.1, 2.0), (0.0, 0.0, 0.0, 0.0))), True),
        (_obs(slots=((1.0, 10.0, 0.1, 1.0), (0.0, 0.0, 0.0, 0.0))), False),  # 1 s old: 5.1 m
        # a lane at D_y = 30 m inside a 300 m turn: ℓ̇ = 5.2/(1 − 0.1) = 5.78, lane error 0.9·(5.78 − 5.70) = 0.07
        (_obs(u=5.2, u_d=5.70, kappa=1 / 300, d_y=30.0), True),
        (_obs(u=5.2, u_d=5.65, kappa=1 / 300, d_y=30.0), False),  # 0.9·(5.78 − 5.65) = 0.115 m/s
    ],
)
def test_in_band_applies_the_success_bands_to_the_own_observation(obs, inside):
    assert bool(in_band(LAYOUT, obs)) is inside


class _Constant:
    """A 'learned' policy that always commands the top of the range."""

    def act_batch(self, obs):
        return np.ones((*np.shape(obs)[:-1], 1), dtype=np.float32)


def test_a_vessel_hands_over_after_twenty_seconds_in_the_band_and_stays_until_reset():
    cfg = make_config("paper", action_level="speed")
    assert HOLD == 20.0 and cfg.dt == 0.5  # so the 41st observation in the band in a row is the first at 20 s
    policy = HandoverPolicy(_Constant(), cfg)
    reference = ReferencePolicy(cfg, extrapolate=True)
    far, near = _obs(e=5.0), _obs(e=0.1, slots=((1.0, 0.6, 0.02, 0.0), (0.0, 0.0, 0.0, 0.0)))
    # vessel 0 in the band for 30 periods, out once, then in; vessel 1 never
    rows = [np.stack([near, far])] * 30 + [np.stack([far, far])] + [np.stack([near, far])] * 41
    actions = np.array([policy.act_batch(obs) for obs in rows])
    assert np.all(actions[:71, 0] == 1.0)  # 30 in a row, a break, then 40 in a row: still learned
    np.testing.assert_array_equal(actions[71, 0], reference.act_batch(near))  # the 41st: the reference
    assert np.all(actions[:, 1] == 1.0)
    np.testing.assert_array_equal(policy.act_batch(np.stack([far, far]))[0], reference.act_batch(far))  # latched
    policy.reset()
    assert np.all(policy.act_batch(np.stack([near, far])) == 1.0)


def test_handover_ends_where_the_controller_does_after_the_learned_transient():
    """The paper's convergence result, inherited: the shipped speed row alone stops centimetres apart."""
    learned, info = load_pretrained("paper_speed")
    cfg = parallel_env(info.scenario, **info.env_kwargs).config
    seeds = [7, 8]
    alone, _ = episode_reports(learned, cfg, seeds)
    handed, _ = episode_reports(HandoverPolicy(learned, cfg), cfg, seeds)
    assert min(m["final_coordination_spread"] for m in alone) > 0.05  # the precision target it misses alone
    for m in handed:
        assert m["final_coordination_spread"] < 1e-6
        assert m["final_cross_track_max"] < 1e-6
        assert m["final_speed_error_max"] < 1e-6
        assert m["success"]


def test_evaluate_names_what_a_handover_cannot_take(capsys):
    with pytest.raises(SystemExit):
        evaluate_module.main(["--policy", "handover:random", "--quiet"])
    assert "handover needs a learned policy" in capsys.readouterr().err
    with pytest.raises(TypeError, match="needs a batch policy"):
        HandoverPolicy(object(), make_config("paper"))
    budget = parallel_env("paper_budget", action_level="speed", transmit=True)
    with pytest.raises(ValueError, match="does not send the transmit action"):
        HandoverPolicy(_Constant(), budget)
