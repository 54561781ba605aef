"""The configuration error and the input checks shared by every module.

``ConfigError`` is re-exported by ``marine_formation_env.scenarios``,
where most users meet it; it lives here so that the modules the scenario
configuration is built from (``channel``,
``disturbances``) can raise it too. The checks of
values a user passes at run time (seeds, actions, initial states) live here as
well, so that every front end refuses the same input with the same message.
Every message names the offending field and value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from marine_formation_env.params import ParameterError

__all__ = [
    "ConfigError",
    "UnknownSettingError",
    "build_config",
    "check_bool",
    "check_number",
    "check_seed",
    "checked_array",
    "float_array",
    "whole_periods",
]


class ConfigError(ValueError):
    """An invalid scenario configuration (names the offending value)."""


class UnknownSettingError(ConfigError, TypeError):
    """A keyword that is not a scenario setting.

    Also a ``TypeError`` with Python's own wording ("got an unexpected
    keyword argument 'x'"), which is what wrappers that probe optional
    keywords expect when a keyword is not supported (TorchRL's ``GymEnv``
    passes ``frameskip=`` and retries without it on exactly that error).
    """


def check_number(owner: str, key: str, value: Any, minimum: float | None = 0.0, strict: bool = False) -> None:
    """Raise ``ConfigError`` unless ``value`` is a finite real number (≥ / > ``minimum``)."""
    ok = not isinstance(value, bool) and isinstance(value, (int, float))
    ok = ok and math.isfinite(value)
    if ok and minimum is not None:
        ok = value > minimum if strict else value >= minimum
    if not ok:
        bound = "" if minimum is None else (f" > {minimum:g}" if strict else f" ≥ {minimum:g}")
        raise ConfigError(f"{owner}.{key} must be a finite number{bound}, got {value!r}")


def check_bool(owner: str, key: str, value: Any) -> None:
    """Raise ``ConfigError`` unless ``value`` is ``True`` or ``False`` (a truthy string is not)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{owner}.{key} must be True or False, got {value!r}")


def whole_periods(value: float, dt: float, name: str) -> int:
    """``value / dt`` as a whole number ≥ 1 of control periods; ``ConfigError`` otherwise.

    Things that happen at control instants (transmissions, TDMA slots, graph
    switches) can only be timed in whole control periods.
    """
    ratio = value / dt
    steps = round(ratio)
    if steps < 1 or abs(ratio - steps) > 1e-6 * max(1.0, ratio):
        raise ConfigError(
            f"{name} = {value} s must be a whole number of control periods dt = {dt} s (it takes effect at "
            "control instants)"
        )
    return int(steps)


def check_seed(seed: Any, name: str = "seed", allow_none: bool = True) -> int | None:
    """A seed as a Python ``int`` (or None); refuse anything that is not a whole number ≥ 0.

    Python and numpy integers are accepted; floats (``1.5``, and ``2.0``
    too: a seed is not a measurement), strings and booleans are refused with a
    ``TypeError`` and negative integers with a ``ValueError``, each naming
    ``name`` and the value.
    """
    expected = "a whole number ≥ 0 or None" if allow_none else "a whole number ≥ 0"
    if seed is None and allow_none:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be {expected}, got {seed!r} ({type(seed).__name__})")
    if seed < 0:
        raise ValueError(f"{name} must be {expected}, got {seed!r}")
    return int(seed)


def float_array(value: Any, name: str) -> np.ndarray:
    """``value`` as a float64 array, with a message naming ``name`` and the value if it is not numeric.

    Raises:
        TypeError: strings, objects or ragged nested sequences (numpy's own
            message would not say which input was wrong).
    """
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be numeric, got the string {value!r}")
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a numeric array, got {_short(value)} ({err})") from None


def checked_array(
    value: Any, name: str, shapes: Sequence[tuple[int, ...]], error: type[ValueError] = ValueError, hint: str = ""
) -> np.ndarray:
    """A finite float64 array of one of ``shapes``; ``error`` naming ``name`` and the offending entry otherwise.

    Raises:
        TypeError: not numeric (``float_array``).
        error: another shape (``hint`` describes the columns), or a non-finite entry.
    """
    arr = float_array(value, name)
    if arr.shape not in [tuple(shape) for shape in shapes]:
        expected = " or ".join(str(tuple(shape)) for shape in shapes)
        raise error(f"{name} must have shape {expected}{hint}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise error(f"{name} must be finite, but {name}{list(bad)} = {arr[bad]}")
    return arr


def _short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


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
