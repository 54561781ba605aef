"""The learning benchmark's runner (benchmarks.suite): scores, aggregates, the quick pipeline, resuming."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("rliable")
from scipy import stats

import benchmarks.suite as suite
from baselines.engine import episode_reports
from baselines.reference import ReferencePolicy
from baselines.seeds import benchmark_seeds
from marine_formation_env import parallel_env

pytestmark = pytest.mark.backend_independent  # runs the env on either backend alike (test_backends.py)


def test_the_score_is_zero_at_the_random_policy_and_one_at_the_reference():
    assert suite.normalized_score(-300.0, -100.0, -300.0) == 0.0
    assert suite.normalized_score(-100.0, -100.0, -300.0) == 1.0
    assert suite.normalized_score(-50.0, -100.0, -300.0) == pytest.approx(1.25)  # beyond the reference
    with pytest.raises(ValueError, match=r"must exceed the random policy.s -100\.0"):
        suite.normalized_score(-50.0, -120.0, -100.0)


def test_the_aggregate_is_the_interquartile_mean_with_a_bootstrap_interval_around_it():
    rng = np.random.default_rng(3)
    table = {"mappo": rng.normal(1.0, 0.3, (5, 6)), "ippo": rng.normal(0.2, 0.3, (5, 6))}
    summary = suite.aggregate(table, reps=500)
    for name, scores in table.items():
        # the IQM: the mean of the middle half of all runs' scores (scipy's 25 % trimmed mean)
        assert summary[name]["iqm"] == pytest.approx(stats.trim_mean(scores.ravel(), 0.25))
        low, high = summary[name]["ci"]
        assert low < summary[name]["iqm"] < high and summary[name]["runs"] == 30
    better = summary["probability_of_improvement"]
    assert better["pair"] == "mappo,ippo" and better["value"] > 0.95  # MAPPO's scores lie ~0.8 above IPPO's
    assert summary == suite.aggregate(table, reps=500)  # the bootstrap is seeded


def test_every_algorithm_has_one_configuration_that_differs_from_the_others_only_in_the_algorithm():
    configs = {
        name: yaml.safe_load((suite.ALGORITHM_CONFIGS / f"{name}.yaml").read_text()) for name in suite.ALGORITHMS
    }
    assert configs["mappo"] == configs["ippo"]  # BenchMARL's two classes, one set of hyperparameters
    experiment = yaml.safe_load((suite.ALGORITHM_CONFIGS / "experiment.yaml").read_text())
    # the task sets the budget; the cell scores the policy itself on the reserved seeds
    assert experiment["evaluation"] is False and experiment["loggers"] == []
    assert experiment["on_policy_collected_frames_per_batch"] % experiment["on_policy_n_envs_per_worker"] == 0


def test_the_tasks_are_the_benchmarl_tasks_and_each_has_a_budget_in_formation_steps():
    shipped = {path.stem for path in suite.TASK_CONFIGS.glob("*.yaml")}
    assert set(suite.TASKS) | set(suite.COMMUNICATION_TASKS) == shipped
    assert not set(suite.TASKS) & set(suite.COMMUNICATION_TASKS)
    for task in suite.TASKS.values():
        scenario, overrides = task.scenario()
        assert isinstance(task.budget, int) and task.budget > 0
        parallel_env(scenario, **overrides)  # each builds


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    pytest.importorskip("benchmarl")
    """The quick pipeline over its two tasks and one seed, MAPPO only (each cell is a subprocess that imports
    torch: seconds), as CI runs it; the two algorithms' aggregate is tested on numbers above."""
    root = tmp_path_factory.mktemp("suite")
    argv = ["table", "--quick", "--algorithms", "mappo", "--seeds", "0", "--episodes", "2", "--out",
            str(root / "runs"), "--results", str(root / "results.json"), "--quiet"]  # fmt: skip
    assert suite.main(argv) == 0
    return root, argv


def test_the_quick_table_scores_every_cell_against_its_task_s_reference_and_random_policy(quick):
    root, _ = quick
    results = json.loads((root / "results.json").read_text())
    assert sorted(results["cells"]) == sorted(f"{task}/mappo/seed_0" for task in suite.QUICK_TASKS)
    for cell in results["cells"].values():
        assert cell["provenance"]["command"].startswith("python -m benchmarks.suite table --quick")
        assert len(cell["learned"]["returns"]) == 2 and cell["formation_steps"] == suite.QUICK["max_n_frames"]
    # the reference of the acoustic task is the extrapolating one: recomputed here with the engine
    task = results["tasks"]["acoustic_speed"]
    assert task["reference"]["options"] == {"extrapolate": True}
    scenario, overrides = suite.TASKS["acoustic_speed"].scenario()
    env = parallel_env(scenario, **{**overrides, "horizon": suite.QUICK_HORIZON})
    metrics, _ = episode_reports(ReferencePolicy(env, extrapolate=True), env.config, benchmark_seeds(2))
    assert task["reference"]["returns"] == [m["return"] for m in metrics]


def test_the_report_gives_each_task_s_scores_the_aggregates_and_a_figure(quick, capsys):
    root, _ = quick
    figure = root / "report.png"
    assert suite.main(["report", "--results", str(root / "results.json"), "--figure", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "| `paper_speed` |" in out and "| `acoustic_speed` |" in out and "IQM of the score" in out
    assert figure.stat().st_size > 10_000
    page = root / "page.md"
    page.write_text("# Page\n\nbefore\n<!-- benchmark-results:start -->\nold\n<!-- benchmark-results:end -->\nafter\n")
    args = ["report", "--results", str(root / "results.json"), "--figure", str(figure), "--document", str(page)]
    assert suite.main(args) == 0
    text = page.read_text()
    assert text.startswith("# Page\n\nbefore\n") and text.endswith("after\n") and "old" not in text
    assert "| `paper_speed` |" in text and "python -m benchmarks.suite report" in text


def test_the_table_resumes_finished_cells_are_kept_and_a_killed_one_is_trained_again(quick, monkeypatch):
    root, argv = quick
    before = json.loads((root / "results.json").read_text())

    def no_training(*args, **kwargs):
        raise AssertionError("a finished cell was trained again")

    monkeypatch.setattr(suite, "run_cell", no_training)
    assert suite.main(argv) == 0
    assert json.loads((root / "results.json").read_text()) == before
    monkeypatch.undo()
    killed = root / "runs" / "paper_speed" / "mappo" / "seed_1"
    killed.mkdir(parents=True)
    (killed / "progress.csv").write_text("vessel_steps,wall_time_s\n12")  # what a killed run leaves
    cell_argv = ["cell", "--task", "paper_speed", "--algorithm", "mappo", "--seed", "1", "--quick", *argv[6:]]
    assert suite.main(cell_argv) == 0
    after = json.loads((root / "results.json").read_text())
    assert "paper_speed/mappo/seed_1" in after["cells"] and set(before["cells"]) < set(after["cells"])
    assert (killed / "result.json").is_file() and not (killed / "progress.csv").exists()  # a new run folder


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["cell", "--task", "fish", "--algorithm", "mappo", "--seed", "0"], "invalid choice: 'fish'"),
        (["table", "--tasks", "paper_speed,fish", "--results", "x.json"], "--tasks: unknown ['fish']"),
        (["table", "--algorithms", "qmix", "--results", "x.json"], "--algorithms: unknown ['qmix']"),
        (["table", "--quick"], "--quick writes a results file of its own"),
        (["report", "--results", "missing.json"], "no cells yet"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        suite.main(argv)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert not Path("x.json").exists()


def test_the_benchmark_page_shows_the_tables_of_the_committed_results_file():
    """docs/benchmark.md between its markers is what ``report`` makes of docs/benchmark_results.json."""
    root = Path(__file__).resolve().parents[1]
    results = json.loads((root / "docs" / "benchmark_results.json").read_text())
    page = (root / "docs" / "benchmark.md").read_text()
    start, end = suite.MARKERS
    assert page.count(start) == 1 and page.count(end) == 1, "the page needs one pair of result markers"
    block = page.split(start, 1)[1].split(end, 1)[0]
    expected = suite.format_report(results, suite.aggregate(suite.scores(results)))
    assert expected in block, "regenerate: python -m benchmarks.suite report --document docs/benchmark.md"
