"""TorchRL collection throughput: the batched TorchRL env against TorchRL's ``PettingZooWrapper``.

    python -m benchmarks.torchrl_collection --json docs/torchrl_collection.json

A TorchRL collector with a random policy (uniform in the action spec) gathers
frames from, in one run and each case in its own process:

* ``PettingZooWrapper(parallel_env("paper", action_level=...))``: TorchRL's
  generic wrapper over our PettingZoo env, one formation (what a TorchRL user
  gets without this project's TorchRL env);
* ``MarineFormationTorchEnv(num_envs=B)`` for each ``--batch-sizes`` B.

Rates are formation-steps per second (a frame of the wrapper is one
formation-step; a frame of the batched env is one formation of the batch),
steady state as in ``benchmarks.throughput``: a warm-up through episode ends,
then timed repeats (median and spread). The ratio column is against the
wrapper in the same run. The target of the TorchRL issue is ≥ 20× at B ≥ 64.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

from benchmarks.throughput import _time_steps
from marine_formation_env.atomic import atomic_write_text, check_writable
from marine_formation_env.cli import ArgumentParser, int_at_least
from marine_formation_env.provenance import command_line, provenance
from training.torchrl_ppo import make_collector

__all__ = ["main", "run_case"]

BATCH_SIZES = (64, 1024)
#: Formation-steps per collected batch of the batched env, per formation (the wrapper collects this many frames).
STEPS_PER_BATCH = 50


def run_case(case: str, b: int, level: str, min_seconds: float, repeats: int) -> dict[str, Any]:
    """Time one case in this process: ``"wrapper"`` (B is 1) or ``"native"``."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    from marine_formation_env.env import parallel_env
    from marine_formation_env.torchrl import MarineFormationTorchEnv

    if case == "wrapper":
        env: Any = PettingZooWrapper(parallel_env("paper", action_level=level), use_mask=True)
        frames = STEPS_PER_BATCH
        done_key: Any = ("vessel", "done")
    else:
        env = MarineFormationTorchEnv(num_envs=b, scenario="paper", action_level=level)
        frames = STEPS_PER_BATCH * b
        done_key = "done"
    env.set_seed(0)
    collector = make_collector(env, None, frames, -1)  # None: random actions
    batches = iter(collector)

    def step(_: int) -> int:
        data = next(batches)
        done = data.get(("next", *done_key)) if isinstance(done_key, tuple) else data.get(("next", done_key))
        return int(done.any(-1).sum()) if done.ndim > 1 else int(done.sum())

    out = _time_steps(step, min_seconds, repeats)
    collector.shutdown()
    out["formation_steps_per_s"] = out["steps_per_s"] * STEPS_PER_BATCH * (1 if case == "wrapper" else b)
    return out


def _worker(case: str, b: int, level: str, min_seconds: float, repeats: int) -> dict[str, Any]:
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.torchrl_collection",
        "--worker",
        case,
        str(b),
        level,
        str(min_seconds),
        str(repeats),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"exit {done.returncode}"}
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _versions() -> dict[str, str]:
    import numpy
    import torch
    import torchrl

    return {
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "torch": torch.__version__,
        "torchrl": torchrl.__version__,
    }


def format_tables(report: dict[str, Any]) -> str:
    """The markdown table of a report."""
    rows = ["| case | formation-steps/s [slowest–fastest] | / wrapper |", "|---|---|---|"]
    base = report["cases"]["wrapper"].get("formation_steps_per_s")
    for name, case in report["cases"].items():
        if "error" in case:
            rows.append(f"| {name} | failed: {case['error']} | |")
            continue
        scale = case["formation_steps_per_s"] / case["steps_per_s"]
        spread = case["spread"]
        ratio = f"{case['formation_steps_per_s'] / base:.1f}" if base else "n/a"
        rows.append(
            f"| {name} | {case['formation_steps_per_s']:,.0f} "
            f"[{spread['min'] * scale:,.0f}–{spread['max'] * scale:,.0f}] | {ratio} |"
        )
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == "--worker":
        case, b, level, seconds, repeats = argv[1:6]
        print(json.dumps(run_case(case, int(b), level, float(seconds), int(repeats))))
        return 0
    parser = ArgumentParser(prog="python -m benchmarks.torchrl_collection", description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch-sizes", type=int_at_least(1), nargs="+", default=list(BATCH_SIZES))
    parser.add_argument("--level", default="speed", choices=["force", "guidance", "speed"])
    parser.add_argument("--seconds", type=float, default=2.0, help="minimum seconds per timing repeat")
    parser.add_argument("--repeats", type=int_at_least(1), default=5)
    parser.add_argument("--json", default=None, help="write the report here")
    args = parser.parse_args(argv)
    if not args.seconds > 0:
        parser.error(f"argument --seconds: expected a positive number of seconds, got {args.seconds}")
    if args.json:
        check_writable(args.json, "--json")
    cases = {"wrapper": _worker("wrapper", 1, args.level, args.seconds, args.repeats)}
    for b in args.batch_sizes:
        cases[f"MarineFormationTorchEnv B = {b}"] = _worker("native", b, args.level, args.seconds, args.repeats)
    report = {"level": args.level, "versions": _versions(), "cases": cases}
    report["provenance"] = provenance(command_line("python -m benchmarks.torchrl_collection", argv))
    if args.json:
        atomic_write_text(args.json, json.dumps(report, indent=2) + "\n")
    print(format_tables(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
