"""Which implementation of the step runs: the numpy reference path or the compiled numba kernel.

Both compute the same rules (``marine_formation_env.rules``) and agree to
floating-point rounding (``tests/test_backends.py``).
"""

from __future__ import annotations

import importlib.util
import os

__all__ = ["BACKENDS", "resolve_backend"]

BACKENDS = ("auto", "numpy", "numba")


def resolve_backend(backend: str) -> str:
    """``"numpy"`` or ``"numba"`` for a requested backend (``"auto"``: numba if installed).

    The environment variable ``MARINE_FORMATION_BACKEND`` overrides ``"auto"``.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {list(BACKENDS)}")
    if backend == "auto":
        backend = os.environ.get("MARINE_FORMATION_BACKEND", "auto")
        if backend not in BACKENDS:
            raise ValueError(f"MARINE_FORMATION_BACKEND={backend!r}; choose one of {list(BACKENDS)}")
    if backend == "auto":
        return "numba" if importlib.util.find_spec("numba") is not None else "numpy"
    if backend == "numba" and importlib.util.find_spec("numba") is None:
        raise ImportError("backend 'numba' needs numba: pip install 'marine-formation-env[fast]'")
    return backend
