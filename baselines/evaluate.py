"""Evaluate policies on a scenario: metrics table, JSON, trajectories and plots.

Examples::

    # the paper's scenario with the paper's controller
    python -m baselines.evaluate --scenario paper --policy reference --episodes 1 --seed 0 \\
        --json results/paper.json --save-trajectory results/paper.npz --plot results/paper.png
    # a trained model beside the reference, on the same seeds
    python -m baselines.evaluate --policy reference --policy runs/paper_speed/model.zip --episodes 10 \\
        --plot results/compare.png

    # the reference under the acoustic preset, plain and extrapolating, with 3 s more latency
    python -m baselines.evaluate --scenario acoustic --policy reference --policy reference:extrapolate \\
        --set channel.latency=3.0 --episodes 5
    # plain LOS against integral LOS in a cross current (the policy steers at the guidance level)
    python -m baselines.evaluate --scenario current --set action_level=guidance \\
        --policy reference --policy reference:ilos=1.0

``--policy`` repeats: ``reference``, ``random``, ``pretrained:NAME`` (a policy
shipped with the project, ``--list-pretrained`` lists them; numpy only), or a
model saved by ``python -m training.train`` (``runs/NAME/model.zip`` or the
run folder; ``training.torchrl_ppo`` and ``training.rllib_ppo`` run folders
too). The
reference takes options after a colon, comma-separated: ``extrapolate``
(predict neighbours' positions from their last message's velocity and age) and
``ilos=σ`` (integral LOS with gain σ [m/s], ``ilos`` alone: σ = 1), e.g.
``reference:extrapolate,ilos=1.0``; ``event=δ`` runs it with event-triggered
broadcasting at threshold δ (``channel.event_threshold``) and extrapolating,
e.g. ``reference:event=0.5``. ``handover:LEARNED`` runs the learned policy
``LEARNED`` (pretrained or saved) until each vessel's own observation has
been in the success bands for 20 s, then the paper's controller
(``baselines.handover``), e.g. ``handover:pretrained:paper_speed``. A
model or pretrained policy brings its training scenario and env overrides;
``--scenario`` and ``--set`` take precedence over them (a pretrained policy
refuses a team size, action level or observation layout it cannot take). ``--set KEY=VALUE`` overrides any scenario
field (``--set action_level=force``, ``--set n_vessels=5 --set topology=ring``,
``--set 'gains={"delta": 80}'``); values are Python/JSON literals, anything
else is taken as a string. A dotted key sets one field of a nested setting and
keeps the scenario's others: ``--set channel.loss=0.3``,
``--set channel.latency=2.0``, ``--set current.speed=0.8``,
``--set sensor_noise.position=0.5``. Episode ``k`` is reset with seed ``seed + k``, the
same for every policy. With several policies, ``--plot`` draws them side by
side (and each policy's own Fig. 6-style figure beside it).
"""

from __future__ import annotations

import dataclasses
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import episode_reports
from baselines.handover import HANDOVER_PREFIX, HandoverPolicy, is_handover
from baselines.metrics import summarize
from baselines.plots import plot_comparison, plot_episode
from baselines.pretrained import check_compatible, format_listing, list_pretrained, load_pretrained
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy, Trajectory
from baselines.runs import load_run
from marine_formation_env.atomic import atomic_path, atomic_write_text, check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least, parse_overrides
from marine_formation_env.env import parallel_env
from marine_formation_env.provenance import command_line, provenance
from marine_formation_env.scenarios import SCENARIOS, ScenarioConfig

__all__ = ["evaluate", "is_reference", "main", "make_policy", "parse_overrides", "reference_options"]

BUILTIN_POLICIES = ("reference", "random")

#: Default integral-LOS gain σ [m/s] of ``reference:ilos``.
DEFAULT_ILOS_GAIN = 1.0


def is_reference(spec: str) -> bool:
    """Whether a ``--policy`` value names the reference policy, with or without options."""
    return spec == "reference" or spec.startswith("reference:")


def reference_options(spec: str) -> dict[str, Any]:
    """Keyword arguments of ``ReferencePolicy`` from ``reference[:opt,opt=value]`` (``event=δ`` extrapolates;
    its channel setting is ``policy_config``'s)."""
    options: dict[str, Any] = {}
    for name, value in _reference_items(spec):
        if name == "extrapolate" or name == "event":
            options["extrapolate"] = True
        elif name == "ilos":
            options["integral_los"] = DEFAULT_ILOS_GAIN if value is None else value
    return options


def _reference_items(spec: str) -> list[tuple[str, float | None]]:
    """The options of ``reference[:opt,opt=value]`` as ``(name, number or None)``, checked."""
    _, _, raw = spec.partition(":")
    items: list[tuple[str, float | None]] = []
    for item in filter(None, (part.strip() for part in raw.split(","))):
        name, eq, value = item.partition("=")
        if name == "extrapolate" and not eq:
            items.append((name, None))
        elif name in ("ilos", "event") and (eq or name == "ilos"):
            try:
                items.append((name, float(value) if eq else None))
            except ValueError:
                symbol = "σ" if name == "ilos" else "δ"
                raise ValueError(f"policy {spec!r}: {name}={symbol} needs a number, got {value!r}") from None
        else:
            raise ValueError(
                f"policy {spec!r}: unknown reference option {item!r}; options: extrapolate, ilos[=σ], event=δ"
            )
    return items


def policy_config(spec: str, config: ScenarioConfig) -> ScenarioConfig:
    """The scenario ``spec`` runs in: ``config``, with event-triggered broadcasting at threshold δ for
    ``reference:event=δ`` (``ChannelConfig.event_threshold``)."""
    threshold = dict(_reference_items(spec)).get("event") if is_reference(spec) else None
    if threshold is None:
        return config
    channel = dataclasses.replace(config.channel, event_threshold=threshold)
    channel.validate(config.dt, config.n_vessels)
    return dataclasses.replace(config, channel=channel)


PRETRAINED_PREFIX = "pretrained:"


def is_pretrained(spec: str) -> bool:
    """Whether a ``--policy`` value names a shipped pretrained policy (``pretrained:NAME``)."""
    return spec.startswith(PRETRAINED_PREFIX)


def is_model_path(spec: str) -> bool:
    """Whether a ``--policy`` value names a saved model rather than a built-in policy."""
    builtin = spec in BUILTIN_POLICIES or is_reference(spec) or is_pretrained(spec)
    return not builtin and (spec.endswith(".zip") or Path(spec).is_dir())


def load_model(spec: str) -> tuple[Any, dict[str, Any]]:
    """Load a saved model and its run config (``baselines.runs.load_run``; needs the trainer's extra)."""
    return load_run(spec)


def learned_spec(spec: str) -> str:
    """The learned policy a ``--policy`` value loads: ``LEARNED`` of ``handover:LEARNED``, else the value itself."""
    return spec[len(HANDOVER_PREFIX) :] if is_handover(spec) else spec


def make_policy(spec: str, env: Any, seed: int, loaded: dict[str, Any] | None = None) -> Any:
    """Build a policy from its command-line name (or a loaded model)."""
    if is_handover(spec):
        inner = learned_spec(spec)
        if not (is_pretrained(inner) or is_model_path(inner)):
            raise ValueError(f"policy {spec!r}: handover needs a learned policy (pretrained:NAME or a saved model)")
        return HandoverPolicy(make_policy(inner, env, seed, loaded), env)
    if is_reference(spec):
        return ReferencePolicy(policy_config(spec, env.config), **reference_options(spec))
    if spec == "random":
        return RandomPolicy(env, seed=seed)
    if loaded is not None and spec in loaded:
        policy = loaded[spec]
        obs_dim = env.observation_space(env.possible_agents[0]).shape[0]
        if is_pretrained(spec):
            check_compatible(policy.info, env.config, obs_dim)
            return policy
        expected, actions = policy.observation_dim, policy.action_dim
        any_team = getattr(policy, "any_slots", False)  # a slot network reads any team (training.learned)
        if (expected != obs_dim and not any_team) or actions != env.config.action_dim:
            if any_team:  # only the action size can be wrong
                wants, has = f"actions of size {actions}", f"{env.config.action_dim}"
            else:
                wants = f"observations of size {expected} and actions of size {actions}"
                has = f"{obs_dim} and {env.config.action_dim}"
            raise ValueError(
                f"model {spec!r} expects {wants}, but this scenario has {has} "
                f"(action_level {env.config.action_level!r}, n_vessels {env.config.n_vessels}); "
                "evaluate it on the scenario it was trained on"
            )
        return policy
    raise ValueError(
        f"unknown policy {spec!r}; known policies: {list(BUILTIN_POLICIES)}, pretrained:NAME or a saved model (.zip)"
    )


def progress_bar(total: int, enabled: bool, desc: str = "episodes") -> Any:
    """A tqdm bar over ``total`` episodes on stderr, or None (disabled, or tqdm not installed)."""
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="ep", file=sys.stderr)


def evaluate(
    scenario: str | None,
    policies: Sequence[str],
    episodes: int,
    seed: int,
    overrides: dict[str, Any],
    progress: bool = True,
) -> tuple[dict[str, Any], dict[str, Trajectory], ScenarioConfig]:
    """Run every policy for ``episodes`` episodes on the same seeds.

    Args:
        scenario: scenario name; None takes the first model's (else ``paper``).
        policies: ``reference``, ``random`` or saved-model paths.
        overrides: env overrides, applied over the first model's env_kwargs.

    Returns:
        ``(report, first, config)``: the JSON-friendly report, per policy its
        first episode's trajectory, and the scenario configuration used.
    """
    if episodes < 1:
        raise ValueError(f"--episodes must be ≥ 1, got {episodes}")
    if len(set(policies)) != len(policies):
        raise ValueError(f"each --policy may appear once, got {list(policies)}")
    loaded: dict[str, Any] = {}
    trained_on: dict[str, Any] = {}
    for spec in map(learned_spec, policies):
        if is_pretrained(spec):
            loaded[spec], info = load_pretrained(spec[len(PRETRAINED_PREFIX) :])
            if not trained_on:
                trained_on = {"scenario": info.scenario, **info.env_kwargs}
                if info.n_vessels is None:  # any team: its training padding is no default for another team
                    trained_on.pop("observation_slots", None)
        elif is_model_path(spec):
            loaded[spec], run_config = load_model(spec)
            if not trained_on:
                trained_on = {"scenario": run_config["scenario"], **run_config["env_kwargs"]}
                if getattr(loaded[spec], "any_slots", False):  # as for an any-team pretrained policy
                    trained_on.pop("observation_slots", None)
    scenario = scenario or trained_on.pop("scenario", "paper")
    trained_on.pop("scenario", None)
    overrides = {**trained_on, **overrides}
    env = parallel_env(scenario, **overrides)
    cfg = env.config
    report: dict[str, Any] = {
        "scenario": scenario,
        "overrides": {k: v if isinstance(v, (int, float, str, bool)) else repr(v) for k, v in overrides.items()},
        "seed": seed,
        "episodes": episodes,
        "config": cfg.to_dict(),
        "policies": {},
    }
    first: dict[str, Trajectory] = {}
    bar = progress_bar(len(policies) * episodes, progress)
    seeds = [seed + k for k in range(episodes)]
    built = {label: make_policy(label, env, seed, loaded) for label in policies}  # every refusal before any episode
    for label, policy in built.items():
        per_episode, trajectories = episode_reports(policy, policy_config(label, cfg), seeds)
        first[label] = trajectories[0]
        if bar is not None:
            bar.update(episodes)
        report["policies"][label] = {"episodes": per_episode, "summary": summarize(per_episode)}
    if bar is not None:
        bar.close()
    env.close()
    return report, first, cfg


TABLE_COLUMNS = (
    ("return", "return", "{:.2f}"),
    ("final_coordination_spread", "spread [m]", "{:.3g}"),
    ("final_cross_track_max", "|e| [m]", "{:.3g}"),
    ("rms_cross_track", "rms e [m]", "{:.3g}"),
    ("final_speed_error_max", "|u−u_d| [m/s]", "{:.3g}"),
    ("settling_time", "settling [s]", "{:.1f}"),
    ("time_outside_speed_band", "outside band [s]", "{:.1f}"),
    ("effort", "effort", "{:.3g}"),
    ("action_change", "Δa", "{:.3g}"),
    ("message_rate", "msg/vessel/s", "{:.3g}"),
    ("success", "success", "{:.0%}"),
)


def format_table(report: dict[str, Any]) -> str:
    """A plain-text table: mean ± std over episodes (final values at the episode end)."""
    header = ["policy"] + [name for _, name, _ in TABLE_COLUMNS]
    rows = [header]
    for label, result in report["policies"].items():
        row = [label]
        for key, _, fmt in TABLE_COLUMNS:
            stats = result["summary"].get(key)
            if stats is None:
                row.append("never" if key == "settling_time" else "n/a")
            elif key == "success" or stats["count"] == 1:
                row.append(fmt.format(stats["mean"]))
            elif stats["count"] < len(result["episodes"]):
                row.append(f"{fmt.format(stats['mean'])} ± {fmt.format(stats['std'])} ({stats['count']} ep.)")
            else:
                row.append(f"{fmt.format(stats['mean'])} ± {fmt.format(stats['std'])}")
        rows.append(row)
    widths = [max(len(r[c]) for r in rows) for c in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(r, widths, strict=True)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m baselines.evaluate", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--scenario", default=None, help=f"scenario ({', '.join(sorted(SCENARIOS))}); default: a model's, else paper"
    )
    parser.add_argument(
        "--policy",
        action="append",
        dest="policies",
        help="policy to run; repeatable: reference[:extrapolate,ilos=σ,event=δ], random, pretrained:NAME, "
        "a saved model .zip / run folder, or handover:LEARNED (that learned policy, then the reference)",
    )
    parser.add_argument("--list-pretrained", action="store_true", help="list the shipped pretrained policies and exit")
    parser.add_argument("--episodes", type=int_at_least(1), default=1, help="episodes per policy (default 1)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="seed of the first episode (default 0)")
    parser.add_argument("--json", type=Path, help="write metrics (per episode and summary) to this JSON file")
    parser.add_argument("--save-trajectory", type=Path, help="write the first episode to this .npz (t, state, …)")
    parser.add_argument("--plot", type=Path, help="write the Fig. 6-style figure of the first episode here")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="scenario override (PARENT.FIELD=VALUE too)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    args = parser.parse_args(argv)
    if args.list_pretrained:
        print(format_listing(list_pretrained()))
        return 0
    policies = args.policies or ["reference"]
    try:
        for flag, path in (("--json", args.json), ("--save-trajectory", args.save_trajectory), ("--plot", args.plot)):
            if path is not None:
                check_writable(path, flag)  # before the evaluation, not after it
        overrides = parse_overrides(args.set)
        report, first, cfg = evaluate(args.scenario, policies, args.episodes, args.seed, overrides, not args.quiet)
    except (ValueError, KeyError, TypeError, FileNotFoundError, ImportError) as err:
        parser.error(str(err))
    if not args.quiet:
        print(format_table(report))
    if args.json:
        report["provenance"] = provenance(command_line("python -m baselines.evaluate", argv))
        atomic_write_text(args.json, json.dumps(report, indent=2, allow_nan=False, default=_json_default))
    if args.save_trajectory:
        arrays: dict[str, np.ndarray] = {}
        for k, (label, traj) in enumerate(first.items()):
            arrays.update(traj.to_npz_dict("" if k == 0 else f"{label}__"))
        arrays["formation"] = np.asarray(_config_of(report)["formation"])
        with atomic_path(args.save_trajectory) as tmp:
            np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
    if args.plot:
        if len(first) == 1:
            (label, traj), *_ = first.items()
            plot_episode(
                traj,
                cfg,
                args.plot,
                title=f"{report['scenario']}: policy {label!r}, seed {args.seed}, action level {cfg.action_level!r}",
            )
        else:
            plot_comparison(first, cfg, args.plot, title=f"{report['scenario']} ({cfg.action_level}), seed {args.seed}")
            for k, (label, traj) in enumerate(first.items()):
                name = Path(label).parent.name if is_model_path(label) else label.replace(PRETRAINED_PREFIX, "")
                name = re.sub(r"[^A-Za-z0-9_.=-]+", "_", name)  # "reference:ilos" → "reference_ilos"
                path = args.plot.with_name(f"{args.plot.stem}_{k}_{name}{args.plot.suffix}")
                plot_episode(traj, cfg, path, title=f"{report['scenario']}: policy {label!r}, seed {args.seed}")
    return 0


def _config_of(report: dict[str, Any]) -> dict[str, Any]:
    return report["config"]  # type: ignore[no-any-return]


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


if __name__ == "__main__":
    raise SystemExit(main())
