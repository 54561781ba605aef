"""Training throughput side by side: four learning pipelines, the same task, the same budget, the same evaluation.

On the ``paper`` scenario at the ``speed`` level (random starts around the
slots, as every shipped config has it), each pipeline trains for
``--minutes`` of wall clock on this machine, one after the other:

=============  ===========================================================================
pipeline       what runs
=============  ===========================================================================
``sb3``        SB3 PPO, one shared policy over every vessel (``benchmarks.learning``,
               ``training/configs/paper_speed_ppo.yaml``)
``torchrl``    MAPPO with TorchRL on the batched TorchRL env (``training.torchrl_ppo``,
               ``training/configs/torchrl/paper_speed_mappo.yaml``)
``benchmarl``  BenchMARL's MAPPO with its default settings on ``marine_formation/paper_speed``
               (``benchmarks.benchmarl_budget``; ecosystem environment)
``rllib``      RLlib PPO, one shared module, 2 env runners (``training.rllib_ppo``,
               ``training/configs/rllib/paper_speed_ppo.yaml``; ecosystem environment)
=============  ===========================================================================

Every pipeline's final policy is then run deterministically by the engine of
``baselines.evaluate`` on the same ``--episodes`` seeds (10 000 +), next to
the reference policy. The table reports vessel-steps processed (each
vessel's transition counts once), training seconds, vessel-steps/s, its ratio
to SB3's, and the mean evaluation return (≤ 0; the reference's is the
yardstick)::

    python -m benchmarks.training_throughput --minutes 15 --ecosystem-python .venv-ecosystem/bin/python \\
        --out runs/training_throughput --json docs/training_throughput.json

The BenchMARL and RLlib steps run with ``--ecosystem-python`` (BenchMARL needs
TorchRL 0.11, RLlib pins gymnasium 1.2.2; see README); without it they are
skipped and say so. RLlib's local Ray instance runs in its own network
namespace (loopback only) when this machine can make one. Pipelines run one
at a time, each in its own process, so none competes with another for the
two cores.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from marine_formation_env.atomic import atomic_write_text, check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least

__all__ = ["PIPELINES", "format_table", "main"]

PIPELINES = ("sb3", "torchrl", "benchmarl", "rllib")
ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "training" / "configs"


def _command(name: str, minutes: float, episodes: int, seed: int, folder: Path, eco: str | None) -> list[str] | None:
    """The command line of one pipeline (None: it needs the ecosystem interpreter and none was given)."""
    here = sys.executable
    if name == "sb3":
        return [here, "-m", "benchmarks.learning", "--level", "speed", "--minutes", str(minutes),
                "--seed", str(seed), "--episodes", str(episodes), "--out", str(folder), "--quiet"]  # fmt: skip
    if name == "torchrl":
        return [here, "-m", "training.torchrl_ppo", "--config", str(CONFIGS / "torchrl" / "paper_speed_mappo.yaml"),
                "--set", f"minutes={minutes}", "--set", "total_frames=1e12", "--set", f"eval_episodes={episodes}",
                "--seed", str(seed), "--out", str(folder), "--overwrite", "--no-progress"]  # fmt: skip
    if eco is None:
        return None
    if name == "benchmarl":
        return [eco, "-m", "benchmarks.benchmarl_budget", "--minutes", str(minutes), "--episodes", str(episodes),
                "--seed", str(seed), "--out", str(folder)]  # fmt: skip
    command = [eco, "-m", "training.rllib_ppo", "--config", str(CONFIGS / "rllib" / "paper_speed_ppo.yaml"),
               "--set", f"minutes={minutes}", "--set", "total_env_steps=1e12", "--set", f"eval_episodes={episodes}",
               "--set", "num_env_runners=2", "--seed", str(seed), "--out", str(folder), "--overwrite",
               "--no-progress"]  # fmt: skip
    return _isolated(command)


def _isolated(command: list[str]) -> list[str]:
    """``command`` in fresh network and PID namespaces when possible (its Ray instance then listens on loopback)."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return command
    prefix = ["unshare", "--net", "--pid", "--fork", "--kill-child", "--mount-proc"]
    probe = subprocess.run([*prefix, "true"], capture_output=True, check=False)
    if probe.returncode != 0:
        return command
    quoted = " ".join(f"'{part}'" for part in command)
    return [*prefix, "bash", "-c", f"ip link set lo up && exec {quoted}"]


def _sb3_evaluation(folder: Path, episodes: int) -> dict[str, Any]:
    """SB3's run folder through the common evaluation (``benchmarks.learning`` has its own seeds)."""
    from training.config import load_config
    from training.learned import evaluate_run, load_learned_policy

    bench = json.loads((folder / "benchmark.json").read_text())
    policy, _ = load_learned_policy(folder / "model.zip")
    raw = load_config(CONFIGS / "paper_speed_ppo.yaml")
    cfg = {"scenario": raw.get("scenario", "paper"), "env_kwargs": raw.get("env_kwargs", {}), "eval_episodes": episodes}
    steps = int(bench["vessel_steps"])
    return evaluate_run(folder, policy, cfg, steps // 3, steps, float(bench["wall_time_s"]))


def run_pipeline(name: str, minutes: float, episodes: int, seed: int, out: Path, eco: str | None) -> dict[str, Any]:
    """Train one pipeline in its own process, evaluate it; its row of the table."""
    folder = out / name
    command = _command(name, minutes, episodes, seed, folder, eco)
    if command is None:
        return {"pipeline": name, "skipped": "needs --ecosystem-python (BenchMARL and RLlib live there)"}
    begin = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - begin
    atomic_write_text(out / f"{name}.log", done.stdout + "\n--- stderr ---\n" + done.stderr)
    if done.returncode != 0:
        return {"pipeline": name, "failed": f"exit {done.returncode}; see {out / (name + '.log')}"}
    if name == "sb3":
        summary = _sb3_evaluation(folder, episodes)
    else:
        summary = json.loads((folder / "evaluation.json").read_text())
    return {
        "pipeline": name,
        "vessel_steps": int(summary["vessel_steps"]),
        "train_seconds": float(summary["seconds"]),
        "vessel_steps_per_s": summary["vessel_steps"] / summary["seconds"] if summary["seconds"] else None,
        "learned_return": summary["learned_return"],
        "reference_return": summary["reference_return"],
        "learned_success": summary["learned_success"],
        "wall_seconds": round(wall, 1),
    }


def format_table(report: dict[str, Any]) -> str:
    """The markdown table of a report (throughput relative to SB3's)."""
    rows = report["pipelines"]
    base = next((r.get("vessel_steps_per_s") for r in rows if r["pipeline"] == "sb3"), None)
    lines = [
        "| pipeline | vessel-steps | training s | vessel-steps/s | × SB3 | return (learned) | return (reference) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "vessel_steps" not in r:
            lines.append(f"| {r['pipeline']} | {r.get('skipped') or r.get('failed')} | | | | | |")
            continue
        rate = r["vessel_steps_per_s"]
        ratio = f"{rate / base:.2f}" if base and rate else "–"
        lines.append(
            f"| {r['pipeline']} | {r['vessel_steps']:,} | {r['train_seconds']:.0f} | {rate:,.0f} | {ratio} | "
            f"{r['learned_return']:.1f} | {r['reference_return']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.training_throughput", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=15.0, help="training budget of each pipeline (default 15)")
    parser.add_argument("--episodes", type=int_at_least(1), default=10, help="evaluation episodes (default 10)")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="training seed of every pipeline (default 0)")
    parser.add_argument("--pipelines", default=",".join(PIPELINES), help=f"comma-separated subset of {PIPELINES}")
    parser.add_argument("--ecosystem-python", default=None, help="interpreter with BenchMARL and RLlib installed")
    parser.add_argument("--out", type=Path, default=Path("runs/training_throughput"), help="folder of the runs")
    parser.add_argument("--json", type=Path, default=None, help="also write the report here")
    args = parser.parse_args(argv)
    if not args.minutes > 0:
        parser.error(f"--minutes must be > 0, got {args.minutes}")
    names = [p.strip() for p in args.pipelines.split(",") if p.strip()]
    unknown = sorted(set(names) - set(PIPELINES))
    if unknown or not names:
        parser.error(f"--pipelines: unknown {unknown or names}; choose from {list(PIPELINES)}")
    if args.ecosystem_python is not None and shutil.which(args.ecosystem_python) is None:
        parser.error(f"--ecosystem-python {args.ecosystem_python!r} is not an executable")
    if args.json is not None:
        check_writable(args.json, "--json")
    args.out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {"minutes": args.minutes, "episodes": args.episodes, "seed": args.seed, "pipelines": []}
    for name in names:
        print(f"{name}: training for {args.minutes:g} min ...", file=sys.stderr, flush=True)
        row = run_pipeline(name, args.minutes, args.episodes, args.seed, args.out, args.ecosystem_python)
        report["pipelines"].append(row)
        print(format_table(report), file=sys.stderr, flush=True)
    text = json.dumps(report, indent=2) + "\n"
    atomic_write_text(args.out / "training_throughput.json", text)
    if args.json is not None:
        atomic_write_text(args.json, text)
    print(format_table(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
