"""Checks of one value, each raising a :class:`~clothlab.errors.ConfigError` at the value's location.

A :class:`Location` is where a value came from: the source (a file name, or None for a command-line
option), the dotted field and the line.  Messages show the value found with its YAML type and what was
expected, e.g. ``expected an integer >= 1, got 0`` or ``unknown value 'GN_CRS2'; expected one of ...
(did you mean 'GN_CRS2_LM'?)``.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any

from clothlab.errors import ConfigError


@dataclass(frozen=True)
class Location:
    """The location of one value, able to build the ConfigError that names it."""

    source: str | None
    field: str
    line: int | None = None

    def error(self, message: str) -> ConfigError:
        return ConfigError(message, path=self.source, line=self.line, field=self.field)


_TYPE_NAMES = {bool: "true/false", int: "integer", float: "number", str: "string", list: "list",
               dict: "mapping", type(None): "null"}


def shown(value: Any) -> str:
    """``value`` as a message shows it: its repr (cut at 60 characters) and its YAML type."""
    name = _TYPE_NAMES.get(type(value), type(value).__name__)
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({name})"


def suggest(word: Any, choices) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``choices`` to a misspelt ``word``, else ``""``."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def as_str(value: Any, at: Location) -> str:
    """``value`` if it is a string (a number or boolean is refused with a hint to quote it)."""
    if not isinstance(value, str):
        hint = "; quote it" if isinstance(value, int | float | bool) else ""
        raise at.error(f"expected a string, got {shown(value)}{hint}")
    return value


def as_int(value: Any, at: Location, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` if it is an integer (not a boolean, not 11.0) within [lo, hi] (either end optional)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise at.error(f"expected an integer, got {shown(value)}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        if hi is None:
            expected = f">= {lo}"
        elif lo is None:
            expected = f"<= {hi}"
        else:
            expected = f"in [{lo}, {hi}]"
        raise at.error(f"expected an integer {expected}, got {value}")
    return value


def as_number(value: Any, at: Location) -> float:
    """``value`` as a finite float (an integer or a float, not a boolean)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise at.error(f"expected a number, got {shown(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise at.error(f"expected a finite number, got {value!r}")
    return x


def as_choice(value: Any, at: Location, choices, allow_null: bool = False):
    """``value`` if it is one of ``choices`` (or None with ``allow_null``); suggests the closest otherwise."""
    if value is None and allow_null:
        return None
    if not isinstance(value, str) or value not in choices:
        allowed = ", ".join(choices) + (", or null" if allow_null else "")
        raise at.error(f"unknown value {value!r}; expected one of {allowed}{suggest(value, choices)}")
    return value


def as_list(value: Any, at: Location) -> list:
    """``value`` if it is a list."""
    if not isinstance(value, list):
        raise at.error(f"expected a list, got {shown(value)}")
    return value


def check_plain_data(value: Any, at: Location) -> None:
    """Options and kang parameters are passed on as they are; they must be JSON-like data (for the hash)."""
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, str):
                raise at.error(f"keys must be strings, got {shown(k)}")
            check_plain_data(v, at)
    elif isinstance(value, list):
        for v in value:
            check_plain_data(v, at)
    elif isinstance(value, float) and not math.isfinite(value):
        raise at.error(f"expected a finite number, got {value!r}")
    elif not isinstance(value, str | int | float | bool | type(None)):
        raise at.error(f"expected plain data (strings, numbers, lists, mappings), got {shown(value)}")


def as_cli_int(value: Any, at: Location, lo: int | None = None, hi: int | None = None) -> int:
    """A command-line integer: as :func:`as_int`, also accepting its decimal text (``"21"``)."""
    if isinstance(value, str):
        try:
            value = int(value.strip())
        except ValueError:
            raise at.error(f"expected an integer, got {value!r}") from None
    return as_int(value, at, lo, hi)
