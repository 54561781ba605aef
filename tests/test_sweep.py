"""Command-line access to the channel and the current: evaluate's overrides and options, the sweep script."""

from __future__ import annotations

import json

import pytest

from baselines.evaluate import main as evaluate_main
from baselines.evaluate import reference_options
from baselines.sweep import main as sweep_main
from marine_formation_env.cli import parse_overrides
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)


def test_dotted_overrides_collect_into_nested_settings():
    parsed = parse_overrides(["channel.loss=0.3", "channel.latency=2", "current.speed=0.4", "horizon=50"])
    assert parsed == {"channel": {"loss": 0.3, "latency": 2}, "current": {"speed": 0.4}, "horizon": 50}
    cfg = make_config("acoustic", **parse_overrides(["channel.latency=3.0"]))
    assert cfg.channel.latency == 3.0 and cfg.channel.tdma_slot == 4.0  # the rest of the preset is kept
    with pytest.raises(ValueError, match=r"PARENT\.FIELD=VALUE"):
        parse_overrides(["channel.=1"])
    with pytest.raises(ValueError, match="channel was already set"):
        parse_overrides(["channel=None", "channel.loss=0.1"])


def test_reference_options_from_the_policy_name():
    assert reference_options("reference") == {}
    assert reference_options("reference:extrapolate") == {"extrapolate": True}
    assert reference_options("reference:ilos") == {"integral_los": 1.0}
    assert reference_options("reference:extrapolate,ilos=2.5") == {"extrapolate": True, "integral_los": 2.5}
    with pytest.raises(ValueError, match="unknown reference option 'kalman'"):
        reference_options("reference:kalman")
    with pytest.raises(ValueError, match="ilos=σ needs a number, got 'big'"):
        reference_options("reference:ilos=big")


def test_evaluate_cli_with_channel_overrides_and_reference_options(tmp_path, capsys):
    out = tmp_path / "acoustic.json"
    code = evaluate_main(
        [
            "--scenario", "acoustic", "--policy", "reference", "--policy", "reference:extrapolate",
            "--set", "channel.latency=2.0", "--set", "horizon=150", "--episodes", "1",
            "--json", str(out), "--quiet",
        ]
    )  # fmt: skip
    assert code == 0
    report = json.loads(out.read_text())
    assert report["config"]["channel"]["latency"] == 2.0 and report["config"]["channel"]["tdma_slot"] == 4.0
    spread = {p: r["summary"]["final_coordination_spread"]["mean"] for p, r in report["policies"].items()}
    # with stale data the plain law lags by u·age; the extrapolating one does not
    assert spread["reference"] > 10 * spread["reference:extrapolate"]
    with pytest.raises(SystemExit):
        evaluate_main(["--scenario", "acoustic", "--set", "channel.loss=1.5", "--quiet"])
    assert "channel.loss must be a probability in [0, 1], got 1.5" in capsys.readouterr().err


def test_sweep_writes_table_json_and_figure(tmp_path):
    prefix = tmp_path / "sweep"
    code = sweep_main(
        [
            "--loss",
            "0,0.5",
            "--latency",
            "0,2",
            "--episodes",
            "1",
            "--set",
            "horizon=60",
            "--out",
            str(prefix),
            "--quiet",
        ]
    )
    assert code == 0
    report = json.loads(prefix.with_suffix(".json").read_text())
    assert report["loss"] == [0.0, 0.5] and report["latency"] == [0.0, 2.0]
    cells = report["cells"]["reference"]
    assert cells[0][0]["final_spread"] < cells[0][1]["final_spread"]  # latency hurts the plain law
    assert set(cells[1][1]) >= {"final_spread", "settling_time", "surge_outside_band_time", "collision_rate"}
    table = prefix.with_suffix(".md").read_text()
    assert "| loss p \\ latency | 0 s | 2 s |" in table and "### reference:extrapolate" in table
    assert prefix.with_suffix(".png").stat().st_size > 10_000
