"""Learning benchmark: how close does a learned policy get to the paper's controller in N minutes?

Example::

    python -m benchmarks.learning --level speed --minutes 15

Trains PPO (``training/configs/paper_<level>_ppo.yaml``: the paper's scenario
with randomized initial states) until the wall-clock budget is spent, then
runs the learned policy, the reference policy and a uniform random policy on
the same ``--episodes`` seeds, the evaluation seeds (``baselines.seeds``:
10 000, 10 001, …, as every tool that reports a number), and reports:

* mean ± std of the episode return (≤ 0; 0 is perfect) for each policy;
* ``performance = R_reference / R_learned``: the fraction of the reference's
  performance the learned policy reaches (1 = parity, 0.9 = it accumulates
  1/0.9 ≈ 1.11 times the reference's cost; the target is ≥ 0.9);
* ``normalized = (R_learned − R_random) / (R_reference − R_random)``: 0 is
  random, 1 is the reference;
* learned/reference ratio of the final coordination spread, with both values
  (the reference's spread is ~1e-12 m, so the ratio is large for any policy
  that is not exactly consensus);
* success rates (``baselines.metrics.SUCCESS_BANDS``), the wall time and the
  vessel-steps used.

Results go to ``<out>/benchmark.json``; the run folder holds the model, so
``python -m baselines.evaluate --policy reference --policy <out>/model.zip
--episodes 10 --seed 10000`` (with the config's scenario and ``env_kwargs``
as ``--scenario``/``--set``) reproduces the comparison. Over a non-ideal channel (``--config
training/configs/acoustic_speed_ppo.yaml``) the reference that extrapolates
stale messages (``reference_extrapolate``) is evaluated too; ``performance``
and ``normalized`` stay relative to the paper's controller. ``--set KEY=VALUE``
(dots nest, repeatable) overrides a key of the config for one run, for example
``--set learning_rate=lin_3e-4``; the run's ``config.yaml`` records it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from baselines.metrics import summarize
from baselines.reference import ReferencePolicy
from baselines.rollout import RandomPolicy
from baselines.seeds import evaluation_seeds
from marine_formation_env import ACTION_LEVELS
from marine_formation_env.cli import ArgumentParser, int_at_least, parse_overrides, report_error
from marine_formation_env.env import parallel_env
from training import run_folder
from training.callbacks import evaluate_policy_episodes
from training.config import TrainConfigError, apply_overrides, load_config, validate
from training.learned import ModelPolicy
from training.train import train

__all__ = ["main", "run_benchmark"]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "training" / "configs"


def config_file(level: str, config_path: Path | None = None) -> Path:
    """The training config a run reads: ``config_path``, or ``training/configs/paper_<level>_ppo.yaml``."""
    return config_path or CONFIG_DIR / f"paper_{level}_ppo.yaml"


def config_level(config: dict[str, Any], level: str | None, path: Path) -> str:
    """The action level ``config`` trains at; ``level`` (``--level``), if given, must be that one.

    Raises:
        ValueError: ``level`` names another level than the config's ``env_kwargs.action_level``.
    """
    own = str(config.get("env_kwargs", {}).get("action_level", "speed"))
    if level is not None and level != own:
        raise ValueError(f"--level {level!r}, but {path} trains at action_level {own!r}")
    return own


def run_benchmark(
    level: str | None,
    minutes: float,
    seed: int,
    episodes: int,
    out: Path,
    config_path: Path | None = None,
    progress: bool = True,
    vessel_steps: int | None = None,
    overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Train for ``minutes`` of wall time at ``level`` and compare with the reference (module docstring).

    ``level`` picks the default config; with ``config_path`` it may be ``None`` (the config's own
    ``action_level``, which the report records) and is refused if it names another level.
    ``vessel_steps``: also stop after that many vessel-steps (a budget that does
    not depend on the machine's load; the wall-clock budget still applies).
    ``overrides``: config keys replaced before training (``--set``, dots nest),
    recorded in the run folder's ``config.yaml``.
    """
    if level is not None and level not in ACTION_LEVELS:
        raise ValueError(f"unknown level {level!r}; choose one of {list(ACTION_LEVELS)}")
    path = config_file(level or "speed", config_path)
    # The budget stops training; the step count is only a ceiling. No periodic evaluation:
    # its time would count against the budget.
    ceiling = 10**9 if vessel_steps is None else int(vessel_steps)
    config = apply_overrides(load_config(path), overrides or {})
    level = config_level(config, level, path)
    resolved = validate(apply_overrides(config, {"n_timesteps": ceiling, "eval_freq": 0}))
    start = time.perf_counter()
    model = train(
        resolved,
        out,
        seed,
        progress=progress,
        minutes=minutes,
    )
    wall = time.perf_counter() - start
    env = parallel_env(resolved["scenario"], **resolved["env_kwargs"])
    policies = {
        "learned": ModelPolicy(model, model.get_vec_normalize_env()),
        "reference": ReferencePolicy(env),
        "random": RandomPolicy(env, seed=seed),
    }
    if not env.config.ideal_observations:  # stale data: also the reference that extrapolates them
        policies["reference_extrapolate"] = ReferencePolicy(env, extrapolate=True)
    seeds = evaluation_seeds(episodes)
    summaries = {name: summarize(evaluate_policy_episodes(env, p, seeds)) for name, p in policies.items()}
    r = {name: s["return"]["mean"] for name, s in summaries.items()}
    spread = {name: s["final_coordination_spread"]["mean"] for name, s in summaries.items()}
    report = {
        "level": level,
        "scenario": resolved["scenario"],
        "config": str(path),
        "minutes_budget": minutes,
        "vessel_steps_budget": vessel_steps,
        "wall_time_s": wall,
        "vessel_steps": int(model.num_timesteps),
        "episodes": episodes,
        "eval_seeds": seeds,
        "returns": {name: {"mean": s["return"]["mean"], "std": s["return"]["std"]} for name, s in summaries.items()},
        "performance": r["reference"] / r["learned"] if r["learned"] else float("nan"),
        "normalized": (r["learned"] - r["random"]) / (r["reference"] - r["random"]),
        "return_ratio_learned_over_reference": r["learned"] / r["reference"],
        "final_spread": spread,
        "final_spread_ratio_learned_over_reference": spread["learned"] / spread["reference"]
        if spread["reference"]
        else float("inf"),
        "success": {name: s["success"]["mean"] for name, s in summaries.items()},
        "target_met": bool(r["reference"] / r["learned"] >= 0.9) if r["learned"] else False,
    }
    run_folder.write_bytes(out / "benchmark.json", json.dumps(report, indent=2).encode())
    return report


def format_report(report: dict[str, Any]) -> str:
    lines = [
        f"level {report['level']}: {report['vessel_steps']:,} vessel-steps in {report['wall_time_s'] / 60:.1f} min",
        f"{'policy':<22} {'return':>18} {'final spread [m]':>18} {'success':>8}",
    ]
    for name in report["returns"]:
        ret = report["returns"][name]
        lines.append(
            f"{name:<22} {ret['mean']:>9.2f} ± {ret['std']:<6.2f} {report['final_spread'][name]:>18.3g} "
            f"{report['success'][name]:>8.0%}"
        )
    lines.append(
        f"performance R_ref/R_learned = {report['performance']:.3f} (target ≥ 0.9: "
        f"{'met' if report['target_met'] else 'not met'}); normalized score = {report['normalized']:.3f}; "
        f"spread ratio learned/reference = {report['final_spread_ratio_learned_over_reference']:.3g}"
    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.learning", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--level",
        choices=list(ACTION_LEVELS),
        default=None,
        help="picks training/configs/paper_<level>_ppo.yaml (default speed); with --config, must be its level",
    )
    parser.add_argument("--minutes", type=float, default=15.0, help="wall-clock training budget (default 15)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="training seed (default 0)")
    parser.add_argument(
        "--episodes", type=int_at_least(1), default=10, help="evaluation episodes per policy (default 10)"
    )
    parser.add_argument("--config", type=Path, help="training config (default training/configs/paper_<level>_ppo.yaml)")
    parser.add_argument("--out", type=Path, help="run folder (default runs/benchmark_<level>)")
    parser.add_argument(
        "--vessel-steps",
        type=int_at_least(1),
        default=None,
        help="also stop after this many vessel-steps (a budget independent of the machine's load)",
    )
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key; dots nest"
    )
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if not args.minutes > 0:
        parser.error(f"--minutes must be > 0, got {args.minutes}")
    try:  # a bad file, override or level is refused here, in one line, before any training
        overrides = parse_overrides(args.set, nest=False)
        path = config_file(args.level or "speed", args.config)
        config = validate(apply_overrides(load_config(path), overrides))
        level = config_level(config, args.level, path)
    except (TrainConfigError, ValueError, OSError) as err:
        report_error(parser.prog, str(err))
    out = args.out or Path("runs") / f"benchmark_{level}"
    report = run_benchmark(
        args.level, args.minutes, args.seed, args.episodes, out, args.config, not args.quiet, args.vessel_steps,
        overrides,
    )  # fmt: skip
    print(format_report(report))
    print(f"written {out / 'benchmark.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
