"""The configuration error shared by the configuration modules.

:class:`ConfigError` is re-exported by :mod:`marine_formation_env.scenarios`,
where most users meet it; it lives here so that the modules the scenario
configuration is built from (:mod:`~marine_formation_env.channel`,
:mod:`~marine_formation_env.disturbances`) can raise it too.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

from marine_formation_env.params import ParameterError

__all__ = ["ConfigError", "build_config", "check_number"]


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


def build_config(cls: type, values: Mapping[str, Any], name: str) -> Any:
    """``cls(**values)`` for a configuration dataclass, with errors that name ``name``.

    Raises ``ConfigError`` for keys that are not fields of ``cls`` (listing the
    valid ones) and turns a ``ParameterError`` of the constructor into one.
    """
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"unknown {name} key(s) {unknown}; valid keys: {sorted(names)}")
    try:
        return cls(**values)
    except ParameterError as err:
        raise ConfigError(str(err)) from None
