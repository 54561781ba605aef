"""Test-suite settings shared by every module.

The suite runs twice in CI: with the default backend (numba when installed)
and with ``MARINE_FORMATION_BACKEND=numpy``. Modules whose tests do not
depend on the backend carry the marker ``backend_independent`` and are
deselected in the numpy run, where they would test the same code twice: pure
functions, configuration checks, documentation, subprocesses that choose
their backend themselves, ``test_backends.py`` (which builds both), and
everything above the env (training, export, evaluation tools, benchmarks),
which ``test_backends.py``'s step-for-step agreement of the two backends
covers.
"""

from __future__ import annotations

import os

import pytest


@pytest.fixture(autouse=True, scope="session")
def _sb3_logs_in_pytest_s_tmp(tmp_path_factory: pytest.TempPathFactory):
    """SB3's ``learn`` without a log folder makes an empty ``SB3-<date>`` folder in the system's temp directory
    (``stable_baselines3.common.logger.configure``) unless ``SB3_LOGDIR`` names one: the suite's go to pytest's
    own temp directory, which pytest prunes, instead of piling up in /tmp."""
    before = os.environ.get("SB3_LOGDIR")
    os.environ["SB3_LOGDIR"] = str(tmp_path_factory.mktemp("sb3_logs"))
    yield
    if before is None:
        os.environ.pop("SB3_LOGDIR", None)
    else:
        os.environ["SB3_LOGDIR"] = before


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
