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
               ``training/configs/torchrl/paper_speed_mappo.yaml`` without its ``train_reward``:
               every pipeline learns from the benchmark's reward)
``benchmarl``  BenchMARL's MAPPO with its default settings on ``marine_formation/paper_speed``
               (``benchmarks.benchmarl_budget``; ecosystem environment)
``rllib``      RLlib PPO, one shared module, 2 env runners (``training.rllib_ppo``,
               ``training/configs/rllib/paper_speed_ppo.yaml``; ecosystem environment)
=============  ===========================================================================

Every pipeline's final policy is then run deterministically by the engine of
``baselines.evaluate`` on the same ``--episodes`` seeds (10 000 +), next to
the reference policy. With ``--seeds 0,1,2`` every pipeline trains once per
seed (seed-major: seed 0's pipelines, then seed 1's, ..., so a change in the
machine's load falls on every pipeline alike). The table reports, per
pipeline over its seeds, the mean, the sample standard deviation and the
min–max of vessel-steps/s (each vessel's transition counts once) and of the
mean evaluation return (≤ 0; the reference's is the yardstick), the ratio of
the mean rate to SB3's, and whether the throughput target holds (≥ 5× SB3's
mean vessel-steps/s and a mean return ≥ SB3's); a second table lists every
run::

    python -m benchmarks.training_throughput --minutes 15 --ecosystem-python .venv-ecosystem/bin/python \\
        --out runs/training_throughput --json docs/training_throughput.json
    python -m benchmarks.training_throughput --minutes 15 --pipelines sb3,torchrl --seeds 0,1,2 \\
        --out runs/tt_seeds --json docs/training_throughput_seeds.json

The JSON (``OUT/training_throughput.json`` and ``--json``) keeps every run
(``runs``, with its seed) and the per-pipeline summaries (``pipelines``); it
is rewritten atomically after each run (``complete`` is false until the
last), so an interrupted measurement keeps what it finished. Each run's
folder is ``OUT/seed_<s>/<pipeline>``.

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
from marine_formation_env.provenance import command_line, provenance
from training.config import load_config
from training.learned import evaluate_run, load_learned_policy

__all__ = ["PIPELINES", "TARGET_RATIO", "format_runs", "format_table", "main", "parse_seeds", "summarize"]

PIPELINES = ("sb3", "torchrl", "benchmarl", "rllib")
#: The throughput target: this many times SB3's vessel-steps/s, at a mean return at least SB3's.
TARGET_RATIO = 5.0
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
                "--set", "train_reward={}",  # the benchmark's reward, as every other pipeline trains on
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
    bench = json.loads((folder / "benchmark.json").read_text())
    policy, _ = load_learned_policy(folder / "model.zip")
    raw = load_config(CONFIGS / "paper_speed_ppo.yaml")
    cfg = {"scenario": raw.get("scenario", "paper"), "env_kwargs": raw.get("env_kwargs", {}), "eval_episodes": episodes}
    steps = int(bench["vessel_steps"])
    return evaluate_run(folder, policy, cfg, vessel_steps=steps, wall_time_s=float(bench["wall_time_s"]))


def run_pipeline(name: str, minutes: float, episodes: int, seed: int, out: Path, eco: str | None) -> dict[str, Any]:
    """Train one pipeline with one seed in its own process (folder ``out/<name>``), evaluate it; its run's row."""
    folder = out / name
    command = _command(name, minutes, episodes, seed, folder, eco)
    if command is None:
        return {"pipeline": name, "seed": seed, "skipped": "needs --ecosystem-python (BenchMARL and RLlib live there)"}
    out.mkdir(parents=True, exist_ok=True)
    begin = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - begin
    log = out / f"{name}.log"
    atomic_write_text(log, done.stdout + "\n--- stderr ---\n" + done.stderr)
    if done.returncode != 0:
        return {"pipeline": name, "seed": seed, "failed": f"exit {done.returncode}; see {log}"}
    if name == "sb3":
        summary = _sb3_evaluation(folder, episodes)
    else:
        summary = json.loads((folder / "evaluation.json").read_text())
    return {
        "pipeline": name,
        "seed": seed,
        "vessel_steps": int(summary["vessel_steps"]),
        "train_seconds": float(summary["wall_time_s"]),
        "vessel_steps_per_s": summary["vessel_steps"] / summary["wall_time_s"] if summary["wall_time_s"] else None,
        "learned_return": summary["learned_return"],
        "reference_return": summary["reference_return"],
        "learned_success": summary["learned_success"],
        "wall_seconds": round(wall, 1),
    }


#: The per-run quantities summarized over seeds.
MEASURES = ("vessel_steps", "train_seconds", "vessel_steps_per_s", "learned_return", "reference_return")


def _spread(values: list[float]) -> dict[str, Any]:
    """Mean, sample standard deviation (ddof 1; 0 for one value), min, max and the values themselves."""
    mean = sum(values) / len(values)
    var = sum((v - mean) ** 2 for v in values) / (len(values) - 1) if len(values) > 1 else 0.0
    return {"mean": mean, "std": var**0.5, "min": min(values), "max": max(values), "per_seed": values}


def summarize(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One summary per pipeline (in the order first seen) over the runs that finished.

    Each summary has ``seeds`` (those that finished) and, per quantity of
    ``MEASURES``, ``{mean, std, min, max, per_seed}``; runs that failed or
    were skipped are listed under ``failed`` / ``skipped``. Every pipeline
    other than SB3 also gets ``vs_sb3``: the ratio of its mean vessel-steps/s
    to SB3's, its mean return minus SB3's, and ``target_met`` (ratio ≥
    ``TARGET_RATIO`` and the return difference ≥ 0).
    """
    names = list(dict.fromkeys(r["pipeline"] for r in runs))
    summaries: list[dict[str, Any]] = []
    for name in names:
        mine = [r for r in runs if r["pipeline"] == name]
        ok = [r for r in mine if "vessel_steps" in r and r["vessel_steps_per_s"] is not None]
        row: dict[str, Any] = {"pipeline": name, "seeds": [r["seed"] for r in ok]}
        for key in ("failed", "skipped"):
            bad = {str(r["seed"]): r[key] for r in mine if key in r}
            if bad:
                row[key] = bad
        if ok:
            row.update({key: _spread([float(r[key]) for r in ok]) for key in MEASURES})
        summaries.append(row)
    base = next((s for s in summaries if s["pipeline"] == "sb3" and s["seeds"]), None)
    for row in summaries:
        if base is None or row is base or not row["seeds"]:
            continue
        ratio = row["vessel_steps_per_s"]["mean"] / base["vessel_steps_per_s"]["mean"]
        gap = row["learned_return"]["mean"] - base["learned_return"]["mean"]
        row["vs_sb3"] = {
            "rate_ratio": ratio,
            "return_difference": gap,
            "target_met": ratio >= TARGET_RATIO and gap >= 0,
        }
    return summaries


def format_table(report: dict[str, Any]) -> str:
    """The markdown table of the per-pipeline summaries (mean ± std (min – max) over seeds; rate relative to SB3)."""
    lines = [
        "| pipeline | seeds | vessel-steps/s: mean ± std (min – max) | × SB3 | "
        "return (learned): mean ± std (min – max) | return (reference) | ≥ 5× and return ≥ SB3's |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in report["pipelines"]:
        if not r["seeds"]:
            why = "; ".join(f"seed {s}: {m}" for s, m in {**r.get("skipped", {}), **r.get("failed", {})}.items())
            lines.append(f"| {r['pipeline']} | {why} | | | | | |")
            continue
        rate, ret, vs = r["vessel_steps_per_s"], r["learned_return"], r.get("vs_sb3")
        seeds = ", ".join(str(s) for s in r["seeds"])
        if "failed" in r or "skipped" in r:
            seeds += f" ({len(r.get('failed', {})) + len(r.get('skipped', {}))} not finished)"
        ratio = "1.00" if r["pipeline"] == "sb3" else (f"{vs['rate_ratio']:.2f}" if vs else "–")
        met = "–" if vs is None else ("met" if vs["target_met"] else "not met")
        lines.append(
            f"| {r['pipeline']} | {seeds} | {rate['mean']:,.0f} ± {rate['std']:,.0f} ({rate['min']:,.0f} – "
            f"{rate['max']:,.0f}) | {ratio} | {ret['mean']:.1f} ± {ret['std']:.1f} ({ret['min']:.1f} – "
            f"{ret['max']:.1f}) | {r['reference_return']['mean']:.1f} | {met} |"
        )
    return "\n".join(lines) + "\n"


def format_runs(report: dict[str, Any]) -> str:
    """The markdown table of every run (one row per pipeline and seed)."""
    lines = [
        "| pipeline | seed | vessel-steps | training s | vessel-steps/s | return (learned) | return (reference) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in report["runs"]:
        if "vessel_steps" not in r:
            lines.append(f"| {r['pipeline']} | {r['seed']} | {r.get('skipped') or r.get('failed')} | | | | |")
            continue
        rate = r["vessel_steps_per_s"]
        lines.append(
            f"| {r['pipeline']} | {r['seed']} | {r['vessel_steps']:,} | {r['train_seconds']:.0f} | "
            f"{rate:,.0f} | {r['learned_return']:.1f} | {r['reference_return']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def parse_seeds(text: str) -> list[int]:
    """``"0,1,2"`` → ``[0, 1, 2]``: distinct whole numbers ≥ 0 (``ValueError`` names the bad item)."""
    items = [item.strip() for item in text.split(",")]
    seeds: list[int] = []
    for item in items:
        if not item.isdigit():
            raise ValueError(f"--seeds: expected comma-separated whole numbers ≥ 0, got {item!r} in {text!r}")
        if int(item) in seeds:
            raise ValueError(f"--seeds: seed {int(item)} given twice in {text!r}")
        seeds.append(int(item))
    return seeds


def _write(report: dict[str, Any], out: Path, json_path: Path | None) -> None:
    text = json.dumps(report, indent=2) + "\n"
    atomic_write_text(out / "training_throughput.json", text)
    if json_path is not None:
        atomic_write_text(json_path, text)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m benchmarks.training_throughput", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=15.0, help="training budget of each pipeline (default 15)")
    parser.add_argument("--episodes", type=int_at_least(1), default=10, help="evaluation episodes (default 10)")
    seeds = parser.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", default=None, help="comma-separated training seeds, each run by every pipeline")
    seeds.add_argument("--seed", type=int_at_least(0), default=None, help="one training seed (= --seeds N; default 0)")
    parser.add_argument("--pipelines", default=",".join(PIPELINES), help=f"comma-separated subset of {PIPELINES}")
    parser.add_argument("--ecosystem-python", default=None, help="interpreter with BenchMARL and RLlib installed")
    parser.add_argument("--out", type=Path, default=Path("runs/training_throughput"), help="folder of the runs")
    parser.add_argument("--json", type=Path, default=None, help="also write the report here")
    args = parser.parse_args(argv)
    if not args.minutes > 0:
        parser.error(f"--minutes must be > 0, got {args.minutes}")
    try:
        seed_list = parse_seeds(args.seeds) if args.seeds is not None else [0 if args.seed is None else args.seed]
    except ValueError as err:
        parser.error(str(err))
    names = [p.strip() for p in args.pipelines.split(",") if p.strip()]
    unknown = sorted(set(names) - set(PIPELINES))
    if unknown or not names:
        parser.error(f"--pipelines: unknown {unknown or names}; choose from {list(PIPELINES)}")
    if args.ecosystem_python is not None and shutil.which(args.ecosystem_python) is None:
        parser.error(f"--ecosystem-python {args.ecosystem_python!r} is not an executable")
    try:
        if args.json is not None:
            check_writable(args.json, "--json")
        check_writable(args.out / "training_throughput.json", "--out")
    except ValueError as err:
        parser.error(str(err))
    report: dict[str, Any] = {
        "provenance": provenance(command_line("python -m benchmarks.training_throughput", argv)),
        "minutes": args.minutes,
        "episodes": args.episodes,
        "seeds": seed_list,
        "spread": "std is the sample standard deviation over seeds (ddof 1); min and max over seeds",
        "complete": False,
        "runs": [],
        "pipelines": [],
    }
    for seed in seed_list:
        for name in names:
            print(f"{name}, seed {seed}: training for {args.minutes:g} min ...", file=sys.stderr, flush=True)
            row = run_pipeline(
                name, args.minutes, args.episodes, seed, args.out / f"seed_{seed}", args.ecosystem_python
            )
            report["runs"].append(row)
            report["pipelines"] = summarize(report["runs"])
            _write(report, args.out, args.json)
            print(format_runs(report), file=sys.stderr, flush=True)
    report["complete"] = True
    _write(report, args.out, args.json)
    print(format_table(report))
    print(format_runs(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
