"""Joining a Ray cluster from the project's command lines (``--address``).

``python -m training.rllib_ppo --address ...`` and ``python -m baselines.sweep
--address ...`` share ``connect``. The address is what Ray's own tools
take:

- ``HOST:PORT`` of a running cluster's head (what ``ray start --head`` prints),
- ``auto``: the cluster this machine belongs to (started with ``ray start``),
- ``local``: a Ray instance of this process only (started here, stopped at exit).

A multi-node cluster, one machine as the head, the others joining it (every
node needs this project installed in the same environment, as Ray ships
functions by reference to their module)::

    ray start --head --port=6379                 # on the head; prints its address
    ray start --address=HEAD_IP:6379             # on every other machine
    python -m training.rllib_ppo --address HEAD_IP:6379 ...   # on any node
    ray stop                                     # on every node, when done
"""

from __future__ import annotations

import os
from typing import Any

__all__ = ["RAY_MISSING", "connect"]

#: The message when Ray is not installed.
RAY_MISSING = (
    "Ray is not installed; it comes with the rllib extra: "
    "pip install -c constraints-ecosystem.txt -e '.[rllib]' (see docs/training.md)"
)


def connect(address: str) -> Any:
    """Connect this process to the Ray cluster at ``address`` (see the module docstring) and return ``ray``.

    An already initialized Ray is reused as it is.

    Raises:
        ImportError: Ray is not installed (the message says how to install it).
        ValueError: ``address`` is empty.
        ConnectionError: no cluster answers at ``address`` (Ray's message, with the address).
    """
    try:
        import ray
    except ImportError:
        raise ImportError(RAY_MISSING) from None
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"--address must be HOST:PORT, 'auto' or 'local', got {address!r}")
    if ray.is_initialized():
        return ray
    # the project's modules must be importable by the workers Ray starts on this node
    # (an editable install is; a checkout run from its folder needs its path passed on)
    env_vars = {"PYTHONPATH": os.pathsep.join(p for p in (os.getcwd(), os.environ.get("PYTHONPATH")) if p)}
    kwargs: dict[str, Any] = {"runtime_env": {"env_vars": env_vars}, "log_to_driver": False}
    try:
        if address == "local":
            ray.init(include_dashboard=False, **kwargs)
        else:
            ray.init(address=address, **kwargs)
    except ConnectionError as err:
        raise ConnectionError(f"no Ray cluster at --address {address!r}: {err}") from err
    return ray
