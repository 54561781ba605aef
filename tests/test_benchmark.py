"""The throughput benchmark's instruments (not its timings: those live in the script, as ratios)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from benchmarks import throughput as benchmark
from marine_formation_env.dynamics import vessel_rhs
from marine_formation_env.params import SUPPLY

pytestmark = pytest.mark.backend_independent


def test_counter_counts_elementwise_operations() -> None:
    benchmark._Counter.ops = {}
    a = np.arange(5.0).view(benchmark._Counter)
    _ = a * 2.0 + np.sin(a)  # 5 multiplies, 5 sines, 5 additions
    assert benchmark._Counter.ops == {"multiply": 5, "sin": 5, "add": 5}


def test_vessel_step_count_is_four_stages_plus_the_rk4_combination() -> None:
    # One force-level control period is one RK4 step: 4 evaluations of the vessel ODE,
    # 3 stage states (a multiply and an add per component) and the final combination
    # (k2 + k3, 2·(…), + k1, + k4, (h/6)·(…), state + …: 6 operations per component).
    benchmark._Counter.ops = {}
    state = np.array([[0.0, 1.0, 0.2, 5.0, 0.1, 0.01]]).view(benchmark._Counter)
    vessel_rhs(SUPPLY, state, 0.1, 0.01)
    one_rhs = sum(benchmark._Counter.ops.values())
    counted = benchmark.count_vessel_step_ops("force")
    assert counted["substeps"] == 1
    assert counted["ops_per_vessel_step"] == 4 * one_rhs + 3 * 2 * 6 + 6 * 6
    assert counted["transcendental_per_vessel_step"] == 8  # sin and cos at each stage


def test_cases_report_rates_and_missing_peers(monkeypatch: pytest.MonkeyPatch) -> None:
    ours = benchmark.run_case("ours_batched", 4, 0.05, 1)
    assert ours["env_steps_per_s"] == pytest.approx(4 * ours["steps_per_s"])
    assert ours["steps_per_s"] > 0 and ours["max_rss_mb"] > 0
    monkeypatch.setitem(sys.modules, "vmas", None)  # import vmas now raises ImportError
    missing = benchmark.run_case("vmas_batched", 4, 0.05, 1)
    assert "unavailable" in missing and "vmas" in missing["unavailable"]
    monkeypatch.setitem(sys.modules, "jax", None)  # jax, or jaxmarl on top of it: either may be missing
    monkeypatch.setitem(sys.modules, "jaxmarl", None)
    for case in ("jaxmarl_scan_batched", "jaxmarl_step_batched"):
        missing = benchmark.run_case(case, 4, 0.05, 1)
        assert "unavailable" in missing and "jax" in missing["unavailable"]
    with pytest.raises(ValueError, match="'warp_drive'"):
        benchmark.run_case("warp_drive", 1, 0.05, 1)


def test_timing_warms_up_through_episode_ends_before_measuring() -> None:
    calls: list[int] = []

    def step(k: int) -> int:  # an "episode" ends every 500 steps
        calls.append(k)
        return int(k % 500 == 499)

    out = benchmark._time_steps(step, min_seconds=0.01, repeats=3, warmup_seconds=0.0)
    warm = out["warmup"]
    assert warm["resets"] >= benchmark.WARMUP_RESETS and warm["steps"] >= 1000  # two episode ends passed
    assert len(out["repeats"]) == 3
    spread = out["spread"]
    assert spread["min"] <= spread["q1"] <= out["steps_per_s"] <= spread["q3"] <= spread["max"]
    assert calls == list(range(len(calls)))  # the step index keeps counting through the timed repeats


def test_team_size_scaling_reports_vessel_steps_and_the_growth_exponent(monkeypatch: pytest.MonkeyPatch) -> None:
    def fake_case(case: str, b: int, min_seconds: float, repeats: int) -> dict[str, float]:
        n = int(case.rsplit("_", 1)[1])
        return {"env_steps_per_s": 1e6 / n**2, "steps_per_s": 1e6 / n**2 / b}  # cost ∝ n²

    monkeypatch.setattr(benchmark, "_subprocess_case", fake_case)
    out = benchmark.team_size_scaling(0.1, 1, sizes=(3, 8, 20))
    assert out["ideal"]["exponent"] == pytest.approx(2.0) and out["acoustic"]["exponent"] == pytest.approx(2.0)
    real = benchmark.run_case("scaling_acoustic_5", 4, 0.05, 1)
    assert real["vessel_steps_per_s"] == pytest.approx(5 * real["env_steps_per_s"])


def test_training_throughput_table_is_relative_to_sb3_and_names_skipped_pipelines() -> None:
    from benchmarks.training_throughput import format_table

    rows = [
        {"pipeline": "sb3", "vessel_steps": 1000, "train_seconds": 10.0, "vessel_steps_per_s": 100.0,
         "learned_return": -120.0, "reference_return": -80.0},
        {"pipeline": "torchrl", "vessel_steps": 5000, "train_seconds": 10.0, "vessel_steps_per_s": 500.0,
         "learned_return": -100.0, "reference_return": -80.0},
        {"pipeline": "rllib", "skipped": "needs --ecosystem-python"},
    ]  # fmt: skip
    table = format_table({"pipelines": rows}).splitlines()
    assert table[2].startswith("| sb3 | 1,000 | 10 | 100 | 1.00 |")
    assert table[3].startswith("| torchrl | 5,000 | 10 | 500 | 5.00 | -100.0 | -80.0 |")
    assert table[4] == "| rllib | needs --ecosystem-python | | | | | |"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--minutes", "0"], "--minutes must be > 0, got 0.0"),
        (["--pipelines", "sb3,jax"], "--pipelines: unknown ['jax']"),
        (["--ecosystem-python", "/no/python"], "--ecosystem-python '/no/python' is not an executable"),
    ],
)
def test_training_throughput_refuses_bad_arguments_by_name(capsys, args, message) -> None:
    from benchmarks.training_throughput import main

    with pytest.raises(SystemExit):
        main(args)
    assert message in capsys.readouterr().err
