"""How long does a formation last under untrained, exploring actions? (the ``initial_scale`` of a learner)

A freshly initialized Gaussian policy acts about like zero-mean Gaussian noise
of its initial deviation. This script steps formations of a scenario under
exactly that, actions ``a ~ N(0, s²)`` per vessel and entry (the env clips them
to [−1, 1]), and reports how long each formation lasts before it terminates
(a vessel leaves the workspace or the envelope |u|, |v| ≤ max_speed,
|r| ≤ max_yaw_rate, or two vessels collide) or reaches the horizon::

    python -m benchmarks.exploration --level force --scales 1,0.3,0.1
    python -m benchmarks.exploration --level force --scales 1,0.3,0.1 --spread 0.1

At the ``force`` level the actions are the surge and yaw accelerations at
10 Hz: with SB3's and TorchRL's default deviation of 1, the yaw rate leaves its
envelope within seconds, so a learner's early episodes are too short to teach
it anything. ``--spread`` starts the formations that fraction of the way from
their lanes to the scenario's initial state (as the trainers' curriculum over
the initial state does; 1 = the scenario's own).

``--reference`` also reports how much of each actuator's range the paper's
controller uses (|a| per action entry over the episodes of ``--formations``
seeds, over the whole episode and after ``--after`` seconds), the yardstick for
a learner's ``initial_scale`` and ``action_scale``::

    python -m benchmarks.exploration --level force --scales 0.1 --reference --formations 10
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from baselines.engine import evaluate_episodes
from baselines.reference import ReferencePolicy
from marine_formation_env import ACTION_LEVELS
from marine_formation_env.actions import LEVEL_COMMANDS
from marine_formation_env.atomic import atomic_write_text
from marine_formation_env.cli import ArgumentParser, int_at_least, report_error
from marine_formation_env.core import FormationCore
from marine_formation_env.dynamics import R, U, V, X, Y
from marine_formation_env.frontend import InitialStates
from marine_formation_env.provenance import command_line, provenance
from marine_formation_env.rules import outside_workspace
from marine_formation_env.scenarios import SCENARIOS, make_config

#: What ended a formation, checked in this order on its last state.
CAUSES = ("yaw_rate", "speed", "workspace", "collision")

__all__ = ["lifetimes", "main", "reference_actions"]


def lifetimes(
    scenario: str, level: str, scale: float, formations: int, seed: int, spread: float = 1.0
) -> dict[str, Any]:
    """Seconds each of ``formations`` formations lasts under ``N(0, scale²)`` actions (the horizon if it never ends).

    Returns a dict with ``seconds`` (one entry per formation), ``ended_by``: the fraction of formations that each
    bound ended (``CAUSES``: |r| > max_yaw_rate, |u| or |v| > max_speed, outside the workspace, two vessels
    closer than the safety distance; the first that holds on the last state), and the ``horizon``.
    """
    if not scale > 0:
        raise ValueError(f"scale must be > 0, got {scale!r}")
    config = make_config(scenario, action_level=level)
    core = FormationCore(config, formations)
    starts = InitialStates(config, formations)
    starts.seed(list(range(seed, seed + formations)))
    starts.set_spread(spread)
    core.reset(starts.draw())
    rng = np.random.default_rng(seed)
    steps = round(config.horizon / config.dt)
    ended = np.full(formations, steps, dtype=np.int64)
    counts = dict.fromkeys(CAUSES, 0)
    alive = np.ones(formations, dtype=bool)
    shape = (formations, config.n_vessels, config.action_dim)
    for k in range(steps):
        out = core.step(rng.normal(0.0, scale, shape))
        now = alive & np.asarray(out.terminated, dtype=bool)
        ended[now] = k + 1
        for last in core.state[now]:  # a terminated formation keeps its last state (nothing restarts it)
            counts[_cause(config, last)] += 1
        alive &= ~now
        if not alive.any():
            break
    return {
        "scale": scale,
        "seconds": (ended * config.dt).tolist(),
        "ended_by": {cause: counts[cause] / formations for cause in CAUSES},
        "horizon": config.horizon,
    }


def reference_actions(scenario: str, level: str, seeds: list[int], after: float) -> dict[str, Any]:
    """How much of each actuator's range the reference uses: quantiles of |a| per action entry.

    Runs ``ReferencePolicy`` for one episode per seed and returns, per entry (a list
    of ``action_dim``), ``max``, ``p99`` and ``median`` of |a| over every vessel and control period, and
    ``max_after``: the largest |a| after ``after`` seconds. The actions are those the env applied (clipped).
    """
    config = make_config(scenario, action_level=level)
    if not 0.0 <= after < config.horizon:
        raise ValueError(f"after must lie in [0, horizon = {config.horizon:g}) s, got {after!r}")
    runs = evaluate_episodes(ReferencePolicy(config), config, seeds)
    size = np.abs(np.concatenate([run.actions.reshape(-1, config.action_dim) for run in runs]))
    late = np.abs(np.concatenate([run.actions[run.t[:-1] >= after].reshape(-1, config.action_dim) for run in runs]))
    return {
        "max": size.max(axis=0).tolist(),
        "p99": np.quantile(size, 0.99, axis=0).tolist(),
        "median": np.median(size, axis=0).tolist(),
        "max_after": late.max(axis=0).tolist(),
        "after": after,
        "seeds": seeds,
    }


def _cause(config: Any, state: np.ndarray) -> str:
    """Which bound a terminated formation's last state ``(N, 6)`` broke, the first of ``CAUSES`` that holds."""
    if np.any(np.abs(state[:, R]) > config.max_yaw_rate):
        return "yaw_rate"
    if np.any(np.abs(state[:, [U, V]]) > config.max_speed):
        return "speed"
    if np.any(outside_workspace(state[:, X], state[:, Y], *config.workspace)) or not np.all(np.isfinite(state)):
        return "workspace"
    return "collision"


def _scales(text: str) -> list[float]:
    try:
        values = [float(s) for s in text.split(",")]
    except ValueError:
        raise ValueError(f"--scales must be comma-separated numbers, got {text!r}") from None
    bad = [v for v in values if not v > 0]
    if bad:
        raise ValueError(f"--scales must all be > 0, got {bad}")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.exploration", description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper", choices=sorted(SCENARIOS))
    parser.add_argument("--level", default="force", choices=list(ACTION_LEVELS))
    parser.add_argument("--scales", default="1,0.3,0.1", help="action deviations to try (default 1,0.3,0.1)")
    parser.add_argument("--spread", type=float, default=1.0, help="initial-state spread in [0, 1] (default 1)")
    parser.add_argument("--formations", type=int_at_least(1), default=32, help="formations per deviation (default 32)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="also write the lifetimes here")
    parser.add_argument(
        "--reference", action="store_true", help="also report the reference's |a| on --formations seeds from --seed"
    )
    parser.add_argument("--after", type=float, default=60.0, help="--reference: also |a| after this time [s]")
    args = parser.parse_args(argv)
    if not 0.0 <= args.spread <= 1.0:
        parser.error(f"--spread must lie in [0, 1], got {args.spread}")
    try:
        scales = _scales(args.scales)
    except ValueError as err:
        parser.error(str(err))
    try:
        results = [lifetimes(args.scenario, args.level, s, args.formations, args.seed, args.spread) for s in scales]
    except (ValueError, TypeError) as err:
        report_error(parser.prog, str(err))
    print(f"{args.scenario}, {args.level} level, spread {args.spread:g}, {args.formations} formations")
    print("| action deviation | lifetime [s]: median | 10 % | 90 % | to the horizon | ended by |")
    print("|---|---|---|---|---|---|")
    for r in results:
        seconds = np.asarray(r["seconds"])
        causes = ", ".join(f"{c.replace('_', ' ')} {f:.0%}" for c, f in r["ended_by"].items() if f > 0) or "–"
        print(
            f"| {r['scale']:g} | {np.median(seconds):.1f} | {np.quantile(seconds, 0.1):.1f} | "
            f"{np.quantile(seconds, 0.9):.1f} | {np.mean(seconds >= r['horizon']):.0%} | {causes} |"
        )
    used = None
    if args.reference:
        try:
            used = reference_actions(args.scenario, args.level, list(range(args.seed, args.seed + args.formations)),
                                     args.after)  # fmt: skip
        except ValueError as err:
            report_error(parser.prog, str(err))
        entries = LEVEL_COMMANDS[args.level]
        print(f"\nthe reference's |a| over {args.formations} episodes, {args.scenario}, {args.level} level")
        print(f"| statistic | {' | '.join(entries)} |")
        print("|---|" + "---|" * len(used["max"]))
        for key, label in (
            ("max", "max"),
            ("p99", "99 %"),
            ("median", "median"),
            ("max_after", f"max after {args.after:g} s"),
        ):
            print(f"| {label} | " + " | ".join(f"{v:.4g}" for v in used[key]) + " |")
    if args.json is not None:
        command = command_line("python -m benchmarks.exploration", argv)
        report: dict[str, Any] = {"provenance": provenance(command), "runs": results}
        if used is not None:
            report["reference"] = used
        atomic_write_text(args.json, json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
