"""The learning benchmark: tasks × algorithms × training seeds, scored on reserved seeds (``docs/benchmark.md``).

A **cell** is one ``(task, algorithm, seed)``: BenchMARL's experiment runner
trains its implementation of the algorithm with the benchmark's one
configuration of it (``training/configs/benchmark/``: ``ALGO.yaml``,
``mlp.yaml`` and ``experiment.yaml``, the same for every task) on the BenchMARL
task of that name (``marine_formation_env.benchmarl``) for the task's budget in
formation-steps, in a subprocess (``python -m benchmarks.suite train``); then
the policy acts deterministically on the reserved benchmark seeds
(``baselines.seeds.benchmark_seeds``), in the benchmark's reward. BenchMARL
needs the ecosystem environment (``pip install -c constraints-ecosystem.txt -e
".[marl,dev]"``). Each task's reference (the paper's controller; the
extrapolating one over lossy links) and random policy are evaluated once on the
same seeds, and a cell's **score** is its reference-normalized return
``(R − R_random) / (R_reference − R_random)``: 0 is random, 1 the paper's
controller::

    python -m benchmarks.suite cell --task paper_speed --algorithm mappo --seed 0
    python -m benchmarks.suite table                       # every cell, resumable
    python -m benchmarks.suite table --address HOST:PORT   # the cells as Ray tasks on a cluster
    python -m benchmarks.suite report                      # tables and figures from the results file
    python -m benchmarks.suite table --quick --out runs/suite_quick --results runs/suite_quick/results.json

``table`` skips the cells its results file holds already and retrains a cell
that was killed (its run folder is replaced); each finished cell is added to
the results file at once (``docs/benchmark_results.json`` by default, with its
commit, command and machine), from which ``report`` computes the interquartile
mean with 95 % stratified-bootstrap confidence intervals, performance profiles
and the probability of improvement (rliable), and the sample-efficiency curves.
``--quick`` shrinks every budget, the team's horizon and the episode count so
that the whole pipeline runs in well under a minute (the test suite runs it).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from baselines.engine import episode_reports
from baselines.metrics import summarize
from baselines.ray_cluster import connect
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy
from baselines.seeds import benchmark_seeds
from benchmarks.training_throughput import parse_seeds
from marine_formation_env.atomic import atomic_path, atomic_write_text
from marine_formation_env.cli import ArgumentParser, int_at_least
from marine_formation_env.env import parallel_env
from marine_formation_env.provenance import command_line, provenance

__all__ = [
    "ALGORITHMS",
    "COMMUNICATION_TASKS",
    "TASKS",
    "Cell",
    "Task",
    "aggregate",
    "main",
    "normalized_score",
    "run_cell",
    "run_table",
    "train_cell",
]

ROOT = Path(__file__).resolve().parents[1]
TASK_CONFIGS = ROOT / "marine_formation_env" / "benchmarl_conf" / "task" / "marine_formation"
ALGORITHM_CONFIGS = ROOT / "training" / "configs" / "benchmark"
RESULTS = ROOT / "docs" / "benchmark_results.json"
#: Episodes each trained policy (and each task's reference and random policy) is scored on.
EPISODES = 20
#: The training seeds of the table (at least five per cell).
SEEDS = (0, 1, 2, 3, 4)


@dataclass(frozen=True)
class Task:
    """A task of the benchmark: a BenchMARL task config and its budget [formation-steps], the same for every
    algorithm."""

    name: str
    budget: int
    #: the reference's options on this task (``ReferencePolicy``): extrapolate over lossy links
    reference: tuple[tuple[str, Any], ...] = ()

    def scenario(self) -> tuple[str, dict[str, Any]]:
        """The task's scenario name and overrides, from its BenchMARL task config."""
        config = yaml.safe_load((TASK_CONFIGS / f"{self.name}.yaml").read_text())
        return str(config["scenario"]), dict(config.get("overrides") or {})


#: The tasks, in the order of the tables.
TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        Task("paper_speed", 20_000_000),
        Task("paper_guidance", 20_000_000),
        Task("paper_force", 20_000_000),
        Task("acoustic_speed", 15_000_000, (("extrapolate", True),)),
        Task("ring6_speed", 10_000_000),
        Task("survey_speed", 20_000_000),
    )
}
#: The BenchMARL tasks of the communication track (docs/channel.md): a learned policy there is compared with
#: the reference tuned to the task's budget (``benchmarks.communication``), not in this table.
COMMUNICATION_TASKS = ("paper_speed_budget", "acoustic_speed_budget")
#: The algorithms, BenchMARL's: one configuration each (``ALGORITHM_CONFIGS``), for every task.
ALGORITHMS = ("mappo", "ippo")
#: What ``--quick`` changes in BenchMARL's experiment configuration: budgets and batches, so that a cell takes
#: seconds (the episode is shortened too, ``QUICK_HORIZON``).
QUICK = {"on_policy_n_envs_per_worker": 8, "on_policy_collected_frames_per_batch": 256,
         "on_policy_minibatch_size": 128, "max_n_frames": 512}  # fmt: skip
QUICK_HORIZON = 20.0
QUICK_TASKS = ("paper_speed", "acoustic_speed")


@dataclass(frozen=True)
class Cell:
    task: str
    algorithm: str
    seed: int

    @property
    def key(self) -> str:
        return f"{self.task}/{self.algorithm}/seed_{self.seed}"


def normalized_score(learned: float, reference: float, random: float) -> float:
    """``(R − R_random) / (R_reference − R_random)``: 0 for the random policy's return, 1 for the reference's.

    Raises:
        ValueError: the reference does not return more than the random policy (the scale is undefined).
    """
    if not reference > random:
        raise ValueError(f"the reference's return {reference!r} must exceed the random policy's {random!r}")
    return (learned - random) / (reference - random)


def _env_kwargs(task: Task, quick: bool) -> tuple[str, dict[str, Any]]:
    scenario, overrides = task.scenario()
    if quick:
        overrides["horizon"] = QUICK_HORIZON
    return scenario, overrides


def _evaluate(policy: Any, scenario: str, overrides: dict[str, Any], episodes: int) -> dict[str, Any]:
    """Mean return, success, final spread, final max |e| and Δa of ``policy`` on the benchmark seeds."""
    env = parallel_env(scenario, **overrides)
    metrics, _ = episode_reports(policy, env.config, benchmark_seeds(episodes))
    stats = summarize(metrics)
    return {
        "return": stats["return"]["mean"],
        "returns": [float(m["return"]) for m in metrics],
        "success": stats["success"]["mean"],
        "final_spread": stats["final_coordination_spread"]["mean"],
        "final_cross_track": stats["final_cross_track_max"]["mean"],
        "action_change": stats["action_change"]["mean"],
    }


def task_baselines(task: Task, episodes: int, quick: bool) -> dict[str, Any]:
    """The task's reference and random policy on the benchmark seeds (``_evaluate``)."""
    scenario, overrides = _env_kwargs(task, quick)
    env = parallel_env(scenario, **overrides)
    return {
        "reference": {"options": dict(task.reference), **_evaluate(ReferencePolicy(env, **dict(task.reference)),
                                                                  scenario, overrides, episodes)},
        "random": _evaluate(RandomPolicy(env, seed=0), scenario, overrides, episodes),
    }  # fmt: skip


def run_cell(cell: Cell, out: Path, episodes: int = EPISODES, quick: bool = False) -> dict[str, Any]:
    """Train and score one cell in a subprocess (``python -m benchmarks.suite train``) in ``out/TASK/ALGO/seed_S``.

    A run folder left by a killed cell is replaced. Returns the cell's record (``train_cell``).
    """
    folder = out / cell.key
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    command = [sys.executable, "-m", "benchmarks.suite", "train", "--task", cell.task, "--algorithm",
               cell.algorithm, "--seed", str(cell.seed), "--out", str(folder), "--episodes", str(episodes)]  # fmt: skip
    if quick:
        command.append("--quick")
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or [f"exit {done.returncode}"]
        raise RuntimeError(f"cell {cell.key} failed: {tail[0]}")
    return dict(json.loads((folder / "result.json").read_text()))


try:
    from benchmarl.experiment.callback import Callback
except ImportError:  # BenchMARL lives in the ecosystem environment; train_cell needs it, the rest does not
    Callback = object  # type: ignore[assignment,misc]


class TrainingCurve(Callback):  # type: ignore[misc,valid-type]
    """A BenchMARL callback: after each batch, the formation-steps so far and the mean return per vessel of
    the training episodes that ended in it (none ended: no point). At module level: BenchMARL pickles its
    callbacks with the experiment."""

    def __init__(self) -> None:
        super().__init__()
        self.formation_steps: list[float] = []
        self.returns: list[float] = []
        self.frames = 0

    def on_batch_collected(self, batch: Any) -> None:
        self.frames += int(batch.numel())
        done = batch.get(("next", "done")).squeeze(-1)
        if bool(done.any()):
            group = next(iter(self.experiment.group_map))
            self.formation_steps.append(float(self.frames))
            self.returns.append(float(batch.get(("next", group, "episode_reward"))[done].mean()))


def train_cell(cell: Cell, folder: Path, episodes: int = EPISODES, quick: bool = False) -> dict[str, Any]:
    """Train the cell with BenchMARL in this process, score it on the benchmark seeds and write
    ``folder/result.json``: the task, algorithm, seed, formation-steps, wall time, the ``learned`` policy's
    scores (``_evaluate``) and the training ``curve``. Returns the record."""
    import torch
    from benchmarl.algorithms import IppoConfig, MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from benchmarks.benchmarl_budget import BenchMARLPolicy, task_action_dim
    from marine_formation_env.benchmarl import MarineFormationTask

    torch.set_num_threads(1)
    task = TASKS[cell.task]
    scenario, overrides = _env_kwargs(task, quick)
    benchmarl_task = MarineFormationTask.__members__[cell.task.upper()].get_from_yaml()
    benchmarl_task.config.update({"scenario": scenario, "overrides": overrides})
    config = ExperimentConfig.get_from_yaml(str(ALGORITHM_CONFIGS / "experiment.yaml"))
    config.max_n_frames = task.budget
    for key, value in (QUICK if quick else {}).items():
        setattr(config, key, value)
    config.save_folder = str(folder)
    algorithm = {"mappo": MappoConfig, "ippo": IppoConfig}[cell.algorithm]
    model = MlpConfig.get_from_yaml(str(ALGORITHM_CONFIGS / "mlp.yaml"))
    curve = TrainingCurve()
    experiment = Experiment(
        task=benchmarl_task,
        algorithm_config=algorithm.get_from_yaml(str(ALGORITHM_CONFIGS / f"{cell.algorithm}.yaml")),
        model_config=model,
        critic_model_config=model,
        seed=cell.seed,
        config=config,
        callbacks=[curve],
    )
    begin = time.perf_counter()
    experiment.run()
    wall = time.perf_counter() - begin
    env = experiment.test_env
    group = next(iter(experiment.group_map))
    observation_dim = int(env.observation_spec[group, "observation"].shape[-1])
    n_agents = len(experiment.group_map[group])
    policy = BenchMARLPolicy(experiment.policy, group, n_agents, observation_dim, task_action_dim(env))
    record = {
        "task": cell.task,
        "algorithm": cell.algorithm,
        "seed": cell.seed,
        "formation_steps": int(experiment.total_frames),
        "wall_time_s": wall,
        "learned": _evaluate(policy, scenario, overrides, episodes),
        "curve": {"formation_steps": curve.formation_steps, "return": curve.returns},
    }
    atomic_write_text(folder / "result.json", json.dumps(record, indent=2, allow_nan=False) + "\n")
    return record


# ----------------------------------------------------------------------------- the table


def _read_results(path: Path) -> dict[str, Any]:
    if path.is_file():
        return dict(json.loads(path.read_text()))
    return {"description": "The learning benchmark's cells (docs/benchmark.md): per cell its record, commit, "
            "command and machine; per task its reference and random policy on the same seeds.",
            "tasks": {}, "cells": {}}  # fmt: skip


def _write_results(path: Path, results: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(results, indent=2, allow_nan=False) + "\n")


def run_table(
    cells: Sequence[Cell],
    out: Path,
    results_path: Path,
    command: str,
    *,
    episodes: int = EPISODES,
    quick: bool = False,
    address: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the cells the results file does not hold yet, adding each to it as it finishes; returns the file's
    contents. Each task's reference and random policy are evaluated once (kept in the file). With ``address``
    the cells run as Ray tasks on that cluster (``baselines.ray_cluster.connect``), one CPU each, and this
    process writes the results file as they finish."""
    source = provenance(command)  # the code as it is when the run starts: every cell trains with it
    results = _read_results(results_path)
    for name in sorted({cell.task for cell in cells}):
        if name not in results["tasks"]:
            budget = QUICK["max_n_frames"] if quick else TASKS[name].budget
            results["tasks"][name] = {"budget": budget, "episodes": episodes,
                                      **task_baselines(TASKS[name], episodes, quick),
                                      "provenance": source}  # fmt: skip
            _write_results(results_path, results)
    todo = [cell for cell in cells if cell.key not in results["cells"]]
    bar = _bar(len(cells), len(cells) - len(todo), progress)

    def finished(record: dict[str, Any]) -> None:
        key = Cell(record["task"], record["algorithm"], record["seed"]).key
        results["cells"][key] = {**record, "provenance": source}
        _write_results(results_path, results)
        if bar is not None:
            bar.update(1)

    if address is None:
        for cell in todo:
            finished(run_cell(cell, out, episodes, quick))
    else:
        ray = connect(address)
        remote = ray.remote(num_cpus=1)(run_cell)
        pending = [remote.remote(cell, out, episodes, quick) for cell in todo]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            finished(ray.get(ready[0]))
    if bar is not None:
        bar.close()
    return results


def _bar(total: int, done: int, progress: bool) -> Any:
    if not progress:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, initial=done, desc="cells", unit="cell", file=sys.stderr)


# ----------------------------------------------------------------------------- the report


def _pm(values: Sequence[float], fmt: str = ".2f") -> str:
    """``mean ± sample std`` of ``values`` (``± 0`` for one value)."""
    spread = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
    return f"{np.mean(values):{fmt}} ± {spread:{fmt}}"


def scores(results: dict[str, Any]) -> dict[str, np.ndarray]:
    """Per algorithm, the normalized scores ``(seeds, tasks)`` of the cells the results file holds: the seeds
    every task of the algorithm has, the tasks in the order of ``TASKS``."""
    out: dict[str, np.ndarray] = {}
    for algorithm in ALGORITHMS:
        cells = [c for c in results["cells"].values() if c["algorithm"] == algorithm]
        tasks = [t for t in TASKS if any(c["task"] == t for c in cells)]
        if not tasks:
            continue
        seeds = sorted(set.intersection(*({c["seed"] for c in cells if c["task"] == t} for t in tasks)))
        table = np.empty((len(seeds), len(tasks)))
        for k, seed in enumerate(seeds):
            for j, name in enumerate(tasks):
                cell = results["cells"][Cell(name, algorithm, seed).key]
                base = results["tasks"][name]
                table[k, j] = normalized_score(cell["learned"]["return"], base["reference"]["return"],
                                               base["random"]["return"])  # fmt: skip
        out[algorithm] = table
    return out


def aggregate(table: dict[str, np.ndarray], reps: int = 2000, seed: int = 0) -> dict[str, Any]:
    """rliable's interquartile mean with 95 % stratified-bootstrap confidence intervals per algorithm, and the
    probability that the first algorithm improves on the second (with its interval)."""
    from rliable import library as rly
    from rliable import metrics

    # rliable's stratified bootstrap draws its indices from numpy's global generator; the one for two
    # independent samples (the probability of improvement) from arch's, given as a RandomState
    np.random.seed(seed)  # noqa: NPY002
    iqm, intervals = rly.get_interval_estimates(table, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=reps)
    out: dict[str, Any] = {
        name: {"iqm": float(iqm[name][0]), "ci": [float(intervals[name][0, 0]), float(intervals[name][1, 0])],
               "runs": int(table[name].size)}
        for name in table
    }  # fmt: skip
    names = list(table)
    if len(names) == 2 and table[names[0]].shape == table[names[1]].shape:
        pair = {f"{names[0]},{names[1]}": (table[names[0]], table[names[1]])}
        with warnings.catch_warnings():  # arch prefers a Generator to the RandomState rliable passes on
            warnings.simplefilter("ignore", FutureWarning)
            prob, prob_ci = rly.get_interval_estimates(
                pair, metrics.probability_of_improvement, reps=reps, random_state=np.random.RandomState(seed)
            )
        key = next(iter(pair))
        low, high = np.ravel(prob_ci[key])
        out["probability_of_improvement"] = {"pair": key, "value": float(np.ravel(prob[key])[0]),
                                             "ci": [float(low), float(high)]}  # fmt: skip
    return out


def format_report(results: dict[str, Any], summary: dict[str, Any]) -> str:
    """The markdown tables of ``report``: per task and algorithm the score, success and final spread over its
    seeds (mean ± sample std), and the aggregates."""
    lines = ["| task | budget [formation-steps] | reference return, success | random return | "
             + " | ".join(f"{a} score (seeds) | {a} success | {a} final spread [m]" for a in ALGORITHMS) + " |",
             "|---|---|---|---|" + "---|---|---|" * len(ALGORITHMS)]  # fmt: skip
    for name, base in results["tasks"].items():
        cells = []
        for algorithm in ALGORITHMS:
            mine = [c for c in results["cells"].values() if c["task"] == name and c["algorithm"] == algorithm]
            if not mine:
                cells += ["–", "–", "–"]
                continue
            values = [normalized_score(c["learned"]["return"], base["reference"]["return"], base["random"]["return"])
                      for c in mine]  # fmt: skip
            success = _pm([100 * c["learned"]["success"] for c in mine], ".0f")
            cells += [
                f"{_pm(values)} ({len(values)})",
                f"{success} %",
                _pm([c["learned"]["final_spread"] for c in mine], ".2g"),
            ]
        reference = f"{base['reference']['return']:.1f}, {base['reference']['success']:.0%}"
        lines.append(f"| `{name}` | {base['budget']:.3g} | {reference} | {base['random']['return']:.1f} | "
                     + " | ".join(cells) + " |")  # fmt: skip
    lines += ["", "| algorithm | IQM of the score | 95 % CI | runs |", "|---|---|---|---|"]
    for name in ALGORITHMS:
        if name in summary:
            s = summary[name]
            lines.append(f"| {name} | {s['iqm']:.2f} | [{s['ci'][0]:.2f}, {s['ci'][1]:.2f}] | {s['runs']} |")
    if "probability_of_improvement" in summary:
        p = summary["probability_of_improvement"]
        first, second = p["pair"].split(",")
        lines += ["", f"P({first} > {second}) = {p['value']:.2f} [{p['ci'][0]:.2f}, {p['ci'][1]:.2f}] (95 % CI)"]
    return "\n".join(lines)


def plot_report(results: dict[str, Any], table: dict[str, np.ndarray], path: Path) -> None:
    """Three panels: the performance profile of each algorithm (with 95 % CI bands), the IQM with its CI, and
    the sample-efficiency curves (IQM of the normalized training return against formation-steps)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from rliable import library as rly
    from rliable import metrics

    fig = Figure(figsize=(15, 4.2), dpi=110)
    FigureCanvasAgg(fig)
    profile, bars, curves = fig.subplots(1, 3)
    taus = np.linspace(-0.25, 1.5, 71)
    # rliable's performance profile takes no generator: its bootstrap draws from numpy's global one
    np.random.seed(0)  # noqa: NPY002
    distributions, cis = rly.create_performance_profile(table, taus)
    for name in table:
        profile.plot(taus, distributions[name], label=name)
        profile.fill_between(taus, cis[name][0], cis[name][1], alpha=0.2)
    profile.set(xlabel="normalized score τ", ylabel="fraction of runs with score > τ", title="performance profile")
    profile.axvline(1.0, color="grey", lw=0.8, ls="--")
    profile.legend()
    summary = aggregate(table)
    names = [n for n in ALGORITHMS if n in summary]
    for k, name in enumerate(names):
        low, high = summary[name]["ci"]
        bars.barh(k, high - low, left=low, height=0.5, alpha=0.6)
        bars.plot([summary[name]["iqm"]] * 2, [k - 0.25, k + 0.25], color="black")
    bars.set(yticks=range(len(names)), yticklabels=names, xlabel="IQM of the normalized score (95 % CI)",
             title="aggregate over tasks and seeds")  # fmt: skip
    bars.axvline(1.0, color="grey", lw=0.8, ls="--")
    grid = np.linspace(0.0, 1.0, 21)  # fraction of each task's budget
    for name in names:
        runs = []
        for seed in sorted({c["seed"] for c in results["cells"].values() if c["algorithm"] == name}):
            per_task = []
            for task, base in results["tasks"].items():
                cell = results["cells"].get(Cell(task, name, seed).key)
                if cell is None or len(cell["curve"]["return"]) < 2:
                    break
                x = np.asarray(cell["curve"]["formation_steps"]) / base["budget"]
                y = [normalized_score(r, base["reference"]["return"], base["random"]["return"])
                     for r in cell["curve"]["return"]]  # fmt: skip
                per_task.append(np.interp(grid, x, y))
            else:
                runs.append(per_task)
        if not runs:
            continue
        data = {name: np.asarray(runs)}  # (seeds, tasks, points)
        iqm, ci = rly.get_interval_estimates(
            data,
            lambda s: np.array([metrics.aggregate_iqm(s[..., k]) for k in range(s.shape[-1])]),
            reps=500,
        )
        curves.plot(grid, iqm[name], label=name)
        curves.fill_between(grid, ci[name][0], ci[name][1], alpha=0.2)
    if curves.lines:
        curves.legend()
    curves.set(xlabel="fraction of the task's budget [formation-steps]", ylabel="IQM of the normalized training return",
               title="sample efficiency (training episodes)")  # fmt: skip
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")


#: The markers between which ``report --document`` puts its tables.
MARKERS = ("<!-- benchmark-results:start -->", "<!-- benchmark-results:end -->")


def put_between_markers(document: Path, text: str) -> None:
    """Replace what stands between ``MARKERS`` in ``document`` with ``text`` (the rest is kept).

    Raises:
        ValueError: the document lacks the markers (names the file).
    """
    content = document.read_text()
    if MARKERS[0] not in content or MARKERS[1] not in content:
        raise ValueError(f"--document {document}: no {MARKERS[0]} ... {MARKERS[1]} markers")
    head, rest = content.split(MARKERS[0], 1)
    _, tail = rest.split(MARKERS[1], 1)
    atomic_write_text(document, f"{head}{MARKERS[0]}\n{text}{MARKERS[1]}{tail}")


# ----------------------------------------------------------------------------- command line


def _cells(tasks: Sequence[str], algorithms: Sequence[str], seeds: Sequence[int]) -> list[Cell]:
    return [Cell(t, a, s) for s in seeds for t in tasks for a in algorithms]  # seed-major: load falls alike


def _names(text: str, known: Sequence[str], flag: str) -> list[str]:
    names = [item.strip() for item in text.split(",") if item.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f"{flag}: unknown {unknown or text!r}; choose from {list(known)}")
    return names


def main(argv: Sequence[str] | None = None) -> int:
    prog = "python -m benchmarks.suite"
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("cell", "table"):
        p = sub.add_parser(name, help="run one cell" if name == "cell" else "run every cell not yet in the results")
        if name == "cell":
            p.add_argument("--task", required=True, choices=list(TASKS))
            p.add_argument("--algorithm", required=True, choices=list(ALGORITHMS))
            p.add_argument("--seed", type=int_at_least(0), required=True)
        else:
            p.add_argument("--tasks", default=",".join(TASKS), help="comma-separated (default every task)")
            p.add_argument("--algorithms", default=",".join(ALGORITHMS), help="comma-separated (default both)")
            p.add_argument("--seeds", default=",".join(map(str, SEEDS)), help="training seeds (default 0-4)")
            p.add_argument("--address", default=None, help="a Ray cluster (HOST:PORT, auto or local): cells as tasks")
        p.add_argument("--out", type=Path, default=Path("runs/suite"), help="the cells' run folders")
        p.add_argument("--results", type=Path, default=RESULTS, help="the results file (added to, never replaced)")
        p.add_argument("--episodes", type=int_at_least(1), default=EPISODES, help="scoring episodes per policy")
        p.add_argument("--quick", action="store_true", help="tiny budgets and episodes: the pipeline in seconds")
        p.add_argument("--quiet", action="store_true", help="no progress bar")
    train = sub.add_parser("train", help="train and score one cell in this process (what cell and table run)")
    train.add_argument("--task", required=True, choices=list(TASKS))
    train.add_argument("--algorithm", required=True, choices=list(ALGORITHMS))
    train.add_argument("--seed", type=int_at_least(0), required=True)
    train.add_argument("--out", type=Path, required=True, help="the cell's run folder")
    train.add_argument("--episodes", type=int_at_least(1), default=EPISODES)
    train.add_argument("--quick", action="store_true")
    report = sub.add_parser("report", help="tables and figures from the results file")
    report.add_argument("--results", type=Path, default=RESULTS)
    report.add_argument("--figure", type=Path, default=ROOT / "docs" / "benchmark.png")
    report.add_argument("--document", type=Path, default=None, help="also put the tables between its markers")
    args = parser.parse_args(argv)
    command = command_line(prog, argv)
    try:
        if args.command == "train":
            train_cell(Cell(args.task, args.algorithm, args.seed), args.out, args.episodes, args.quick)
            return 0
        if args.command == "report":
            results = _read_results(args.results)
            if not results["cells"]:
                parser.error(f"--results {args.results}: no cells yet (run the table first)")
            table = scores(results)
            text = format_report(results, aggregate(table))
            print(text)
            plot_report(results, table, args.figure)
            if args.document is not None:
                put_between_markers(args.document, f"`{command}`\n\n{text}\n")
            return 0
        if args.quick and args.results == RESULTS:
            parser.error("--quick writes a results file of its own: pass --results (not the shipped one)")
        if args.command == "cell":
            cells = [Cell(args.task, args.algorithm, args.seed)]
        else:
            quick_tasks = ",".join(QUICK_TASKS) if args.quick and args.tasks == ",".join(TASKS) else args.tasks
            cells = _cells(_names(quick_tasks, list(TASKS), "--tasks"),
                           _names(args.algorithms, ALGORITHMS, "--algorithms"), parse_seeds(args.seeds))  # fmt: skip
        run_table(cells, args.out, args.results, command, episodes=args.episodes, quick=args.quick,
                  address=getattr(args, "address", None), progress=not args.quiet)  # fmt: skip
    except (ValueError, RuntimeError, ImportError, ConnectionError) as err:
        parser.error(str(err))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
