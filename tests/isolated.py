"""Servers in tests, on loopback only, bounded in time, stopped whatever happens.

:func:`run_isolated` runs a shell script in fresh network and PID namespaces
(``unshare``, util-linux): the network has only the loopback interface, so
whatever the script starts (a Ray cluster binds its own node address on every
interface it finds) can only be reached from this machine; the script's
processes are the namespace's, and when the script ends, fails or overruns
its timeout, the namespace's first process is killed and the kernel kills
every process left in it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

__all__ = ["require_isolation", "run_isolated"]

_PREFIX = ["unshare", "--net", "--pid", "--fork", "--kill-child", "--mount-proc"]


def require_isolation() -> None:
    """Skip the test unless this machine can make the namespaces (root, util-linux's unshare, iproute2's ip)."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.skip("needs unshare (util-linux) and ip (iproute2) to isolate a server on loopback")
    probe = subprocess.run([*_PREFIX, "ip", "link", "set", "lo", "up"], capture_output=True, text=True, check=False)
    if probe.returncode != 0:
        pytest.skip(f"cannot create network and PID namespaces here: {probe.stderr.strip()}")


def run_isolated(script: str, timeout: float, cwd: str | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``script`` (bash, ``set -e``) isolated (module docstring); ``$PYTHON`` is this interpreter.

    Raises:
        subprocess.TimeoutExpired: the script ran past ``timeout`` seconds (its processes are gone by then).
    """
    require_isolation()
    body = f"set -e\nip link set lo up\nexport PYTHON={sys.executable}\n{script}"
    return subprocess.run(
        [*_PREFIX, "bash", "-c", body], capture_output=True, text=True, timeout=timeout, cwd=cwd, check=False
    )
