"""The throughput benchmark's instruments (not its timings: those live in the script, as ratios)."""

from __future__ import annotations

import argparse
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


def _run(pipeline: str, seed: int, rate: float, ret: float) -> dict[str, object]:
    return {"pipeline": pipeline, "seed": seed, "vessel_steps": int(rate * 10), "train_seconds": 10.0,
            "vessel_steps_per_s": rate, "learned_return": ret, "reference_return": -80.0}  # fmt: skip


def test_training_throughput_summarizes_each_pipeline_over_its_seeds_against_sb3() -> None:
    """Truth: numpy's mean, sample std (ddof 1), min and max of the per-seed values."""
    from benchmarks.training_throughput import format_runs, format_table, summarize

    runs = [
        _run("sb3", 0, 100.0, -70.0), _run("torchrl", 0, 600.0, -72.0),
        _run("sb3", 1, 120.0, -74.0), _run("torchrl", 1, 500.0, -66.0),
        _run("sb3", 2, 110.0, -72.0), {"pipeline": "torchrl", "seed": 2, "failed": "exit 1; see x.log"},
        {"pipeline": "rllib", "seed": 0, "skipped": "needs --ecosystem-python"},
    ]  # fmt: skip
    sb3, torchrl, rllib = summarize(runs)
    for row, rates, returns in [(sb3, [100, 120, 110], [-70, -74, -72]), (torchrl, [600, 500], [-72, -66])]:
        for key, values in (("vessel_steps_per_s", rates), ("learned_return", returns)):
            spread = row[key]
            assert spread["per_seed"] == values
            assert spread["mean"] == pytest.approx(np.mean(values))
            assert spread["std"] == pytest.approx(np.std(values, ddof=1))
            assert (spread["min"], spread["max"]) == (min(values), max(values))
    assert sb3["seeds"] == [0, 1, 2] and "vs_sb3" not in sb3
    assert torchrl["seeds"] == [0, 1] and torchrl["failed"] == {"2": "exit 1; see x.log"}
    assert torchrl["vs_sb3"]["rate_ratio"] == pytest.approx(550 / 110)  # ratio of the means: exactly 5
    assert torchrl["vs_sb3"]["return_difference"] == pytest.approx(-69 + 72)
    assert torchrl["vs_sb3"]["target_met"] is True
    assert rllib == {"pipeline": "rllib", "seeds": [], "skipped": {"0": "needs --ecosystem-python"}}
    table = format_table({"pipelines": [sb3, torchrl, rllib]}).splitlines()
    assert table[2] == "| sb3 | 0, 1, 2 | 110 ± 10 (100 – 120) | 1.00 | -72.0 ± 2.0 (-74.0 – -70.0) | -80.0 | – |"
    assert table[3].startswith("| torchrl | 0, 1 (1 not finished) | 550 ± 71 (500 – 600) | 5.00 | -69.0 ± 4.2 ")
    assert table[3].endswith("| met |")
    assert table[4] == "| rllib | seed 0: needs --ecosystem-python | | | | | |"
    lines = format_runs({"runs": runs}).splitlines()
    assert lines[2] == "| sb3 | 0 | 1,000 | 10 | 100 | -70.0 | -80.0 |"
    assert lines[7] == "| torchrl | 2 | exit 1; see x.log | | | | |"
    slower = summarize([_run("sb3", 0, 100.0, -70.0), _run("torchrl", 0, 499.0, -60.0)])[1]["vs_sb3"]
    worse = summarize([_run("sb3", 0, 100.0, -70.0), _run("torchrl", 0, 900.0, -70.5)])[1]["vs_sb3"]
    assert slower["target_met"] is False and worse["target_met"] is False


def test_training_throughput_trains_torchrl_on_the_benchmark_reward_not_the_configs_shaping(tmp_path) -> None:
    """Every pipeline learns from the same reward: the TorchRL command drops the shipped config's train_reward.

    Truth: the scenario's reward built from the learner's env overrides equals the one the evaluation
    uses (the ``paper`` preset's), while the shipped config alone would train with other scales.
    """
    pytest.importorskip("torch")
    from benchmarks.training_throughput import _command
    from marine_formation_env.scenarios import make_config
    from training.config import add_run_arguments, config_from_arguments, training_env_kwargs
    from training.torchrl_config import resolve

    def learner_reward(argv):
        parser = argparse.ArgumentParser()
        add_run_arguments(parser)
        cfg = config_from_arguments(parser.parse_args(argv), resolve, "test")
        return make_config(cfg["scenario"], **training_env_kwargs(cfg)).reward, make_config(
            cfg["scenario"], **cfg["env_kwargs"]
        ).reward

    command = _command("torchrl", 1.0, 2, 0, tmp_path, None)
    trained, evaluated = learner_reward(command[command.index("--config") :])
    assert trained == evaluated
    shipped = [*command[command.index("--config") : command.index("--config") + 2], "--out", str(tmp_path)]
    trained, evaluated = learner_reward(shipped)
    assert trained.sigma_coordination < evaluated.sigma_coordination  # the config's shaping, which the benchmark drops


def test_training_throughput_runs_every_seed_and_keeps_each_run_in_the_json(monkeypatch, tmp_path, capsys) -> None:
    import json

    from benchmarks import training_throughput

    calls = []

    def fake(name, minutes, episodes, seed, out, eco):
        calls.append((name, seed, out))
        return _run(name, seed, 100.0 * (1 + seed) * (6 if name == "torchrl" else 1), -70.0 - seed)

    monkeypatch.setattr(training_throughput, "run_pipeline", fake)
    report_path = tmp_path / "docs" / "tt.json"
    argv = ["--pipelines", "sb3,torchrl", "--seeds", "3,1", "--out", str(tmp_path / "runs"), "--json", str(report_path)]
    assert training_throughput.main(argv) == 0
    three, one = tmp_path / "runs" / "seed_3", tmp_path / "runs" / "seed_1"
    assert calls == [("sb3", 3, three), ("torchrl", 3, three), ("sb3", 1, one), ("torchrl", 1, one)]
    report = json.loads(report_path.read_text())
    assert report == json.loads((tmp_path / "runs" / "training_throughput.json").read_text())
    assert report["complete"] is True and report["seeds"] == [3, 1] and len(report["runs"]) == 4
    torchrl = report["pipelines"][1]
    assert torchrl["vessel_steps_per_s"]["per_seed"] == [2400.0, 1200.0]
    assert torchrl["vs_sb3"]["rate_ratio"] == pytest.approx(6.0) and torchrl["vs_sb3"]["target_met"] is True
    assert "| torchrl | 3, 1 |" in capsys.readouterr().out
    assert not list(tmp_path.rglob("*.tmp*"))  # written atomically: no temporary left behind
    calls.clear()
    assert training_throughput.main(["--pipelines", "sb3", "--seed", "4", "--out", str(tmp_path / "one")]) == 0
    assert calls == [("sb3", 4, tmp_path / "one" / "seed_4")]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--minutes", "0"], "--minutes must be > 0, got 0.0"),
        (["--pipelines", "sb3,jax"], "--pipelines: unknown ['jax']"),
        (["--ecosystem-python", "/no/python"], "--ecosystem-python '/no/python' is not an executable"),
        (["--seeds", "0,x"], "--seeds: expected comma-separated whole numbers ≥ 0, got 'x' in '0,x'"),
        (["--seeds", "0,-1"], "got '-1' in '0,-1'"),
        (["--seeds", "1,1"], "--seeds: seed 1 given twice in '1,1'"),
        (["--seed", "0", "--seeds", "1"], "not allowed with argument"),
    ],
)
def test_training_throughput_refuses_bad_arguments_by_name(capsys, args, message) -> None:
    from benchmarks.training_throughput import main

    with pytest.raises(SystemExit):
        main(args)
    assert message in capsys.readouterr().err


def test_the_traffic_table_gives_each_case_over_the_ideal_links_of_its_row():
    def entry(rate: float, over: float | None = None) -> dict:
        out = {"steps_per_s": rate / 64, "env_steps_per_s": rate, "spread": {"min": rate / 128, "max": rate / 32}}
        return out if over is None else {**out, "over_ideal": over}

    row = {name: entry(1000.0 * (k + 1), (k + 1) / 1.0) for k, name in enumerate(benchmark.TRAFFIC)}
    row["ideal"] = entry(1000.0)
    text = "\n".join(benchmark.format_traffic({"traffic": {"64": row}}))
    assert "| 64 | 1,000 [500–2,000] | 2,000 [1,000–4,000] | 2.00 |" in text
    assert benchmark.format_traffic({}) == []
