"""Test-suite settings shared by every module.

The suite runs twice in CI: with the default backend (numba when installed)
and with ``MARINE_FORMATION_BACKEND=numpy``. Modules whose tests do not
depend on the backend (pure functions, configuration checks, documentation,
subprocesses that choose their backend themselves) carry the marker
``backend_independent`` and are deselected in the numpy run: they would test
the same code twice.
"""

from __future__ import annotations

import os

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("MARINE_FORMATION_BACKEND") != "numpy":
        return
    keep, drop = [], []
    for item in items:
        (drop if item.get_closest_marker("backend_independent") else keep).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


def record_calls(monkeypatch: pytest.MonkeyPatch, cls: type, name: str) -> list:
    """Wrap the method ``cls.name`` (for this test) so that it still runs and records its one argument per call."""
    calls: list = []
    original = getattr(cls, name)

    def recorded(self, value):
        calls.append(value)
        return original(self, value)

    monkeypatch.setattr(cls, name, recorded)
    return calls
