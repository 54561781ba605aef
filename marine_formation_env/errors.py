"""The configuration error shared by the configuration modules.

:class:`ConfigError` is re-exported by :mod:`marine_formation_env.scenarios`,
where most users meet it; it lives here so that the modules the scenario
configuration is built from (:mod:`~marine_formation_env.channel`,
:mod:`~marine_formation_env.disturbances`) can raise it too.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["ConfigError", "check_number"]


class ConfigError(ValueError):
    """An invalid scenario configuration (names the offending value)."""


def check_number(owner: str, key: str, value: Any, minimum: float | None = 0.0, strict: bool = False) -> None:
    """Raise ``ConfigError`` unless ``value`` is a finite real number (≥ / > ``minimum``)."""
    ok = not isinstance(value, bool) and isinstance(value, (int, float))
    ok = ok and math.isfinite(value)
    if ok and minimum is not None:
        ok = value > minimum if strict else value >= minimum
    if not ok:
        bound = "" if minimum is None else (f" > {minimum:g}" if strict else f" ≥ {minimum:g}")
        raise ConfigError(f"{owner}.{key} must be a finite number{bound}, got {value!r}")
