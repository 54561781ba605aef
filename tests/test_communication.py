"""``benchmarks.communication``: the Pareto sweep's pipeline and its bookkeeping."""

from __future__ import annotations

import json

import pytest

from benchmarks import communication
from marine_formation_env.scenarios import make_config

pytestmark = pytest.mark.backend_independent


@pytest.mark.parametrize("preset, seconds", [("paper", 0.5), ("radio", 1.5), ("acoustic", 12.0)])
def test_a_vessel_may_broadcast_once_per_control_period_or_per_tdma_frame(preset, seconds):
    # paper: dt = 0.5 s at the speed level; radio and acoustic: three vessels, 0.5 s and 4 s TDMA slots
    assert communication.opportunity_period(make_config(preset)) == pytest.approx(seconds)


def test_the_quick_sweep_writes_its_report_and_the_target_follows_from_its_points(tmp_path, capsys):
    out = tmp_path / "communication"
    assert communication.main(["--quick", "--out", str(out), "--quiet"]) == 0
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["provenance"]["command"].startswith("python -m benchmarks.communication")
    assert out.with_suffix(".png").stat().st_size > 0
    for link, result in report["links"].items():
        periodic = next(p for p in result["periodic"] if p["every"] == 1)
        target = result["target"]
        if target.get("share") is not None:
            assert target["share"] == pytest.approx(target["event_rate"] / periodic["message_rate"])
            assert abs(target["return"] - periodic["return"]) <= 0.02 * abs(periodic["return"])
        # broadcasting at 1 in k opportunities sends fewer messages the larger k
        rates = [p["message_rate"] for p in sorted(result["periodic"], key=lambda p: p["every"])]
        assert rates == sorted(rates, reverse=True), link
    for result in report["budgets"].values():
        best = max(result["tuning"], key=lambda e: e["return"])
        assert result["tuned"]["channel"] == best["channel"]  # the δ chosen on the development seeds
    assert "### acoustic_budget" in capsys.readouterr().out


def test_learned_runs_must_come_from_a_budget_preset(tmp_path):
    with pytest.raises(SystemExit):
        communication.main(["--quick", "--out", str(tmp_path / "c"), "--learned", "paper=runs/x"])
