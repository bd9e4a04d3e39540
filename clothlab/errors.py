"""Errors and warnings that speak the user's language (docs/design.md principle 7).

Every user mistake raises a :class:`ClothlabError` (or a subclass) whose message names the file, line,
field, the value found and what was expected.  The CLI turns it into one line on stderr and exit code 2;
a traceback is reserved for bugs.
"""

from __future__ import annotations


class ClothlabError(Exception):
    """A user-facing error: bad input, bad configuration, a parameter outside its physical range."""

    exit_code = 2

    def __init__(self, message: str, *, path=None, line: int | None = None, field: str | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        self.field = field
        self.detail = message
        where = []
        if self.path:
            where.append(self.path if line is None else f"{self.path}:{line}")
        elif line is not None:
            where.append(f"line {line}")
        if field:
            where.append(f"field '{field}'")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class InputError(ClothlabError):
    """A data file (table, image, weave file) is missing, malformed or holds invalid values."""


class ConfigError(ClothlabError):
    """fabric.yaml (or a command-line override) is invalid."""


class ParameterError(ClothlabError):
    """A model parameter lies outside its documented physical range."""


class ResultExistsError(ClothlabError):
    """A result directory exists and overwriting it was not asked for (``--force``)."""


class ResultBusyError(ClothlabError):
    """Another process is writing the same result directory (its lock file is held)."""


class OutputError(ClothlabError):
    """An output path cannot be written (not a directory, not writable, a name too long, a NUL byte)."""


class ResultError(ClothlabError):
    """A computation produced a result that cannot be trusted (a non-finite coefficient, prediction or
    percentile); nothing is saved."""


class GeometryWarning(UserWarning):
    """A yarn geometry violates a constraint of the paper and was mapped to its documented limit form."""
