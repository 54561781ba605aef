"""Evaluate policies on a scenario: metrics table, JSON, trajectory and Fig. 6-style plot.

Example (the paper's scenario with the paper's controller)::

    python -m baselines.evaluate --scenario paper --policy reference --episodes 1 --seed 0 \\
        --json results/paper.json --save-trajectory results/paper.npz --plot results/paper.png

``--set KEY=VALUE`` overrides any scenario field (``--set action_level=force``,
``--set n_vessels=5 --set topology=ring``, ``--set 'gains={"delta": 80}'``);
values are Python/JSON literals, anything else is taken as a string.
Episode ``k`` is reset with seed ``seed + k``, the same for every policy.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines.metrics import episode_metrics, summarize
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy, Trajectory, run_episode
from marine_formation_env.env import parallel_env
from marine_formation_env.scenarios import SCENARIOS

__all__ = ["evaluate", "main", "make_policy", "parse_overrides"]

BUILTIN_POLICIES = ("reference", "random")


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """Parse ``KEY=VALUE`` strings; VALUE is a Python/JSON literal or a plain string."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        text = raw.strip()
        lowered = {"true": "True", "false": "False", "null": "None", "none": "None"}.get(text.lower(), text)
        try:
            value = ast.literal_eval(lowered)
        except (ValueError, SyntaxError):
            value = text
        out[key] = value
    return out


def make_policy(spec: str, env: Any, seed: int) -> Any:
    """Build a policy from its command-line name."""
    if spec == "reference":
        return ReferencePolicy(env)
    if spec == "random":
        return RandomPolicy(env, seed=seed)
    raise ValueError(f"unknown policy {spec!r}; known policies: {list(BUILTIN_POLICIES)}")


def _progress(total: int, enabled: bool) -> Any:
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc="episodes", unit="ep", file=sys.stderr)


def evaluate(
    scenario: str,
    policies: Sequence[str],
    episodes: int,
    seed: int,
    overrides: dict[str, Any],
    progress: bool = True,
) -> tuple[dict[str, Any], dict[str, Trajectory]]:
    """Run every policy for ``episodes`` episodes on the same seeds.

    Returns:
        ``(report, first)``: the JSON-friendly report and, per policy, its first
        episode's trajectory.
    """
    if episodes < 1:
        raise ValueError(f"--episodes must be ≥ 1, got {episodes}")
    env = parallel_env(scenario, **overrides)
    cfg = env.config
    report: dict[str, Any] = {
        "scenario": scenario,
        "overrides": {k: repr(v) if not isinstance(v, (int, float, str, bool)) else v for k, v in overrides.items()},
        "seed": seed,
        "episodes": episodes,
        "config": cfg.to_dict(),
        "policies": {},
    }
    first: dict[str, Trajectory] = {}
    bar = _progress(len(policies) * episodes, progress)
    for label in policies:
        policy = make_policy(label, env, seed)
        per_episode = []
        for k in range(episodes):
            traj = run_episode(env, policy, seed=seed + k)
            first.setdefault(label, traj)
            metrics = episode_metrics(traj, cfg)
            metrics["seed"] = seed + k
            per_episode.append(metrics)
            if bar is not None:
                bar.update(1)
        report["policies"][label] = {"episodes": per_episode, "summary": summarize(per_episode)}
    if bar is not None:
        bar.close()
    env.close()
    return report, first


TABLE_COLUMNS = (
    ("return", "return", "{:.2f}"),
    ("final_coordination_spread", "spread [m]", "{:.3g}"),
    ("final_cross_track_max", "|e| [m]", "{:.3g}"),
    ("final_heading_max_deg", "|ψ| [deg]", "{:.3g}"),
    ("final_speed_error_max", "|u−u_d| [m/s]", "{:.3g}"),
    ("settling_time", "settling [s]", "{:.1f}"),
    ("time_outside_speed_band", "outside band [s]", "{:.1f}"),
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
            elif stats["count"] > 1:
                row.append(f"{fmt.format(stats['mean'])} ± {fmt.format(stats['std'])}")
            else:
                row.append(fmt.format(stats["mean"]))
        rows.append(row)
    widths = [max(len(r[c]) for r in rows) for c in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(r, widths, strict=True)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m baselines.evaluate", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="paper", help=f"scenario name ({', '.join(sorted(SCENARIOS))})")
    parser.add_argument(
        "--policy", action="append", dest="policies", help=f"policy to run; repeatable ({', '.join(BUILTIN_POLICIES)})"
    )
    parser.add_argument("--episodes", type=int, default=1, help="episodes per policy (default 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    parser.add_argument("--json", type=Path, help="write metrics (per episode and summary) to this JSON file")
    parser.add_argument("--save-trajectory", type=Path, help="write the first episode to this .npz (t, state, …)")
    parser.add_argument("--plot", type=Path, help="write the Fig. 6-style figure of the first episode here")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scenario override")
    parser.add_argument("--quiet", action="store_true", help="no progress bar, no table")
    args = parser.parse_args(argv)
    policies = args.policies or ["reference"]
    try:
        overrides = parse_overrides(args.set)
        report, first = evaluate(args.scenario, policies, args.episodes, args.seed, overrides, not args.quiet)
    except (ValueError, KeyError, TypeError) as err:
        parser.error(str(err))
    if not args.quiet:
        print(format_table(report))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2, allow_nan=False, default=_json_default))
    if args.save_trajectory:
        args.save_trajectory.parent.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, np.ndarray] = {}
        for k, (label, traj) in enumerate(first.items()):
            arrays.update(traj.to_npz_dict("" if k == 0 else f"{label}__"))
        arrays["formation"] = np.asarray(_config_of(report)["formation"])
        np.savez_compressed(args.save_trajectory, **arrays)  # type: ignore[arg-type]
    if args.plot:
        from baselines.plots import plot_episode

        env = parallel_env(args.scenario, **overrides)
        for k, (label, traj) in enumerate(first.items()):
            path = args.plot if k == 0 else args.plot.with_name(f"{args.plot.stem}_{label}{args.plot.suffix}")
            plot_episode(
                traj,
                env.config,
                path,
                title=f"{args.scenario}: policy {label!r}, seed {args.seed}, action level {env.config.action_level!r}",
            )
    return 0


def _config_of(report: dict[str, Any]) -> dict[str, Any]:
    return report["config"]  # type: ignore[no-any-return]


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


if __name__ == "__main__":
    raise SystemExit(main())
