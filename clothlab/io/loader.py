"""One entry point for measurement files: detect the format, dispatch to its reader.

Detection (first 200 lines of a file):

- ``clothlab``: a ``# clothlab-table`` header line, or a sidecar ``<file>.yaml`` / ``<stem>.yaml``;
- ``pabopto``: a ``#format:``, ``#intheta``, ``#inphi`` or ``#incident_angle`` header line; a directory is
  read as the pab-opto files of one sample;
- ``astm``: a ``NUM_POINTS`` or ``VARS`` keyword line.

``format=`` (other than ``"auto"``) skips detection; ``**options`` go to the reader
(:func:`clothlab.io.astm.read_astm`'s conventions, :func:`clothlab.io.pabopto.read_pabopto`'s ``up``; the
clothlab table takes none).
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from clothlab.errors import InputError
from clothlab.io.astm import read_astm
from clothlab.io.measurement import Measurement
from clothlab.io.pabopto import SAMPLE_UP, read_pabopto
from clothlab.io.table import CONVENTION_CHOICES, check_row_count, find_sidecar, read_table
from clothlab.strict import MAX_LINE_CHARS, MAX_TABLE_BYTES, check_regular_file

READERS = {"clothlab": read_table, "astm": read_astm, "pabopto": read_pabopto}
FORMATS = tuple(READERS)
"""The measurement formats clothlab reads (fabric.yaml ``measurement.format`` names one, or ``auto``)."""
AUTO = "auto"
"""``format="auto"`` (like None) detects the format with :func:`detect_format`."""
FORMAT_CHOICES = (AUTO, *FORMATS)
"""Every value ``measurement.format`` accepts."""
OPTION_CHOICES = {**{name: tuple(values) for name, values in CONVENTION_CHOICES.items()}, "up": tuple(SAMPLE_UP)}
"""The allowed values of each reader option (the conventions of a table, the pab-opto sample ``up``)."""
_DETECT_LINES = 200
_CLOTHLAB = re.compile(r"^#\s*clothlab-table\s*:")
_PABOPTO = re.compile(r"^#\s*(format\s*:|intheta\b|inphi\b|incident_angle\b)", re.IGNORECASE)
_ASTM = re.compile(r"^\s*(NUM_POINTS|VARS)\b", re.IGNORECASE)


def _existing(path) -> Path:
    """``path`` as a Path, or InputError if it holds a NUL byte or names nothing."""
    if "\x00" in str(path):
        raise InputError("measurement path holds a NUL byte", path=repr(str(path)))
    path = Path(path)
    try:
        exists = path.exists()
    except OSError as exc:  # e.g. a name too long for the file system
        raise InputError(f"cannot open the measurement path: {exc.strerror or exc}", path=path) from None
    if not exists:
        raise InputError("measurement file or directory not found", path=path)
    return path


def detect_format(path) -> str:
    """The format name of a measurement file or directory (one of :data:`FORMATS`), or InputError."""
    path = _existing(path)
    if path.is_dir():
        return "pabopto"
    check_regular_file(path, limit=MAX_TABLE_BYTES, what="measurement file")
    try:
        with open(path, "rb") as handle:
            head = [handle.readline(MAX_LINE_CHARS) for _ in range(_DETECT_LINES)]
    except OSError as exc:
        raise InputError(f"cannot read the measurement file: {exc.strerror or exc}", path=path) from None
    text = b"".join(head).decode("utf-8", errors="replace").removeprefix("\ufeff")
    if not text.strip():
        if find_sidecar(path) is not None:
            return "clothlab"
        raise InputError("file is empty; expected a measurement table", path=path)
    lines = text.splitlines()
    if any(_CLOTHLAB.match(line) for line in lines) or find_sidecar(path) is not None:
        return "clothlab"
    if any(_PABOPTO.match(line) for line in lines):
        return "pabopto"
    if any(_ASTM.match(line) for line in lines):
        return "astm"
    raise InputError(
        "unknown measurement format: expected a clothlab table ('# clothlab-table: 1' header or a sidecar "
        f"{path.name}.yaml), an ASTM E1392 file (NUM_POINTS / VARS keywords) or pab-opto files ('#format:', "
        "'#intheta' or '#incident_angle' lines); or pass format= one of " + ", ".join(FORMATS), path=path)


def check_reader_options(path, format: str, options: dict) -> None:  # noqa: A002
    """InputError (``field`` = the option name) for an option the reader of ``format`` does not take or a
    value outside its choices; ``format='auto'`` detects the format of ``path`` first."""
    if format is None or format == AUTO:
        format = detect_format(path)
    reader = READERS[format]
    declared = {p.name: p.default for p in inspect.signature(reader).parameters.values()
                if p.kind == p.KEYWORD_ONLY}
    for name, value in options.items():
        if name not in declared:
            raise InputError(f"option {name!r} is not accepted by the {format} reader; it takes "
                             f"{', '.join(declared) or 'no options'}", path=path, field=name)
        choices = OPTION_CHOICES.get(name)
        if choices is not None and value not in choices:
            raise InputError(f"unknown {name} {value!r} for the {format} reader; expected one of "
                             f"{' | '.join(choices)}", path=path, field=name)


def load_measurement(path, format: str | None = None, **options) -> Measurement:  # noqa: A002
    """Load a measurement in any supported format into clothlab's convention (degrees, BRDF in 1/sr).

    The measurement must hold at least :data:`clothlab.io.table.MIN_ROWS` rows (the readers themselves
    also read one-row tables, e.g. a single direction to evaluate)."""
    if format is None or format == AUTO:
        format = detect_format(path)
    elif format not in READERS:
        raise InputError(f"unknown measurement format {format!r}; expected one of {', '.join(FORMATS)}",
                         path=path, field="format")
    else:
        _existing(path)
    check_reader_options(path, format, options)
    measurement = READERS[format](path, **options)
    check_row_count(measurement.n, path)
    return measurement
