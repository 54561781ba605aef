"""Communication as a resource: the paper's controller, broadcasting periodically or on events, on a Pareto plot.

For each link preset (``paper``'s ideal links, ``radio``, ``acoustic``) the
extrapolating reference (``ReferencePolicy(extrapolate=True)``, the variant
that predicts each neighbour from its last message, as the event trigger
assumes) runs with

* **periodic** broadcasting at every k-th opportunity (k = 1: the channel's
  own schedule; k > 1: ``event_threshold = inf`` with a heartbeat of k
  opportunity periods), and
* **event-triggered** broadcasting at thresholds δ (``event_threshold``,
  τ_min = dt), without a heartbeat and with one every ``HEARTBEAT``
  opportunity periods (a lost message is otherwise never made good: the
  sender does not know its neighbours missed it),

and each point records the mean return, final spread, settling time (the
horizon when an episode never settles), success and messages per vessel per
second. The target: at a return within 2 % of periodic broadcasting's (k = 1),
event triggering sends at most a third of its messages.

For each budget preset (``paper_budget``, ``acoustic_budget``) the reference
broadcasts periodically into the budget and event-triggered at each δ; the
δ with the best mean return on the development seeds is the **reference
tuned to the budget**, reported on the benchmark seeds beside periodic
broadcasting. ``--learned PRESET=RUN,RUN,...`` adds policies trained with the
``transmit`` action on the preset (one run folder per training seed): each
seed's mean return, success and messages, and their mean and spread over
the seeds. Every other point runs on the benchmark seeds
(``baselines.seeds``), each episode from a random start
(``GENERATED_INIT_NOISE``, as the benchmark's tasks)::

    python -m benchmarks.communication --out docs/communication
    python -m benchmarks.communication --quick --out /tmp/communication
    python -m benchmarks.communication --out docs/communication \\
        --learned paper_budget=runs/budget/paper_s0,runs/budget/paper_s1,runs/budget/paper_s2

Writes ``OUT.json`` (with provenance), ``OUT.md`` (the tables) and ``OUT.png``
(return, final spread and settling time against messages per vessel per second).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import episode_reports
from baselines.evaluate import progress_bar
from baselines.plots import save_figure, write_report
from baselines.reference import ReferencePolicy
from baselines.runs import load_run
from baselines.seeds import benchmark_seeds, development_seeds
from marine_formation_env.atomic import check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least
from marine_formation_env.provenance import command_line, provenance
from marine_formation_env.render import require_matplotlib
from marine_formation_env.scenarios import GENERATED_INIT_NOISE, ScenarioConfig, make_config

__all__ = [
    "BUDGETS",
    "EVERY",
    "LINKS",
    "THRESHOLDS",
    "budget_references",
    "main",
    "opportunity_period",
    "point",
    "sweep",
]

#: The link presets of the Pareto sweep, and the budget presets.
LINKS = ("paper", "radio", "acoustic")
BUDGETS = ("paper_budget", "acoustic_budget")
#: Event thresholds δ [m, m/s] and periodic broadcasting every k-th opportunity.
THRESHOLDS = (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0)
EVERY = (1, 2, 4, 8, 16)
#: The heartbeat of the event-triggered points that have one [opportunity periods].
HEARTBEAT = 4
EPISODES = 20
#: Return within this share of periodic broadcasting's counts as equal (the target's).
EQUAL_RETURN = 0.02
#: ``--quick``: episodes, horizon [s], thresholds, every.
QUICK = (2, 20.0, (0.5, 2.0), (1, 4))


def opportunity_period(config: ScenarioConfig) -> float:
    """Seconds between two opportunities of a vessel to broadcast: ``n·tdma_slot`` with TDMA, else the
    channel's period (or dt)."""
    ch = config.channel
    if ch.tdma_slot is not None:
        return float(config.n_vessels * ch.tdma_slot)
    return float(config.dt if ch.period is None else ch.period)


def _config(scenario: str, channel: dict[str, Any], horizon: float | None) -> ScenarioConfig:
    extra = {} if horizon is None else {"horizon": horizon}
    return make_config(scenario, action_level="speed", init_noise=GENERATED_INIT_NOISE, channel=channel, **extra)


def point(scenario: str, channel: dict[str, Any], seeds: Sequence[int], horizon: float | None = None) -> dict[str, Any]:
    """The extrapolating reference on ``scenario`` with the ``channel`` overrides: its means over ``seeds``."""
    cfg = _config(scenario, channel, horizon)
    return _summary(ReferencePolicy(cfg, extrapolate=True), cfg, seeds, channel)


def learned_point(run: str, preset: str, seeds: Sequence[int], horizon: float | None = None) -> dict[str, Any]:
    """A policy trained with the ``transmit`` action on ``preset`` (its run folder) on ``seeds``."""
    policy, config = load_run(run)
    if config["scenario"] != preset or not config["env_kwargs"].get("transmit"):
        raise ValueError(f"run {run!r} was trained on {config['scenario']!r} (transmit "
                         f"{bool(config['env_kwargs'].get('transmit'))}), not on {preset!r} with transmit")  # fmt: skip
    extra = {} if horizon is None else {"horizon": horizon}
    cfg = make_config(preset, **{**config["env_kwargs"], "init_noise": GENERATED_INIT_NOISE, **extra})
    return {"run": run, **_summary(policy, cfg, seeds, {})}


def _summary(policy: Any, cfg: ScenarioConfig, seeds: Sequence[int], channel: dict[str, Any]) -> dict[str, Any]:
    metrics, _ = episode_reports(policy, cfg, seeds)
    settle = [cfg.horizon if m["settling_time"] is None else m["settling_time"] for m in metrics]
    return {
        "channel": {key: "inf" if value == math.inf else value for key, value in channel.items()},
        "return": float(np.mean([m["return"] for m in metrics])),
        "return_std": float(np.std([m["return"] for m in metrics])),
        "final_spread": float(np.mean([m["final_coordination_spread"] for m in metrics])),
        "settling_time": float(np.mean(settle)),
        "success": float(np.mean([m["success"] for m in metrics])),
        "message_rate": float(np.mean([m["message_rate"] for m in metrics])),
    }


def _periodic(scenario: str, k: int, horizon: float | None) -> dict[str, Any]:
    """The channel overrides of broadcasting at every k-th opportunity."""
    if k == 1:
        return {}
    return {"event_threshold": math.inf, "heartbeat": k * opportunity_period(_config(scenario, {}, horizon))}


def _events(scenario: str, thresholds: Sequence[float], horizon: float | None) -> list[dict[str, Any]]:
    """The event-triggered settings: each δ without a heartbeat, then each with one of ``HEARTBEAT``
    opportunity periods."""
    beat = HEARTBEAT * opportunity_period(_config(scenario, {}, horizon))
    plain = [{"event_threshold": delta} for delta in thresholds]
    return plain + [{"event_threshold": delta, "heartbeat": beat} for delta in thresholds]


def _event_label(point: dict[str, Any]) -> str:
    beat = point["channel"].get("heartbeat")
    return f"event δ = {point['threshold']:g}" + ("" if beat is None else f", heartbeat {beat:g} s")


def sweep(
    links: Sequence[str],
    thresholds: Sequence[float],
    every: Sequence[int],
    episodes: int,
    horizon: float | None = None,
    bar: Any = None,
) -> dict[str, Any]:
    """Per link preset: the periodic and event-triggered points (``point``) and the target's numbers."""
    seeds = benchmark_seeds(episodes)
    out: dict[str, Any] = {}
    for link in links:
        periodic = []
        for k in every:
            periodic.append({"every": k, **point(link, _periodic(link, k, horizon), seeds, horizon)})
            _tick(bar)
        event = []
        for channel in _events(link, thresholds, horizon):
            event.append({"threshold": channel["event_threshold"], **point(link, channel, seeds, horizon)})
            _tick(bar)
        out[link] = {"periodic": periodic, "event": event, "target": _target(periodic, event)}
    return out


def _target(periodic: list[dict[str, Any]], event: list[dict[str, Any]]) -> dict[str, Any]:
    """The fewest messages event triggering sends at a return within ``EQUAL_RETURN`` of broadcasting at
    every opportunity, as a share of that one's."""
    base = next((p for p in periodic if p["every"] == 1), None)
    if base is None:
        return {}
    equal = [e for e in event if abs(e["return"] - base["return"]) <= EQUAL_RETURN * abs(base["return"])]
    if not equal:
        closest = max(event, key=lambda e: e["return"])
        return {"periodic_rate": base["message_rate"], "setting": None, "share": None,
                "closest": {"setting": _event_label(closest), "return": closest["return"],
                            "periodic_return": base["return"],
                            "share": closest["message_rate"] / base["message_rate"]}}  # fmt: skip
    best = min(equal, key=lambda e: e["message_rate"])
    return {"periodic_rate": base["message_rate"], "setting": _event_label(best), "event_rate": best["message_rate"],
            "return": best["return"], "periodic_return": base["return"],
            "share": best["message_rate"] / base["message_rate"]}  # fmt: skip


def budget_references(
    budgets: Sequence[str], thresholds: Sequence[float], episodes: int, horizon: float | None = None, bar: Any = None
) -> dict[str, Any]:
    """Per budget preset: periodic broadcasting into the budget, and the event-triggered reference (δ, with or
    without the heartbeat) that returns most on the development seeds, both on the benchmark seeds."""
    out: dict[str, Any] = {}
    for preset in budgets:
        tuning = []
        for channel in _events(preset, thresholds, horizon):
            tuned = point(preset, channel, development_seeds(episodes), horizon)
            tuning.append({"threshold": channel["event_threshold"], **tuned})
            _tick(bar)
        best = max(tuning, key=lambda e: e["return"])
        seeds = benchmark_seeds(episodes)
        out[preset] = {
            "tuning": tuning,
            "periodic": point(preset, {}, seeds, horizon),
            "tuned": {"threshold": best["threshold"], **point(preset, _channel_of(best), seeds, horizon)},
        }
        _tick(bar, 2)
    return out


def _channel_of(point: dict[str, Any]) -> dict[str, Any]:
    """A point's channel overrides back as numbers (``point`` writes ``inf`` as a string for JSON)."""
    return {key: math.inf if value == "inf" else value for key, value in point["channel"].items()}


def learned_rows(learned: dict[str, list[str]], episodes: int, horizon: float | None, bar: Any) -> dict[str, Any]:
    """Per budget preset, each run's ``learned_point`` on the benchmark seeds and the mean and sample std over
    the runs (the training seeds) of its return, success and messages per vessel per second."""
    out: dict[str, Any] = {}
    for preset, runs in learned.items():
        points = []
        for run in runs:
            points.append(learned_point(run, preset, benchmark_seeds(episodes), horizon))
            _tick(bar)
        summary = {key: {"mean": float(np.mean([p[key] for p in points])),
                         "std": float(np.std([p[key] for p in points], ddof=1)) if len(points) > 1 else 0.0}
                   for key in ("return", "success", "message_rate", "final_spread")}  # fmt: skip
        out[preset] = {"runs": points, "over_seeds": summary}
    return out


def _tick(bar: Any, n: int = 1) -> None:
    if bar is not None:
        bar.update(n)


# ----------------------------------------------------------------------------- report


def _row(label: str, p: dict[str, Any]) -> str:
    return (f"| {label} | {p['message_rate']:.3g} | {p['return']:.2f} ± {p['return_std']:.2f} | "
            f"{p['final_spread']:.3g} | {p['settling_time']:.0f} | {p['success']:.0%} |")  # fmt: skip


HEADER = ("| broadcasting | messages / vessel / s | return | final spread [m] | settling [s] | success |\n"
          "|---|---|---|---|---|---|")  # fmt: skip


def format_markdown(report: dict[str, Any]) -> str:
    """The sweep's tables (one per link preset, then the budgets) and each preset's target line."""
    lines = ["# Communication: periodic and event-triggered broadcasting\n",
             f"`{report['provenance']['command']}`\n" if "provenance" in report else "",
             f"{report['episodes']} episodes per point on the benchmark seeds, random starts; the extrapolating "
             "reference. Settling: the horizon when an episode never settles. What each setting means: "
             "[channel.md](channel.md#communication-as-a-resource).\n",
             "![Pareto plot](communication.png)\n"]  # fmt: skip
    for link, result in report["links"].items():
        lines += [f"### {link}\n", HEADER]
        lines += [_row("periodic" if p["every"] == 1 else f"periodic, 1 in {p['every']} opportunities", p)
                  for p in result["periodic"]]  # fmt: skip
        lines += [_row(_event_label(e), e) for e in result["event"]]
        target = result["target"]
        if target.get("share") is not None:
            lines.append(
                f"\nAt a return within {EQUAL_RETURN:.0%} of periodic broadcasting's, {target['setting']} sends "
                f"{target['share']:.1%} of its messages ({target['event_rate']:.3g} against "
                f"{target['periodic_rate']:.3g} per vessel per s).\n"
            )
        elif target:
            closest = target["closest"]
            gap = closest["return"] / closest["periodic_return"] - 1
            lines.append(f"\nNo event-triggered setting returns within {EQUAL_RETURN:.0%} of periodic broadcasting; "
                         f"the closest ({closest['setting']}) returns {gap:.1%} less, at {closest['share']:.1%} "
                         "of its messages.\n")  # fmt: skip
    for preset, result in report.get("budgets", {}).items():
        lines += [f"### {preset}: the reference tuned to the budget\n", HEADER]
        lines.append(_row("periodic, into the budget", result["periodic"]))
        lines.append(_row(f"{_event_label(result['tuned'])} (tuned on the development seeds)", result["tuned"]))
        learned = report.get("learned", {}).get(preset)
        if learned:
            for k, p in enumerate(learned["runs"]):
                lines.append(_row(f"learned, transmit action, training seed {k} (`{p['run']}`)", p))
            m = learned["over_seeds"]
            lines.append(
                f"\nLearned, over {len(learned['runs'])} training seeds (mean ± sample std): return "
                f"{m['return']['mean']:.2f} ± {m['return']['std']:.2f}, {m['message_rate']['mean']:.3g} ± "
                f"{m['message_rate']['std']:.2g} messages per vessel per s, success {m['success']['mean']:.0%}, "
                f"final spread {m['final_spread']['mean']:.3g} m."
            )
        lines.append("")
    return "\n".join(lines) + "\n"


def plot_pareto(report: dict[str, Any], path: Path) -> None:
    """Return, final spread and settling time against messages per vessel per second (log scale)."""
    require_matplotlib()
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15, 4.6), layout="constrained")
    axes = fig.subplots(1, 3)
    colors = dict(zip(report["links"], ("tab:blue", "tab:orange", "tab:green"), strict=False))
    budget_colors = {"paper_budget": "tab:blue", "acoustic_budget": "tab:green"}
    for ax, key, label in zip(axes, ("return", "final_spread", "settling_time"),
                              ("mean return", "final spread [m]", "settling time [s]"), strict=True):  # fmt: skip
        for link, result in report["links"].items():
            beats = [e for e in result["event"] if "heartbeat" in e["channel"]]
            plain = [e for e in result["event"] if "heartbeat" not in e["channel"]]
            for mode, style, points in (("periodic", "s--", result["periodic"]), ("event", "o-", plain),
                                        (f"event, heartbeat {HEARTBEAT} opportunities", "^:", beats)):  # fmt: skip
                pts = sorted(points, key=lambda p: p["message_rate"])
                ax.plot([p["message_rate"] for p in pts], [p[key] for p in pts], style, color=colors[link],
                        label=f"{link}, {mode}", alpha=0.85, markersize=5)  # fmt: skip
        for preset, result in report.get("budgets", {}).items():
            tuned = result["tuned"]
            ax.plot(tuned["message_rate"], tuned[key], "*", color=budget_colors.get(preset, "k"), markersize=13,
                    markeredgecolor="k", label=f"{preset}: reference tuned to the budget")  # fmt: skip
        for preset, learned in report.get("learned", {}).items():
            runs = learned["runs"]
            ax.plot([p["message_rate"] for p in runs], [p[key] for p in runs], "P", markersize=10,
                    color=budget_colors.get(preset, "k"), markeredgecolor="k",
                    label=f"{preset}: learned, transmit action (each training seed)")  # fmt: skip
        ax.set_xscale("log")
        ax.set_xlabel("messages per vessel per second")
        ax.set_ylabel(label)
        if key == "final_spread":
            ax.set_yscale("symlog", linthresh=1e-3)
            ax.set_ylim(bottom=0.0)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("The paper's controller (extrapolating): periodic and event-triggered broadcasting")
    save_figure(fig, path)


def main(argv: Sequence[str] | None = None) -> int:
    prog = "python -m benchmarks.communication"
    parser = ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="write OUT.json, OUT.md and OUT.png")
    parser.add_argument("--episodes", type=int_at_least(1), default=EPISODES)
    parser.add_argument("--quick", action="store_true", help="2 episodes of 20 s, two thresholds: the pipeline")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--learned",
        action="append",
        default=[],
        metavar="PRESET=RUN,RUN",
        help="run folders of policies trained with the transmit action on a budget preset, one per training seed",
    )
    args = parser.parse_args(argv)
    for suffix in (".json", ".md", ".png"):
        try:
            check_writable(args.out.with_suffix(suffix), "--out")
        except ValueError as err:
            parser.error(str(err))
    learned: dict[str, list[str]] = {}
    for item in args.learned:
        preset, eq, runs = item.partition("=")
        if preset not in BUDGETS or not eq or not runs:
            parser.error(f"--learned {item!r}: expected PRESET=RUN[,RUN...] with PRESET one of {list(BUDGETS)}")
        learned[preset] = [run for run in runs.split(",") if run]
    episodes, horizon, thresholds, every = (args.episodes, None, THRESHOLDS, EVERY) if not args.quick else QUICK
    total = len(LINKS) * (2 * len(thresholds) + len(every)) + len(BUDGETS) * (2 * len(thresholds) + 2)
    total += sum(len(runs) for runs in learned.values())
    bar = progress_bar(total, not args.quiet, desc="points")
    report: dict[str, Any] = {
        "episodes": episodes,
        "links": sweep(LINKS, thresholds, every, episodes, horizon, bar),
        "budgets": budget_references(BUDGETS, thresholds, episodes, horizon, bar),
    }
    try:
        report["learned"] = learned_rows(learned, episodes, horizon, bar)
    except (ValueError, OSError) as err:
        parser.error(str(err))
    if bar is not None:
        bar.close()
    report["provenance"] = provenance(command_line(prog, argv))
    markdown = format_markdown(report)
    print(markdown)
    write_report(args.out, report, markdown, plot_pareto, report["provenance"]["command"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
