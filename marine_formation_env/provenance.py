"""Where a result comes from: the commit, the command and the machine.

Every script that writes a result file (``baselines.evaluate --json``,
``baselines.sweep``, the ``benchmarks`` scripts) puts ``provenance`` into
it under the key ``provenance``, so that a number in the documentation can be
traced to the code that measured it, the command that regenerates it and the
machine it ran on::

    {"commit": "<short hash of HEAD>", "dirty": false, "command": "python -m baselines.sweep --out docs/sweep_paper",
     "machine": "AMD EPYC 7B13, 2 cores, Linux x86_64, Python 3.11.7", "date": "2026-12-07"}

``commit`` is ``unknown`` outside a git checkout; ``dirty`` says whether the
checkout had uncommitted changes or files git neither tracks nor ignores (the
commit alone does not then describe the code).
"""

from __future__ import annotations

import datetime
import os
import platform
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["command_line", "commit", "machine", "provenance"]

#: The checkout this package sits in (its parent folder).
ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def commit() -> str:
    """The short hash of the checkout's HEAD, or ``unknown`` (no git, or not a checkout)."""
    return _git("rev-parse", "--short", "HEAD") or "unknown"


def _dirty() -> bool | None:
    status = _git("status", "--porcelain")  # untracked files too: a new module is code that ran
    return None if status is None else bool(status)


def machine() -> str:
    """One line: the CPU model (from ``/proc/cpuinfo`` where there is one), cores, OS, architecture, Python."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}, Python {platform.python_version()}"
    )


def command_line(prog: str, argv: Sequence[str] | None = None) -> str:
    """``prog`` and its arguments as typed: ``argv``, or this process's own (``sys.argv[1:]``) when None."""
    return " ".join([prog, *(sys.argv[1:] if argv is None else argv)])


def provenance(command: str) -> dict[str, Any]:
    """The ``provenance`` entry of a result file written by ``command`` now (module docstring)."""
    return {
        "commit": commit(),
        "dirty": _dirty(),
        "command": command,
        "machine": machine(),
        "date": datetime.date.today().isoformat(),
    }
