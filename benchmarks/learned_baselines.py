"""The learned baselines, regenerated: train every row over seeds, evaluate next to the reference, write the table.

One row per setting of the learning issue; each trains with its shipped
config for its wall-clock budget on this machine, once per ``--seeds``, in
its own process (one after the other, so no two compete for the cores), and
is then evaluated deterministically by the engine of ``baselines.evaluate``
on ``--episodes`` seeds (10 000 +) next to the paper's controller (and, over
a lossy channel, the controller that extrapolates stale messages)::

    # the whole table (hours): docs/results.md, the figures, the pretrained policies
    python -m benchmarks.learned_baselines --seeds 0,1,2 --publish
    # a smoke run of two rows: every budget 0.2 min, 2 evaluation episodes, nothing published
    python -m benchmarks.learned_baselines --rows paper_speed,survey_speed --seeds 0 --minutes 0.2 --episodes 2

=====================  =======  =====================================================
row                    budget   config (``training/configs/``)
=====================  =======  =====================================================
``paper_speed``        15 min   ``torchrl/paper_speed_mappo.yaml`` (TorchRL MAPPO)
``paper_guidance``     30 min   ``torchrl/paper_guidance_mappo.yaml`` (TorchRL MAPPO)
``paper_force``        60 min   ``torchrl/paper_force_mappo.yaml`` (TorchRL MAPPO)
``acoustic_speed``     30 min   ``acoustic_speed_ppo.yaml`` (SB3 PPO, slot network)
``acoustic_guidance``  30 min   ``acoustic_guidance_ppo.yaml`` (SB3 PPO, slot network)
``survey_speed``       30 min   ``torchrl/survey_speed_mappo.yaml`` (TorchRL MAPPO)
``any_n_speed``        30 min   ``any_n_speed_ppo.yaml`` (SB3 PPO, slot network, teams of 3–6)
=====================  =======  =====================================================

The budgets of ``paper_*`` and ``survey_speed`` are the learning issue's; it
gives none for the ``acoustic`` and ``any_n`` rows, which get 30 minutes.
``any_n_speed`` is evaluated not on its training teams but, without
retraining, on teams of 8, 12 and 20 vessels on ``ring``, ``chain`` and
``random`` graphs (one sub-row each; its row is their mean, and its target
holds when every sub-row's does).

Per row the table gives, as mean ± sample standard deviation over the
training seeds (each seed's number is the mean over the evaluation
episodes): the learned return and the reference's, ``performance`` =
R_reference / R_learned (≥ 0.9 is the target; returns are ≤ 0), the success
rates, and the mean absolute action change per step Δa of both (smoothness:
the learned one's must stay within 3× the reference's at ``speed``). Rows
over a lossy channel also give the extrapolating reference, whose return and
a 90 % success are their target. Every seed counts: no seed is dropped or
picked.

Everything goes to ``--out`` (default ``runs/learned_baselines``):
``ROW/seed_S/`` run folders, ``learned_baselines.json`` (every run and every
row's summary, rewritten atomically after each run), ``learning_curves.png``
(per row the mean and the min–max over seeds of the training episodes'
return against wall-clock minutes, the reference's evaluation return as a
line) and ``episodes/ROW.png`` (one evaluation episode per row, the learned
policy of the first seed beside the reference). A run whose folder already
holds its evaluation (``result.json``) is not trained again, so an
interrupted regeneration continues where it stopped; ``--fresh`` retrains.

``--publish`` (full budgets only) also writes the rows' lines of the table,
each with the commit (and, when its runs trained on another, that one), the
machine and the command, into ``docs/results.md``
(between the ``learned-baselines`` markers; rows published before and not
run this time stay as they were, so the table can be regenerated one row at
a time, ``--rows paper_guidance --publish``), each row's learning curves
into ``docs/learning_curves/ROW.png`` and its episode into
``docs/episodes/ROW.png``, and each row's policy of the first seed (not the
best: the rule is fixed before the results are seen) into
``baselines/pretrained/ROW.npz``, described by its setting, learner, budget
and seed; its header's training commit is the one the run trained with
(``result.json`` keeps it; ``unknown`` for a result written before it did),
which can be older than the publishing commit.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from baselines.engine import episode_reports
from baselines.plots import plot_comparison
from baselines.pretrained import load_pretrained
from baselines.reference import ReferencePolicy
from baselines.seeds import evaluation_seeds
from benchmarks.training_throughput import parse_seeds
from marine_formation_env.atomic import atomic_path, atomic_write_text
from marine_formation_env.cli import ArgumentParser, int_at_least
from marine_formation_env.env import parallel_env
from marine_formation_env.provenance import command_line, machine, provenance
from marine_formation_env.provenance import commit as git_commit
from marine_formation_env.scenarios import make_config
from training.export import export_run
from training.learned import load_learned_policy, member_metrics

__all__ = ["ROWS", "Row", "format_table", "main", "row_summary", "run_row_seed"]

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "training" / "configs"
#: Where ``--publish`` writes results.md and the figures.
DOCS = ROOT / "docs"
MARKERS = ("<!-- learned-baselines:start -->", "<!-- learned-baselines:end -->")
#: The targets a row is judged on (module docstring).
PERFORMANCE_TARGET, SUCCESS_TARGET, CHANNEL_SUCCESS_TARGET, SMOOTHNESS_TARGET = 0.9, 0.8, 0.9, 3.0


@dataclass(frozen=True)
class Row:
    """One row of the table: a setting, its budget and the config that trains it."""

    name: str
    minutes: float
    config: str  # relative to training/configs; torchrl/… runs training.torchrl_ppo, the rest training.train
    note: str = ""
    #: (team size, topology) pairs it is evaluated on instead of its training scenario (a policy for any team)
    generalization: tuple[tuple[int, str], ...] = ()

    @property
    def pipeline(self) -> str:
        return "torchrl" if self.config.startswith("torchrl/") else "sb3"

    @property
    def path(self) -> Path:
        return CONFIGS / self.config


#: The rows, in the order of the table.
ROWS: dict[str, Row] = {
    row.name: row
    for row in (
        Row("paper_speed", 15.0, "torchrl/paper_speed_mappo.yaml"),
        Row("paper_guidance", 30.0, "torchrl/paper_guidance_mappo.yaml"),
        Row("paper_force", 60.0, "torchrl/paper_force_mappo.yaml"),
        Row("acoustic_speed", 30.0, "acoustic_speed_ppo.yaml"),
        Row("acoustic_guidance", 30.0, "acoustic_guidance_ppo.yaml"),
        Row("survey_speed", 30.0, "torchrl/survey_speed_mappo.yaml"),
        Row(
            "any_n_speed",
            30.0,
            "any_n_speed_ppo.yaml",
            "one policy for any team size",
            tuple((n, topology) for n in (8, 12, 20) for topology in ("ring", "chain", "random")),
        ),
    )
}
#: Settings of a team's training scenario that a generalization row replaces.
TEAM_KEYS = ("n_vessels", "topology", "topology_seed", "observation_slots", "formation", "initial_state")


def _train_command(row: Row, seed: int, minutes: float, folder: Path) -> list[str]:
    here = sys.executable
    if row.pipeline == "torchrl":
        return [here, "-m", "training.torchrl_ppo", "--config", str(row.path), "--set", f"minutes={minutes}",
                "--set", "total_frames=1e12", "--set", "eval_episodes=1", "--seed", str(seed), "--out", str(folder),
                "--overwrite", "--no-progress"]  # fmt: skip
    return [here, "-m", "benchmarks.learning", "--config", str(row.path), "--minutes", str(minutes),
            "--seed", str(seed), "--episodes", "1", "--out", str(folder), "--quiet"]  # fmt: skip


def _scenario_of(folder: Path) -> tuple[str, dict[str, Any]]:
    _, config = load_learned_policy(folder)
    return config["scenario"], dict(config["env_kwargs"])


def _run_config(folder: Path) -> dict[str, Any]:
    """The run's ``config.yaml`` (``{}`` if it has none)."""
    path = folder / "config.yaml"
    if not path.is_file():
        return {}
    config = yaml.safe_load(path.read_text()) or {}
    return dict(config)


def _shaping(folder: Path) -> dict[str, Any]:
    """The reward fields the run's learner trained on: its ``train_reward`` (``{}`` for none, or a pipeline
    without one)."""
    return dict(_run_config(folder).get("train_reward") or {})


def evaluate_folder(folder: Path, episodes: int, row: Row | None = None) -> dict[str, Any]:
    """The run's policy, the reference (and the extrapolating reference over a lossy channel) on the same seeds.

    A row with ``generalization`` settings runs its policy (exported as a numpy network, which takes any
    number of slots) on each of them instead; ``learned`` and ``reference`` are then the means over them.
    """
    policy, config = load_learned_policy(folder)
    if row is None or not row.generalization:
        env = parallel_env(config["scenario"], **config["env_kwargs"])
        return _evaluate_members(policy, env, episodes)

    export_run(folder, row.name, row.note, folder / "exported")
    portable, _ = load_pretrained(row.name, folder / "exported")
    base = {k: v for k, v in config["env_kwargs"].items() if k not in TEAM_KEYS}
    settings = {}
    for n, topology in row.generalization:
        env = parallel_env(config["scenario"], **base, n_vessels=n, topology=topology)
        settings[f"n{n}_{topology}"] = _evaluate_members(portable, env, episodes)
    first = next(iter(settings.values()))
    out: dict[str, Any] = {"seeds": first["seeds"], "settings": settings}
    for member in ("learned", "reference"):
        out[member] = {
            key: float(np.mean([s[member][key] for s in settings.values()]))
            for key in ("return", "success", "action_change", "final_spread")
        }
    return out


def _evaluate_members(policy: Any, env: Any, episodes: int) -> dict[str, Any]:
    seeds = evaluation_seeds(episodes)
    policies: dict[str, Any] = {"learned": policy, "reference": ReferencePolicy(env)}
    if not env.config.ideal_observations:
        policies["reference_extrapolate"] = ReferencePolicy(env, extrapolate=True)
    return {"seeds": seeds, **member_metrics(policies, env.config, seeds)}


def run_row_seed(row: Row, seed: int, minutes: float, episodes: int, out: Path, fresh: bool) -> dict[str, Any]:
    """Train (unless done before) and evaluate one row with one seed; its record (also ``result.json``)."""
    folder = out / row.name / f"seed_{seed}"
    result = folder / "result.json"
    if result.is_file() and not fresh:
        record: dict[str, Any] = json.loads(result.read_text())
        if record.get("minutes") == minutes and record.get("episodes") == episodes:
            return record
    if folder.exists():  # an earlier, unfinished or other-budget run of this row and seed: start clean
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    commit = git_commit()  # the code it trains with: a later --publish may run on a later commit
    begin = time.perf_counter()
    done = subprocess.run(_train_command(row, seed, minutes, folder), cwd=ROOT, capture_output=True, text=True)
    atomic_write_text(folder / "train.log", done.stdout + "\n--- stderr ---\n" + done.stderr)
    if done.returncode != 0:
        return {"row": row.name, "seed": seed, "failed": f"exit {done.returncode}; see {folder / 'train.log'}"}
    record = {
        "row": row.name,
        "seed": seed,
        "pipeline": row.pipeline,
        "config": row.config,
        "commit": commit,
        "minutes": minutes,
        "episodes": episodes,
        "wall_seconds": round(time.perf_counter() - begin, 1),
        **evaluate_folder(folder, episodes, row),
    }
    atomic_write_text(result, json.dumps(record, indent=2) + "\n")
    return record


def _stats(values: list[float]) -> dict[str, Any]:
    """Mean, sample standard deviation (0 for one value), min, max and the values."""
    array = np.asarray(values, dtype=float)
    std = float(array.std(ddof=1)) if len(array) > 1 else 0.0
    return {"mean": float(array.mean()), "std": std, "min": float(array.min()), "max": float(array.max()),
            "per_seed": [float(v) for v in array]}  # fmt: skip


def row_summary(row: Row, records: list[dict[str, Any]]) -> dict[str, Any]:
    """Over the row's finished seeds: each measure's statistics and whether the targets hold (module docstring)."""
    ok = [r for r in records if "learned" in r]
    summary: dict[str, Any] = {"row": row.name, "pipeline": row.pipeline, "seeds": [r["seed"] for r in ok]}
    failed = {str(r["seed"]): r["failed"] for r in records if "failed" in r}
    if failed:
        summary["failed"] = failed
    if not ok:
        return summary
    members = [m for m in ("learned", "reference", "reference_extrapolate") if m in ok[0]]
    for member in members:
        summary[member] = {key: _stats([r[member][key] for r in ok]) for key in ("return", "success", "action_change")}
    _judge(row, summary, ok)
    if row.generalization and all("settings" in r for r in ok):
        summary["settings"] = {}
        for key in ok[0]["settings"]:
            part = [{**r["settings"][key], "seed": r["seed"]} for r in ok]
            sub: dict[str, Any] = {m: {k: _stats([p[m][k] for p in part]) for k in ("return", "success",
                                   "action_change")} for m in ("learned", "reference")}  # fmt: skip
            _judge(row, sub, part)
            summary["settings"][key] = sub
        summary["target_met"] = all(sub["target_met"] for sub in summary["settings"].values())
        summary["smoothness_met"] = all(sub["smoothness_met"] for sub in summary["settings"].values())
    return summary


def _judge(row: Row, summary: dict[str, Any], ok: list[dict[str, Any]]) -> None:
    """Add ``performance``, ``smoothness_ratio``, ``target_met`` (and ``smoothness_met`` at speed) to ``summary``."""
    performance = _stats([r["reference"]["return"] / r["learned"]["return"] for r in ok])
    smoothness = _stats([r["learned"]["action_change"] / max(r["reference"]["action_change"], 1e-12) for r in ok])
    summary["performance"], summary["smoothness_ratio"] = performance, smoothness
    success = summary["learned"]["success"]["mean"]
    if "reference_extrapolate" in summary:
        beaten = summary["learned"]["return"]["mean"] >= summary["reference_extrapolate"]["return"]["mean"]
        summary["target_met"] = bool(success >= CHANNEL_SUCCESS_TARGET and beaten)
    else:
        summary["target_met"] = bool(performance["mean"] >= PERFORMANCE_TARGET and success >= SUCCESS_TARGET)
    if row.name.endswith("_speed"):
        summary["smoothness_met"] = bool(smoothness["mean"] <= SMOOTHNESS_TARGET)


def _pm(stats: dict[str, Any] | None, fmt: str) -> str:
    if stats is None:
        return "–"
    return fmt.format(stats["mean"]) + (f" ± {fmt.format(stats['std'])}" if len(stats["per_seed"]) > 1 else "")


def format_table(summaries: list[dict[str, Any]], budgets: dict[str, float]) -> str:
    """The markdown table of the rows."""
    lines = [
        "| row | pipeline | minutes | seeds | learned return | reference return | performance | success learned "
        "/ reference | Δa learned / reference | extrapolating reference return, success | target |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summaries:
        if "learned" not in s:
            lines.append(f"| `{s['row']}` | {s['pipeline']} | {budgets[s['row']]:g} | – | failed: {s.get('failed')} "
                         "| | | | | | |")  # fmt: skip
            continue
        learned, reference = s["learned"], s["reference"]
        extra = s.get("reference_extrapolate")
        channel = f"{_pm(extra['return'], '{:.1f}')}, {_pm(extra['success'], '{:.0%}')}" if extra else "–"
        target = "met" if s["target_met"] else "not met"
        if "smoothness_met" in s:
            target += ", smooth" if s["smoothness_met"] else ", not smooth"
        lines.append(
            f"| `{s['row']}` | {s['pipeline']} | {budgets[s['row']]:g} | {len(s['seeds'])} "
            f"| {_pm(learned['return'], '{:.1f}')} | {_pm(reference['return'], '{:.1f}')} "
            f"| {_pm(s['performance'], '{:.2f}')} "
            f"| {_pm(learned['success'], '{:.0%}')} / {_pm(reference['success'], '{:.0%}')} "
            f"| {_pm(learned['action_change'], '{:.3g}')} / {_pm(reference['action_change'], '{:.3g}')} "
            f"| {channel} | {target} |"
        )
        for key, sub in s.get("settings", {}).items():
            size, topology = key[1:].split("_", 1)
            mark = "met" if sub["target_met"] else "not met"
            mark += ", smooth" if sub["smoothness_met"] else ", not smooth"
            lines.append(
                f"| ↳ n = {size}, `{topology}` | | | "
                f"| {_pm(sub['learned']['return'], '{:.1f}')} | {_pm(sub['reference']['return'], '{:.1f}')} "
                f"| {_pm(sub['performance'], '{:.2f}')} "
                f"| {_pm(sub['learned']['success'], '{:.0%}')} / {_pm(sub['reference']['success'], '{:.0%}')} "
                f"| {_pm(sub['learned']['action_change'], '{:.3g}')} / "
                f"{_pm(sub['reference']['action_change'], '{:.3g}')} | – | {mark} |"
            )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- figures


def _curve(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(minutes, training episode return) of a run folder's ``progress.csv`` (rows without episodes dropped)."""
    path = folder / "progress.csv"
    if not path.is_file():
        return np.zeros(0), np.zeros(0)
    with path.open(newline="") as handle:
        rows = [r for r in csv.DictReader(handle) if r.get("episode_return_mean") not in (None, "")]
    minutes = np.array([float(r["wall_time_s"]) / 60.0 for r in rows])
    return minutes, np.array([float(r["episode_return_mean"]) for r in rows])


def plot_learning_curves(rows: list[Row], records: list[dict[str, Any]], out: Path, path: Path) -> None:
    """Per row: the mean and the min–max over seeds of the training episodes' return, the reference as a line.

    A row whose runs trained on a shaped reward (``train_reward``) has no reference line: its curve is in that
    reward, not the benchmark's.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = min(3, len(rows))
    nrows = -(-len(rows) // cols)
    fig = Figure(figsize=(5.0 * cols, 3.6 * nrows), dpi=100)
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(nrows, cols, squeeze=False)).ravel()
    any_reference = False
    for ax, row in zip(axes, rows, strict=False):
        mine = [r for r in records if r.get("row") == row.name and "learned" in r]
        # a run trained on a shaped reward logs that reward, which the reference's return does not measure
        shaped = any(_shaping(out / row.name / f"seed_{r['seed']}") for r in mine)
        curves = [_curve(out / row.name / f"seed_{r['seed']}") for r in mine]
        curves = [(t, y) for t, y in curves if len(t) > 1]
        if curves:
            end = min(t[-1] for t, _ in curves)
            grid = np.linspace(0.0, end, 100)
            grid = grid[grid >= max(t[0] for t, _ in curves)]
            ys = np.array([np.interp(grid, t, y) for t, y in curves])
            ax.fill_between(grid, ys.min(axis=0), ys.max(axis=0), alpha=0.25, color="C0", lw=0)
            label = f"learned, mean of {len(curves)} seeds (min–max)" if len(curves) > 1 else "learned, one seed"
            ax.plot(grid, ys.mean(axis=0), color="C0", label=label)
        if mine and not shaped:
            any_reference = True
            ax.axhline(np.mean([r["reference"]["return"] for r in mine]), color="k", ls="--", label="reference")
            if "reference_extrapolate" in mine[0]:
                value = np.mean([r["reference_extrapolate"]["return"] for r in mine])
                ax.axhline(value, color="C2", ls=":", label="extrapolating reference")
        ax.set_title(f"{row.name}\n(shaped training reward: no reference line)" if shaped else row.name, fontsize=10)
        ax.set_xlabel("wall-clock minutes")
        ax.set_ylabel("episode return in the training reward" if shaped else "episode return")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    for ax in axes[len(rows) :]:
        ax.set_visible(False)
    title = "Training episodes' return (stochastic policy)"
    if any_reference:
        title += ("\n" if cols == 1 else " ") + "against the reference's evaluation return"
    fig.suptitle(title, fontsize=10 if cols > 1 else 9)
    fig.tight_layout()
    _save_figure(fig, path)


def plot_episode(row: Row, record: dict[str, Any], out: Path, path: Path) -> None:
    """One evaluation episode (the first seed) of the row's learned policy beside the reference.

    A generalization row shows its largest team on its first graph (20 vessels on a ring), run by the exported
    numpy network.
    """
    folder = out / row.name / f"seed_{record['seed']}"
    policy, config = load_learned_policy(folder)
    env = parallel_env(config["scenario"], **config["env_kwargs"])
    if row.generalization:
        policy, _ = load_pretrained(row.name, folder / "exported")
        n, topology = max(row.generalization, key=lambda pair: pair[0])
        base = {k: v for k, v in config["env_kwargs"].items() if k not in TEAM_KEYS}
        env = parallel_env(config["scenario"], **base, n_vessels=n, topology=topology)
    seeds = record["seeds"][:1]
    _, learned = episode_reports(policy, env.config, seeds)
    _, reference = episode_reports(ReferencePolicy(env), env.config, seeds)
    title = f"{row.name}: learned (training seed {record['seed']}) and reference, evaluation seed {seeds[0]}"
    plot_comparison({"learned": learned[0], "reference": reference[0]}, env.config, path, title=title)


def _save_figure(fig: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip("."))


# ----------------------------------------------------------------------------- publishing


def _split_table(lines: Sequence[str]) -> tuple[list[str], dict[str, list[str]]]:
    """The header lines of a ``format_table`` table and, per row name, its line and its sub-rows' lines."""
    header: list[str] = []
    rows: dict[str, list[str]] = {}
    current = None
    for line in lines:
        if line.startswith("| `"):
            current = line.split("`", 2)[1]
            rows[current] = [line]
        elif line.startswith("| ↳") and current is not None:
            rows[current].append(line)
        elif line.startswith("|"):
            header.append(line)
    return header, rows


def publish_markdown(table: str, provenance: dict[str, str], document: Path) -> None:
    """Put the rows of ``table`` between the ``learned-baselines`` markers of ``document`` (appended if missing).

    Each row published gets ``provenance[row]`` (the commit, the machine, the command) as its line under the
    table and its learning curves figure (``learning_curves/ROW.png``, beside the document) below. Rows
    already in the document and not in ``table`` stay as they were, with their own provenance: the table can
    be regenerated one row at a time. Rows are in the order of ``ROWS``.
    """
    text = document.read_text() if document.is_file() else ""
    old: list[str] = []
    if MARKERS[0] in text and MARKERS[1] in text:
        head, rest = text.split(MARKERS[0], 1)
        inside, tail = rest.split(MARKERS[1], 1)
        old = inside.splitlines()
    else:
        head, tail = text.rstrip("\n") + "\n\n", "\n"
    _, rows = _split_table(old)
    sources = {line.split("`", 2)[1]: line.split("`: ", 1)[1] for line in old if line.startswith("- `")}
    header, new_rows = _split_table(table.splitlines())
    rows.update(new_rows)
    sources.update({name: provenance[name] for name in new_rows})
    order = sorted(rows, key=lambda name: list(ROWS).index(name) if name in ROWS else len(ROWS))
    lines = [MARKERS[0], *header, *(line for name in order for line in rows[name]), ""]
    lines += [f"- `{name}`: {sources[name]}" for name in order if name in sources]
    lines.append("")
    for name in order:
        lines += [f"![{name}: learning curves](learning_curves/{name}.png)", ""]
    atomic_write_text(document, head + "\n".join(lines) + MARKERS[1] + tail)


def _cell(stats: dict[str, Any] | None, fmt: str, scale: float = 1.0) -> dict[str, Any] | None:
    """One measure of a JSON record: ``mean``, ``std`` (over the training seeds) and the table's ``text``."""
    if stats is None:
        return None
    return {"mean": stats["mean"] * scale, "std": stats["std"] * scale, "text": _pm(stats, fmt)}


def _measures(summary: dict[str, Any]) -> dict[str, Any]:
    learned, reference = summary["learned"], summary["reference"]
    extra = summary.get("reference_extrapolate")
    target = "met" if summary["target_met"] else "not met"
    if "smoothness_met" in summary:
        target += ", smooth" if summary["smoothness_met"] else ", not smooth"
    return {
        "learned_return": _cell(learned["return"], "{:.1f}"),
        "reference_return": _cell(reference["return"], "{:.1f}"),
        "performance": _cell(summary["performance"], "{:.2f}"),
        "success_learned": _cell(learned["success"], "{:.0%}", 100.0),
        "success_reference": _cell(reference["success"], "{:.0%}", 100.0),
        "action_change_learned": _cell(learned["action_change"], "{:.3g}"),
        "action_change_reference": _cell(reference["action_change"], "{:.3g}"),
        "extrapolating_reference": None
        if extra is None
        else {"return": _cell(extra["return"], "{:.1f}"), "success": _cell(extra["success"], "{:.0%}", 100.0)},
        "target": target,
    }


def json_record(row: Row, summary: dict[str, Any], budget: float, scenario: str, level: str,
                provenance: dict[str, Any]) -> dict[str, Any]:  # fmt: skip
    """A published row as a record of ``docs/learned_baselines.json`` (the numbers of its table line)."""
    record: dict[str, Any] = {
        "row": row.name,
        "scenario": scenario,
        "level": level,
        "learner": "TorchRL MAPPO" if row.pipeline == "torchrl" else "SB3 PPO",
        "config": f"training/configs/{row.config}",
        "pipeline": row.pipeline,
        "budget_minutes": float(budget),
        "seeds": len(summary["seeds"]),
        **_measures(summary),
    }
    if "settings" in summary:
        record["settings"] = []
        for key, sub in summary["settings"].items():
            size, topology = key[1:].split("_", 1)
            record["settings"].append({"n_vessels": int(size), "topology": topology, **_measures(sub)})
    record["provenance"] = provenance
    return record


def publish_json(records: list[dict[str, Any]], document: Path) -> None:
    """Put ``records`` (``json_record``) into ``document``, replacing the rows of the same name.

    Rows already there and not among ``records`` stay as they were: the table can be regenerated one row at a
    time. Rows are in the order of ``ROWS``.
    """
    data = json.loads(document.read_text()) if document.is_file() else {"rows": []}
    rows = {r["row"]: r for r in data["rows"]}
    rows.update({r["row"]: r for r in records})
    data["rows"] = sorted(rows.values(), key=lambda r: list(ROWS).index(r["row"]) if r["row"] in ROWS else len(ROWS))
    atomic_write_text(document, json.dumps(data, indent=2, ensure_ascii=False) + "\n")


def _description(row: Row, folder: Path, record: dict[str, Any]) -> str:
    """A pretrained policy's one-line description: its setting, how it was trained, which seed."""
    scenario, env_kwargs = _scenario_of(folder)
    learner = "TorchRL MAPPO" if row.pipeline == "torchrl" else "SB3 PPO"
    level = make_config(scenario, **env_kwargs).action_level  # the scenario's own level when the run set none
    text = f"{scenario} scenario, {level} level: {learner}, {record['minutes']:g} min, training seed {record['seed']}"
    run = _run_config(folder)
    shaping = run.get("train_reward") or {}
    if shaping:
        text += ", trained on a shaped reward (" + ", ".join(f"{k}={v}" for k, v in shaping.items()) + ")"
    period = run.get("train_dt")
    if period is not None:
        text += f", deciding every {float(period):g} s in training"
    dropped = run.get("drop_inputs")
    if dropped:
        text += ", not reading " + ", ".join(dropped)
    smoothness = run.get("temporal_smoothness")
    if smoothness:
        text += f", with a temporal smoothness term λ={float(smoothness):g}"
    return f"{text} ({row.note})" if row.note else text


# ----------------------------------------------------------------------------- command line


def _parse_rows(text: str) -> list[Row]:
    names = [item.strip() for item in text.split(",") if item.strip()]
    unknown = [name for name in names if name not in ROWS]
    if unknown or not names:
        raise ValueError(f"--rows: unknown row(s) {unknown or [text]}; rows: {list(ROWS)}")
    return [ROWS[name] for name in dict.fromkeys(names)]


def main(argv: Sequence[str] | None = None) -> int:
    prog = "python -m benchmarks.learned_baselines"
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", default=",".join(ROWS), help=f"comma-separated rows (default all: {','.join(ROWS)})")
    parser.add_argument("--seeds", default="0,1,2", help="training seeds (default 0,1,2)")
    parser.add_argument(
        "--minutes", type=float, default=None, help="every row's budget (a smoke run); default: its own"
    )
    parser.add_argument("--episodes", type=int_at_least(1), default=10, help="evaluation episodes (default 10)")
    parser.add_argument("--out", type=Path, default=Path("runs/learned_baselines"))
    parser.add_argument("--fresh", action="store_true", help="retrain runs that have a result already")
    parser.add_argument("--publish", action="store_true", help="write docs/results.md, the figures and the policies")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    try:
        rows = _parse_rows(args.rows)
        seeds = parse_seeds(args.seeds)
    except ValueError as err:
        parser.error(str(err))
    if args.minutes is not None and not args.minutes > 0:
        parser.error(f"--minutes must be > 0, got {args.minutes}")
    if args.publish and args.minutes is not None:
        parser.error("--publish writes the shipped results: run it with every row's own budget (no --minutes)")
    budgets = {row.name: args.minutes if args.minutes is not None else row.minutes for row in rows}
    records: list[dict[str, Any]] = []
    command = command_line(prog, argv)
    report: dict[str, Any] = {"command": command, "provenance": provenance(command)}
    for seed in seeds:  # seed-major: a change in the machine's load falls on every row alike
        for row in rows:
            if not args.quiet:
                print(f"[{time.strftime('%H:%M:%S')}] {row.name}, seed {seed}, {budgets[row.name]:g} min", flush=True)
            records.append(run_row_seed(row, seed, budgets[row.name], args.episodes, args.out, args.fresh))
            report.update(
                runs=records,
                rows=[row_summary(r, [x for x in records if x.get("row") == r.name]) for r in rows],
                complete=False,
            )
            atomic_write_text(args.out / "learned_baselines.json", json.dumps(report, indent=2) + "\n")
    report["complete"] = True
    atomic_write_text(args.out / "learned_baselines.json", json.dumps(report, indent=2) + "\n")
    table = format_table(report["rows"], budgets)
    print(table)
    plot_learning_curves(rows, records, args.out, args.out / "learning_curves.png")
    for row in rows:
        first = next((r for r in records if r.get("row") == row.name and "learned" in r), None)
        if first is not None:
            plot_episode(row, first, args.out, args.out / "episodes" / f"{row.name}.png")
    if args.publish:
        docs = DOCS
        commit = report["provenance"]["commit"]
        fields = {
            row.name: provenance_fields(commit, [r for r in records if r.get("row") == row.name], report["command"])
            for row in rows
        }
        publish_markdown(table, {name: _provenance(f, name) for name, f in fields.items()}, docs / "results.md")
        published = []
        for row, summary in zip(rows, report["rows"], strict=True):
            if "learned" in summary:
                scenario, env_kwargs = _scenario_of(args.out / row.name / f"seed_{summary['seeds'][0]}")
                level = make_config(scenario, **env_kwargs).action_level
                published.append(json_record(row, summary, budgets[row.name], scenario, level, fields[row.name]))
        publish_json(published, docs / "learned_baselines.json")
        for row in rows:
            first = next((r for r in records if r.get("row") == row.name and "learned" in r), None)
            if first is None:
                continue
            plot_learning_curves([row], records, args.out, docs / "learning_curves" / f"{row.name}.png")
            plot_episode(row, first, args.out, docs / "episodes" / f"{row.name}.png")
            # the commit the policy trained with (a run found done may be older than this publish; a result.json
            # written before runs recorded it does not say, and this publish's commit would be a guess)
            training = {"minutes": first["minutes"], "config": row.config, "commit": first.get("commit", "unknown")}
            folder = args.out / row.name / f"seed_{first['seed']}"
            header = _header_evaluation(row, first, folder, args.episodes)
            export_run(folder, row.name, _description(row, folder, first), training=training, evaluation=header)
    return 0


def provenance_fields(commit: str, records: list[dict[str, Any]], command: str) -> dict[str, Any]:
    """Where a published row comes from: ``trained_on`` (a commit, or ``{"seed K": commit}`` when its runs trained
    on different ones), ``commit`` (the publishing one), ``machine`` and ``command``.

    A run found done (its ``result.json``) may have trained on an older commit than the publish's; its record
    keeps that commit (``unknown`` when written before records kept it).
    """
    runs = [r for r in records if "learned" in r]  # in the order they ran: row by row, seed by seed
    trained = {str(r.get("commit", "unknown")) for r in runs}
    trained_on: Any = trained.pop() if len(trained) == 1 else commit if not trained else None
    if trained_on is None:
        trained_on = {f"seed {r.get('seed', '?')}": str(r.get("commit", "unknown")) for r in runs}
    return {"trained_on": trained_on, "commit": commit, "machine": machine(), "command": command}


def _provenance(fields: dict[str, Any], row: str) -> str:
    """A published row's line under the table (``provenance_fields`` in words)."""
    tail = f"{fields['machine']}, with `{fields['command']}`"
    trained, commit = fields["trained_on"], fields["commit"]
    if trained == commit:
        return f"measured on commit {commit}, {tail}"
    if isinstance(trained, str):
        return f"trained on commit {trained} and published from commit {commit}, {tail}"
    each = ", ".join(f"{row} {seed} on {on}" for seed, on in trained.items())
    return f"trained on several commits ({each}) and published from commit {commit}, {tail}"


def _header_evaluation(row: Row, record: dict[str, Any], folder: Path, episodes: int) -> dict[str, Any]:
    """What a pretrained policy's header says it measured (``baselines.pretrained``), on its training scenario.

    A generalization row's record holds its other teams; its header is measured on its training team (what the
    shipped-policy test re-measures) and lists each setting's mean return and success besides.
    """
    if row.generalization:
        _, config = load_learned_policy(folder)
        portable, _ = load_pretrained(row.name, folder / "exported")
        own = _evaluate_members(portable, parallel_env(config["scenario"], **config["env_kwargs"]), episodes)
        header = _header_evaluation(Row(row.name, row.minutes, row.config), own, folder, episodes)
        header["settings"] = {
            key: {
                "learned_return": s["learned"]["return"],
                "reference_return": s["reference"]["return"],
                "learned_success": s["learned"]["success"],
            }
            for key, s in record["settings"].items()
        }
        return header
    out = {
        "seeds": record["seeds"],
        "learned_return": record["learned"]["return"],
        "learned_returns": record["learned"]["returns"],
        "learned_success": record["learned"]["success"],
        "reference_return": record["reference"]["return"],
        "reference_success": record["reference"]["success"],
        "learned_action_change": record["learned"]["action_change"],
        "reference_action_change": record["reference"]["action_change"],
    }
    if "reference_extrapolate" in record:
        out["reference_extrapolate_return"] = record["reference_extrapolate"]["return"]
    return out


if __name__ == "__main__":
    raise SystemExit(main())
