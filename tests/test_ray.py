"""Ray: the sweep's cells as Ray tasks, the benchmark's cells and RLlib PPO on two-node clusters.

Needs the ``rllib`` extra (``.venv-ecosystem``, see README): skipped elsewhere.
Every cluster runs in its own network and PID namespaces (``tests/isolated.py``):
loopback only, bounded in time, gone when the test ends.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray.rllib")

import benchmarks.suite as suite
from baselines.sweep import main as sweep_main
from tests.isolated import run_isolated
from training.config import TrainConfigError, load_config
from training.rllib_ppo import main as rllib_main
from training.rllib_ppo import resolve

ROOT = Path(__file__).resolve().parent.parent
SMALL_GRID = ["--loss", "0,0.5", "--latency", "0,2", "--episodes", "2", "--set", "horizon=40", "--quiet"]


def test_sweep_on_ray_gives_the_report_of_the_local_run(tmp_path):
    local = tmp_path / "local"
    assert sweep_main([*SMALL_GRID, "--out", str(local)]) == 0
    on_ray = tmp_path / "ray"
    args = " ".join([*SMALL_GRID, "--out", str(on_ray), "--address", "local"])
    done = run_isolated(f"$PYTHON -m baselines.sweep {args}", timeout=300, cwd=str(ROOT))
    assert done.returncode == 0, done.stderr[-3000:]
    # each cell depends only on its settings and seeds: the same numbers, to the last bit, on this build
    remote, here = (json.loads(path.with_suffix(".json").read_text()) for path in (on_ray, local))
    assert remote.pop("provenance")["command"].endswith("--address local") and "provenance" in here
    here.pop("provenance")
    assert remote == here
    assert on_ray.with_suffix(".md").read_text() == local.with_suffix(".md").read_text()
    assert on_ray.with_suffix(".png").stat().st_size > 0


@pytest.mark.slow
def test_the_benchmark_s_cells_on_a_two_node_cluster_score_as_the_local_run(tmp_path):
    """The head node has no CPU, so the cell (a Ray task of one CPU) can only run on the worker node."""
    pytest.importorskip("benchmarl")
    argv = ["table", "--quick", "--tasks", "paper_speed", "--algorithms", "mappo", "--seeds", "0", "--episodes", "2"]
    assert (
        suite.main([*argv, "--out", str(tmp_path / "local"), "--results", str(tmp_path / "local.json"), "--quiet"]) == 0
    )
    remote = " ".join([*argv, "--out", str(tmp_path / "ray"), "--results", str(tmp_path / "ray.json"), "--quiet"])
    port = 6392
    script = f"""
RAY="$(dirname "$PYTHON")/ray"
export RAY_AUTH_MODE=token
"$RAY" start --head --port={port} --num-cpus=0 --include-dashboard=false --disable-usage-stats
"$RAY" start --address=127.0.0.1:{port} --num-cpus=1 --disable-usage-stats
trap '"$RAY" stop --force' EXIT
$PYTHON -m benchmarks.suite {remote} --address 127.0.0.1:{port}
"""
    done = run_isolated(script, timeout=300, cwd=str(ROOT))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    here, there = (json.loads((tmp_path / name).read_text()) for name in ("local.json", "ray.json"))
    for tasks in (here["tasks"], there["tasks"]):
        assert tasks["paper_speed"].pop("provenance")["command"].startswith("python -m benchmarks.suite table")
    assert here["tasks"] == there["tasks"]  # the reference and random policy, evaluated by the driver
    cell, far = here["cells"]["paper_speed/mappo/seed_0"], there["cells"]["paper_speed/mappo/seed_0"]
    assert far["provenance"]["command"].endswith(f"--address 127.0.0.1:{port}")
    # seeded training in a process of its own: the same policy, up to the order in which a Ray worker's math
    # libraries sum in float32 (measured: returns agree to 4e-10 relative)
    for key in ("return", "final_spread", "final_cross_track", "action_change"):
        assert far["learned"][key] == pytest.approx(cell["learned"][key], rel=1e-6), key
    assert far["learned"]["success"] == cell["learned"]["success"]
    assert far["curve"]["formation_steps"] == cell["curve"]["formation_steps"]
    np.testing.assert_allclose(far["curve"]["return"], cell["curve"]["return"], rtol=1e-6)


def test_sweep_without_a_cluster_at_the_address_says_so(tmp_path, capsys):
    with pytest.raises(SystemExit):
        sweep_main([*SMALL_GRID, "--out", str(tmp_path / "s"), "--address", ""])
    assert "--address must be HOST:PORT, 'auto' or 'local', got ''" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("num_env_runnerz=2", "unknown key(s) ['num_env_runnerz']"),
        ("num_env_runners=-1", "num_env_runners must be a whole number ≥ 0, got -1"),
        ("gae_lambda=1.5", "gae_lambda must lie in [0, 1], got 1.5"),
        ("lambda=0.9", "the key 'lambda' is now 'gae_lambda'"),
        ("minibatch_size=600", "the key 'minibatch_size' is now 'batch_size'"),
        ("num_envs_per_env_runner=2", "the key 'num_envs_per_env_runner' is now 'n_envs'"),
        ("env_runner_resources={worker_node: 0}", "env_runner_resources must map resource names to amounts > 0"),
        ("batch_size=100000", "batch_size = 100000 vessel-steps exceeds a batch of 4000 × 3"),
        ("env_kwargs.action_levl=speed", "action_levl"),
    ],
)
def test_bad_rllib_configs_are_refused_in_one_line(tmp_path, capsys, item, message):
    with pytest.raises(SystemExit):
        rllib_main(["--set", item, "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_resolve_fills_the_defaults_and_the_shipped_config_resolves():
    raw = load_config(ROOT / "training/configs/rllib/paper_speed_ppo.yaml")
    cfg = resolve(raw, seed=3)
    assert cfg["seed"] == 3 and cfg["env_kwargs"]["action_level"] == "speed" and cfg["num_env_runners"] == 2
    with pytest.raises(TrainConfigError, match="hidden must be a non-empty list"):
        resolve({"hidden": []}, seed=0)


@pytest.mark.slow
def test_rllib_ppo_on_a_two_node_cluster_places_env_runners_on_the_worker_and_its_checkpoint_evaluates(tmp_path):
    run = tmp_path / "run"
    evaluation = tmp_path / "evaluation.json"
    port = 6391
    script = f"""
ip -o addr > {tmp_path}/interfaces.txt
RAY="$(dirname "$PYTHON")/ray"
export RAY_AUTH_MODE=token  # every process of the cluster and its drivers presents the token (~/.ray/auth_token)
"$RAY" start --head --port={port} --num-cpus=1 --include-dashboard=false --disable-usage-stats
"$RAY" start --address=127.0.0.1:{port} --num-cpus=2 --resources='{{"worker_node": 2}}' --disable-usage-stats
trap '"$RAY" stop --force' EXIT
$PYTHON -m training.rllib_ppo --config training/configs/rllib/paper_speed_ppo.yaml --address 127.0.0.1:{port} \\
    --set iterations=2 --set train_batch_size=800 --set batch_size=600 --set eval_episodes=1 \\
    --set env_runner_resources.worker_node=1 --out {run} --no-progress
$PYTHON -m baselines.evaluate --policy {run} --policy reference --scenario paper --set action_level=speed \\
    --episodes 1 --json {evaluation} --quiet
"""
    done = run_isolated(script, timeout=900, cwd=str(ROOT))
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
    interfaces = (tmp_path / "interfaces.txt").read_text().split()
    assert "lo" in interfaces and "eth0" not in interfaces  # the cluster could only listen on loopback
    cluster = json.loads((run / "cluster.json").read_text())
    assert len(cluster["nodes"]) == 2
    workers = {node for node, info in cluster["nodes"].items() if "worker_node" in info["resources"]}
    assert len(workers) == 1 and {info["address"] for info in cluster["nodes"].values()} == {"127.0.0.1"}
    assert len(cluster["env_runners"]) == 2 and set(cluster["env_runners"]) == workers
    rows = (run / "progress.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[-1].startswith("4800,") and rows[-1].endswith(",2,1600")
    report = json.loads(evaluation.read_text())
    learned = report["policies"][str(run)]["summary"]["return"]["mean"]
    assert math.isfinite(learned) and "reference" in report["policies"]
