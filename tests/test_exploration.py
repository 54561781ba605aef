"""``python -m benchmarks.exploration``: how long formations last under zero-mean Gaussian actions.

Truth: the force level's physics. The yaw rate starts near 0 and its envelope
is |r| ≤ max_yaw_rate = 1 rad/s, while the yaw acceleration is at most
tau_r_max = 2 rad/s² (the sway-yaw coupling adds well under 1 %), so no
formation can leave the envelope in under 0.5 s (its surge speed, starting
near 5 m/s with at most 3 m/s², cannot reach max_speed = 14 m/s sooner
either); and with no actuation at all
a formation that starts on its lanes coasts straight, slowing down, and
lasts the whole episode.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import exploration
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent


def test_full_deviation_yaw_noise_ends_every_formation_but_not_faster_than_the_envelope_allows():
    config = make_config("paper", action_level="force")
    result = exploration.lifetimes("paper", "force", 1.0, 8, seed=0)
    seconds = np.asarray(result["seconds"])
    assert sum(result["ended_by"].values()) == 1.0 and result["ended_by"]["collision"] == 0.0
    assert np.all(seconds < config.horizon)
    assert seconds.min() >= config.max_yaw_rate / config.tau_r_max - 1e-9


def test_an_unactuated_formation_on_its_lanes_coasts_through_the_whole_episode():
    result = exploration.lifetimes("paper", "force", 1e-12, 2, seed=0, spread=0.0)
    assert result["seconds"] == [result["horizon"]] * 2
    assert not any(result["ended_by"].values())


def test_each_ended_formation_is_charged_to_the_bound_its_last_state_breaks():
    config = make_config("paper", action_level="force")
    state = np.zeros((3, 6))
    state[:, 0] = [0.0, 0.0, 1000.0]  # x [m]: far apart, inside the workspace
    assert exploration._cause(config, state) == "collision"  # no bound broken: the core saw vessels too close
    state[1, 5] = 1.5  # r [rad/s] beyond max_yaw_rate = 1
    state[2, 4] = 20.0  # v [m/s] beyond max_speed = 14
    assert exploration._cause(config, state) == "yaw_rate"
    state[1, 5] = 0.0
    assert exploration._cause(config, state) == "speed"
    state[2, 4] = 0.0
    state[0, 1] = 1e9  # y [m]
    assert exploration._cause(config, state) == "workspace"


def test_the_reference_s_late_actions_are_the_model_s_steady_state_on_a_straight_path():
    # once the formation sails its lanes at u = u_d (constant here), v = r = 0: the surge acceleration must only
    # balance the linear damping, tau_u = d11/m11 * u_d, and the yaw acceleration must vanish
    config = make_config("paper", action_level="force")
    assert config.u_d.amplitude == 0.0
    steady = config.vessel.d11 / config.vessel.m11 * config.u_d.mean / config.tau_u_max
    used = exploration.reference_actions("paper", "force", [0, 1], after=200.0)
    assert used["max_after"][0] == pytest.approx(steady, rel=1e-3)  # the consensus term has died out
    assert used["max_after"][1] < 1e-5
    assert used["max"][0] > 10 * steady  # the first seconds use much more of the range
    with pytest.raises(ValueError, match="after must lie in"):
        exploration.reference_actions("paper", "force", [0], after=400.0)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scales", "0,x"], "--scales must be comma-separated numbers, got '0,x'"),
        (["--scales", "0.1,0"], "--scales must all be > 0, got [0.0]"),
        (["--spread", "2"], "--spread must lie in [0, 1], got 2.0"),
        (["--formations", "0"], "expected a whole number ≥ 1, got 0"),
        (["--scales", "0.1", "--formations", "1", "--reference", "--after", "500"], "after must lie in [0, horizon"),
    ],
)
def test_bad_arguments_are_refused_by_name(capsys, args, message):
    with pytest.raises(SystemExit) as stop:
        exploration.main(args)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_the_table_and_the_json_report_every_deviation(tmp_path, capsys):
    out = tmp_path / "lifetimes.json"
    assert exploration.main(["--scales", "1,0.5", "--formations", "2", "--json", str(out)]) == 0
    assert [row["scale"] for row in json.loads(out.read_text())["runs"]] == [1.0, 0.5]
    rows = [line.split("|")[1].strip() for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert rows == ["action deviation", "1", "0.5"]


def test_reference_adds_the_reference_s_use_of_each_range_to_the_table_and_the_json(tmp_path, capsys):
    out = tmp_path / "lifetimes.json"
    args = ["--scales", "0.1", "--formations", "1", "--reference", "--after", "200", "--json", str(out)]
    assert exploration.main(args) == 0
    used = json.loads(out.read_text())["reference"]
    assert used["seeds"] == [0] and used["after"] == 200.0 and len(used["max_after"]) == 2  # tau_u, tau_r
    assert all(0.0 <= late <= top <= 1.0 for late, top in zip(used["max_after"], used["max"], strict=True))
    lines = capsys.readouterr().out.splitlines()
    assert "| statistic | tau_u | tau_r |" in lines and any(line.startswith("| max after 200 s |") for line in lines)
