"""``observation_slots``: observations padded with empty slots, so teams of several sizes share one length.

Truth: the unpadded env itself (the padded observation must start with it,
entry for entry, and end in zeros), on both backends, with ideal links and
over the acoustic channel; the reference's episode must not change.
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines.engine import episode_reports
from baselines.reference import ReferencePolicy
from marine_formation_env import parallel_env
from marine_formation_env.errors import ConfigError
from marine_formation_env.rules import OWN_SIZE, SLOT_SIZE, slot_count


def test_the_default_is_one_slot_per_other_vessel():
    env = parallel_env("paper")
    assert env.config.observation_slots == 2
    assert env.observation_space("vessel_0").shape == (OWN_SIZE + 2 * SLOT_SIZE,)


@pytest.mark.parametrize(("n", "slots"), [(3, None), (5, None), (4, 9)])
def test_slot_count_reads_the_slots_back_from_an_observation_size(n, slots):
    env = parallel_env("paper", n_vessels=n, topology="ring", observation_slots=slots)
    assert slot_count(env.observation_space("vessel_0").shape[0]) == (n - 1 if slots is None else slots)


@pytest.mark.parametrize("dim", [0, OWN_SIZE - 1, OWN_SIZE + 1, OWN_SIZE + SLOT_SIZE + 3])
def test_slot_count_refuses_a_size_that_is_not_own_part_plus_whole_slots(dim):
    with pytest.raises(ValueError, match=rf"an observation of size {dim} is not {OWN_SIZE} \+ {SLOT_SIZE}·slots"):
        slot_count(dim)


@pytest.mark.parametrize(("scenario", "n"), [("paper", 4), ("acoustic", 4), ("circle", 3)])
def test_padded_observations_are_the_plain_ones_followed_by_empty_slots(scenario, n):
    plain = parallel_env(scenario, n_vessels=n, topology="ring", init_noise={"x": 10.0})
    padded = parallel_env(scenario, n_vessels=n, topology="ring", init_noise={"x": 10.0}, observation_slots=7)
    size = OWN_SIZE + (n - 1) * SLOT_SIZE
    assert padded.observation_space("vessel_0").shape == (OWN_SIZE + 7 * SLOT_SIZE,)
    low = padded.observation_space("vessel_0").low
    np.testing.assert_array_equal(low[:size], plain.observation_space("vessel_0").low)
    a, _ = plain.reset(seed=3)
    b, _ = padded.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(30):
        for agent in plain.agents:
            np.testing.assert_array_equal(b[agent][:size], a[agent])
            assert not b[agent][size:].any()
            assert padded.observation_space(agent).contains(b[agent])
        actions = {agent: rng.uniform(-1, 1, 1).astype(np.float32) for agent in plain.agents}
        a, *_ = plain.step(actions)
        b, *_ = padded.step(actions)


def test_the_reference_reads_padded_observations_and_acts_the_same():
    plain = parallel_env("acoustic", init_noise={"x": 10.0, "y": 5.0})
    padded = parallel_env("acoustic", init_noise={"x": 10.0, "y": 5.0}, observation_slots=5)
    first, _ = episode_reports(ReferencePolicy(plain, extrapolate=True), plain.config, [0, 1])
    second, _ = episode_reports(ReferencePolicy(padded, extrapolate=True), padded.config, [0, 1])
    assert [m["return"] for m in first] == [m["return"] for m in second]


@pytest.mark.parametrize("value", [1, 2.5, "many", True])
def test_fewer_slots_than_other_vessels_or_a_non_number_is_refused(value):
    with pytest.raises(
        ConfigError, match=rf"observation_slots must be None or a whole number ≥ n_vessels − 1 = 2 .*got {value!r}"
    ):
        parallel_env("paper", observation_slots=value)
