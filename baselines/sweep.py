"""Where does the paper's controller degrade? Sweep packet loss and latency.

For every pair (loss probability p, latency L) of a grid, run the reference
policy (plain and, by default, extrapolating) for a few episodes and record
the final coordination spread, the settling time, the time some vessel's
surge speed spent outside (U_min, U_max), and collisions. Writes a JSON file,
a markdown table and a figure of heat maps (one row per policy)::

    python -m baselines.sweep --out results/sweep
    python -m baselines.sweep --scenario radio --loss 0,0.2,0.5 --latency 0,1,2 --episodes 5
    python -m baselines.sweep --address HEAD_IP:6379 --episodes 20   # cells as Ray tasks on a cluster

The base scenario keeps everything but the swept settings: loss is Bernoulli
(a Gilbert–Elliott ``burst`` of the scenario is dropped) and the latency is
fixed (the scenario's jitter is kept). By default the vessels start around
their formation slots with random offsets (the generated formations' noise,
``GENERATED_INIT_NOISE``) and a 5 m
safety distance, so that collisions mean something: the paper's own initial
state makes two vessels cross 0.5 m apart even over ideal links
(``--paper-initial-state`` keeps it). Episode ``k`` of every cell uses reset
seed ``seed + k``: the same initial states and channel streams everywhere.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import episode_reports
from baselines.evaluate import is_reference, make_policy, policy_config, progress_bar
from baselines.plots import save_figure, write_report
from baselines.ray_cluster import connect
from marine_formation_env.atomic import check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least, parse_overrides
from marine_formation_env.env import parallel_env
from marine_formation_env.provenance import command_line
from marine_formation_env.render import require_matplotlib
from marine_formation_env.scenarios import GENERATED_INIT_NOISE, SCENARIOS

__all__ = ["METRICS", "main", "run_cell", "sweep"]

#: What each cell reports: key, label, unit.
METRICS = (
    ("final_spread", "final spread", "m"),
    ("settling_time", "settling time", "s"),
    ("surge_outside_band_time", "u outside band", "s"),
    ("collision_rate", "collisions", "fraction"),
)


def _floats(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("expected at least one number")
    return values


def _cell(episodes: list[dict[str, Any]], horizon: float) -> dict[str, Any]:
    settled = [e["settling_time"] for e in episodes if e["settling_time"] is not None]
    return {
        "final_spread": float(np.mean([e["final_coordination_spread"] for e in episodes])),
        # an episode that never settles counts as the horizon (a lower bound of its settling time)
        "settling_time": float(np.mean(settled + [horizon] * (len(episodes) - len(settled)))),
        "settled_fraction": len(settled) / len(episodes),
        "surge_outside_band_time": float(np.mean([e["surge_outside_band_time"] for e in episodes])),
        "collision_rate": float(np.mean([e["collision"] for e in episodes])),
        "min_separation": float(np.min([e["min_separation"] for e in episodes])),
        "message_rate": float(np.mean([e["message_rate"] for e in episodes])),
    }


def sweep(
    scenario: str,
    losses: Sequence[float],
    latencies: Sequence[float],
    policies: Sequence[str],
    episodes: int,
    seed: int,
    overrides: dict[str, Any],
    paper_initial_state: bool = False,
    progress: bool = True,
    address: str | None = None,
) -> dict[str, Any]:
    """Run the grid and return a JSON-friendly report (see the module docstring).

    ``report["cells"][policy][i][k]`` holds the metrics at ``losses[i]``,
    ``latencies[k]`` (means over episodes; ``settling_time`` counts an
    unsettled episode as the horizon, ``settled_fraction`` says how many settled).

    With ``address`` (``"auto"``, ``"HOST:PORT"`` of a running Ray cluster, or
    ``"local"`` for a Ray instance of this process), every cell (a pair loss,
    latency with all its policies and episodes) is one Ray task. A cell's
    numbers depend only on its settings and the seeds, so the report is the
    same as a local run's.
    """
    if episodes < 1:
        raise ValueError(f"--episodes must be ≥ 1, got {episodes}")
    base: dict[str, Any] = dict(overrides)
    if not paper_initial_state:
        base.setdefault("initial_state", None)
        base.setdefault("init_noise", GENERATED_INIT_NOISE)
        base.setdefault("safety_distance", 5.0)
    channel_override = dict(base.pop("channel", {}) or {})
    seeds = [seed + k for k in range(episodes)]
    grid = [(p, latency) for p in losses for latency in latencies]
    jobs = [
        (scenario, {**base, "channel": {**channel_override, "loss": p, "latency": latency, "burst": None}})
        for p, latency in grid
    ]
    # the scenario must build before any work is sent out: a bad override fails here, by name
    config = parallel_env(jobs[0][0], **jobs[0][1]).config
    bar = progress_bar(len(jobs) * len(policies) * episodes, progress, desc="sweep")
    if address is None:
        results = []
        for job in jobs:
            results.append(run_cell(*job, policies, seeds))
            if bar is not None:
                bar.update(len(policies) * episodes)
    else:
        results = _run_on_ray(address, jobs, policies, seeds, bar, len(policies) * episodes)
    if bar is not None:
        bar.close()
    cells: dict[str, list[list[dict[str, Any]]]] = {
        label: [[results[i * len(latencies) + k][label] for k in range(len(latencies))] for i in range(len(losses))]
        for label in policies
    }
    return {
        "scenario": scenario,
        "overrides": {k: repr(v) for k, v in base.items()},
        "loss": list(losses),
        "latency": list(latencies),
        "policies": list(policies),
        "episodes": episodes,
        "seed": seed,
        "config": config.to_dict(),
        "cells": cells,
    }


def run_cell(
    scenario: str, overrides: dict[str, Any], policies: Sequence[str], seeds: Sequence[int]
) -> dict[str, dict[str, Any]]:
    """One cell of the grid: every policy's metrics over the episodes of ``seeds`` (a pure function of its inputs)."""
    env = parallel_env(scenario, **overrides)
    try:
        return {
            label: _cell(
                episode_reports(make_policy(label, env, seeds[0]), policy_config(label, env.config), seeds)[0],
                env.config.horizon,
            )
            for label in policies
        }
    finally:
        env.close()


def _run_on_ray(
    address: str,
    jobs: list[tuple[str, dict[str, Any]]],
    policies: Sequence[str],
    seeds: list[int],
    bar: Any,
    per_cell: int,
) -> list[dict[str, dict[str, Any]]]:
    """The cells as Ray tasks (one CPU each) on the cluster at ``address``; results in grid order."""
    ray = connect(address)
    task = ray.remote(num_cpus=1)(run_cell)
    pending = {task.remote(*job, list(policies), seeds): i for i, job in enumerate(jobs)}
    results: list[Any] = [None] * len(jobs)
    waiting = list(pending)
    while waiting:
        done, waiting = ray.wait(waiting, num_returns=1)
        for ref in done:
            results[pending[ref]] = ray.get(ref)
            if bar is not None:
                bar.update(per_cell)
    return results


def format_markdown(report: dict[str, Any]) -> str:
    """One markdown table per policy: rows loss p, columns latency, cells ``spread / settling``."""
    out = []
    for label in report["policies"]:
        out.append(f"### {label}\n")
        out.append(
            "Each cell: final coordination spread [m] / settling time [s] (✗: some episode never settled; the "
            "mean then counts it as the horizon) / time with some u outside (U_min, U_max) [s] / collision rate.\n"
        )
        header = "| loss p \\ latency | " + " | ".join(f"{lat:g} s" for lat in report["latency"]) + " |"
        out += [header, "|" + "---|" * (len(report["latency"]) + 1)]
        for p, row in zip(report["loss"], report["cells"][label], strict=True):
            cells = []
            for c in row:
                mark = "" if c["settled_fraction"] == 1 else " ✗"
                cells.append(
                    f"{c['final_spread']:.3g} / {c['settling_time']:.0f}{mark} / "
                    f"{c['surge_outside_band_time']:.0f} / {c['collision_rate']:.0%}"
                )
            out.append(f"| {p:g} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def plot_sweep(report: dict[str, Any], path: str | Path) -> Any:
    """Heat maps: one row per policy, one column per metric (loss p down, latency across)."""
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    policies, losses, latencies = report["policies"], report["loss"], report["latency"]
    fig = Figure(figsize=(4.2 * len(METRICS), 3.4 * len(policies)), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(policies), len(METRICS), squeeze=False)
    horizon = float(report["config"]["horizon"])
    # one colour scale per metric, shared by the policies so that their rows compare
    limits = {
        "final_spread": (-3.0, 2.0),
        "settling_time": (0.0, horizon),
        "surge_outside_band_time": (0.0, horizon),
        "collision_rate": (0.0, 1.0),
    }
    for row, label in enumerate(policies):
        for col, (key, name, unit) in enumerate(METRICS):
            ax = axes[row, col]
            values = np.array([[c[key] for c in cells] for cells in report["cells"][label]])
            if key == "final_spread":
                shown = np.log10(np.maximum(values, 1e-3))
                title = f"{name} (log10 {unit}, floor 1 mm)"
            else:
                shown, title = values, f"{name} [{unit}]"
            low, high = limits[key]
            image = ax.imshow(shown, origin="lower", aspect="auto", cmap="viridis", vmin=low, vmax=high)
            fig.colorbar(image, ax=ax, fraction=0.046)
            for i in range(len(losses)):
                for k in range(len(latencies)):
                    text = f"{values[i, k]:.2g}" if key != "collision_rate" else f"{values[i, k]:.0%}"
                    light = (shown[i, k] - low) > 0.6 * (high - low)
                    ax.text(k, i, text, ha="center", va="center", fontsize=7, color="black" if light else "white")
            ax.set_xticks(range(len(latencies)), [f"{v:g}" for v in latencies])
            ax.set_yticks(range(len(losses)), [f"{v:g}" for v in losses])
            ax.set_xlabel("latency [s]")
            ax.set_ylabel("loss probability")
            ax.set_title(f"{label}: {title}", fontsize=9)
    fig.suptitle(
        f"Degradation of the reference policy, scenario {report['scenario']!r}, "
        f"{report['episodes']} episode(s) per cell",
        fontsize=11,
    )
    fig.tight_layout()
    save_figure(fig, path)
    return fig


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m baselines.sweep", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="paper", help=f"base scenario ({', '.join(sorted(SCENARIOS))})")
    parser.add_argument("--loss", type=_floats, default=[0.0, 0.1, 0.3, 0.5, 0.7, 0.9], help="loss probabilities")
    parser.add_argument("--latency", type=_floats, default=[0.0, 0.5, 1.0, 2.0, 4.0, 8.0], help="latencies [s]")
    parser.add_argument(
        "--policy",
        action="append",
        dest="policies",
        help="reference[:extrapolate,ilos=σ]; repeatable (default: reference and reference:extrapolate)",
    )
    parser.add_argument("--episodes", type=int_at_least(1), default=3, help="episodes per cell and policy (default 3)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="seed of the first episode (default 0)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scenario override")
    parser.add_argument("--paper-initial-state", action="store_true", help="start from the paper's initial state")
    parser.add_argument("--out", type=Path, default=Path("results/sweep"), help="output prefix (.json/.md/.png)")
    parser.add_argument(
        "--address",
        default=None,
        help="run the cells as Ray tasks on this cluster: HOST:PORT, 'auto' or 'local' (default: here, one by one)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    args = parser.parse_args(argv)
    policies = args.policies or ["reference", "reference:extrapolate"]
    for label in policies:
        if not is_reference(label):
            parser.error(f"the sweep runs the reference policy (with options), got {label!r}")
    try:
        for suffix in (".json", ".md", ".png"):
            check_writable(args.out.with_suffix(suffix), "--out")
        report = sweep(
            args.scenario,
            args.loss,
            args.latency,
            policies,
            args.episodes,
            args.seed,
            parse_overrides(args.set),
            args.paper_initial_state,
            not args.quiet,
            args.address,
        )
    except (ValueError, KeyError, TypeError, ImportError, ConnectionError) as err:
        parser.error(str(err))
    table = format_markdown(report)
    write_report(args.out, report, table, plot_sweep, command_line("python -m baselines.sweep", argv))
    if not args.quiet:
        print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
