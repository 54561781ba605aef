"""What every command-line tool of the project shares: the ``--set`` grammar and one-line errors.

Standard library only, so the core package stays light; the CLIs in
``baselines`` and ``training`` import from here (and never from each other's
entry points).

* ``parse_overrides`` reads ``--set KEY=VALUE`` items (values are
  Python/JSON literals, anything else a string; ``PARENT.FIELD=VALUE`` nests).
* ``ArgumentParser`` reports a bad argument as one line,
  ``prog: error: <message>``, and exits with status 2 (argparse's usual code),
  without the usage block and without a traceback.
* ``int_at_least`` builds argparse ``type=`` checks such as ``--seed ≥ 0``.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

__all__ = ["ArgumentParser", "int_at_least", "parse_overrides", "report_error"]


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line on stderr and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(str(message).split())}\n")


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type=`` that accepts whole numbers ≥ ``minimum`` and names the value otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number ≥ {minimum}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number ≥ {minimum}, got {value}")
        return value

    parse.__name__ = f"integer ≥ {minimum}"
    return parse


def parse_overrides(items: Sequence[str], nest: bool = True) -> dict[str, Any]:
    """Parse ``KEY=VALUE`` strings; VALUE is a Python/JSON literal or a plain string.

    ``true``/``false``/``null``/``none`` (any case) read as ``True``/``False``/``None``.
    ``PARENT.FIELD=VALUE`` collects into ``{PARENT: {FIELD: VALUE}}``, which
    ``make_config`` merges into the
    scenario's setting field by field; ``nest=False`` keeps dotted keys as
    they are (for configs that resolve dots themselves, as ``training.train``).

    Raises:
        ValueError: an item without ``=`` or with an empty key, or a dotted
            key whose parent was set to a value that is not a mapping.
    """
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        text = raw.strip()
        lowered = {"true": "True", "false": "False", "null": "None", "none": "None"}.get(text.lower(), text)
        try:
            value = ast.literal_eval(lowered)
        except (ValueError, SyntaxError, MemoryError, RecursionError):
            value = text
        parent, dot, child = key.partition(".")
        if dot and nest:
            if not parent or not child or "." in child:
                raise ValueError(f"--set expects KEY=VALUE or PARENT.FIELD=VALUE, got {item!r}")
            nested = out.setdefault(parent, {})
            if not isinstance(nested, dict):
                raise ValueError(f"--set {item!r}: {parent} was already set to {nested!r}")
            nested[child] = value
        else:
            out[key] = value
    return out


def report_error(prog: str, message: str) -> NoReturn:
    """Print ``prog: error: message`` (one line) to stderr and exit with status 2."""
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr)
    raise SystemExit(2)
