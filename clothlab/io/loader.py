"""One entry point for measurement files: detect the format, dispatch to its reader.

Detection (first 200 lines of a file):

- ``clothlab``: a ``# clothlab-table`` header line, or a sidecar ``<file>.yaml`` / ``<stem>.yaml``;
- ``pabopto``: a ``#format:``, ``#intheta``, ``#inphi`` or ``#incident_angle`` header line; a directory is
  read as the pab-opto files of one sample;
- ``astm``: a ``NUM_POINTS`` or ``VARS`` keyword line;
- binary tables, from their first bytes, size and name: ``bsdf`` (RGL-EPFL) the ``tensor_file`` magic;
  ``utia`` a ``*.bin`` file of 1,990,656 bytes; ``merl`` a ``*.binary`` file with a plausible int32 dims
  header; a ``.bsdf`` / ``.bin`` / ``.binary`` file that is not text goes to that reader, which names the
  fault at its byte offset.

``text`` (a lab's own table, :func:`clothlab.io.generic.read_generic`) is never detected: name it with
``format: text`` and give its column mapping and conventions as options.

``format=`` (other than ``"auto"``) skips detection; ``**options`` go to the reader
(:func:`clothlab.io.astm.read_astm`'s conventions, :func:`clothlab.io.pabopto.read_pabopto`'s ``up``, the
sampling of :func:`clothlab.io.merl.read_merl` and :func:`clothlab.io.rglbsdf.read_bsdf`; the clothlab table
takes none).
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from clothlab.errors import ClothlabError, InputError
from clothlab.io.astm import read_astm
from clothlab.io.generic import DELIMITERS, HEADER_CHOICES, read_generic
from clothlab.io.generic import check_options as check_generic_options
from clothlab.io.measurement import Measurement
from clothlab.io.merl import HEADER_BYTES as MERL_HEADER_BYTES
from clothlab.io.merl import MAX_DIM as MAX_MERL_DIM
from clothlab.io.merl import check_options as check_merl_options
from clothlab.io.merl import read_merl
from clothlab.io.pabopto import SAMPLE_UP, read_pabopto
from clothlab.io.rglbsdf import MAGIC as TENSOR_MAGIC
from clothlab.io.rglbsdf import check_options as check_bsdf_options
from clothlab.io.rglbsdf import read_bsdf
from clothlab.io.table import CONVENTION_CHOICES, check_row_count, find_sidecar, read_table
from clothlab.io.utia import NEGATIVE, UTIA_BYTES, read_utia
from clothlab.io.utia import check_options as check_utia_options
from clothlab.untrusted import MAX_LINE_CHARS, MAX_TABLE_BYTES, check_regular_file

READERS = {"clothlab": read_table, "astm": read_astm, "pabopto": read_pabopto, "text": read_generic,
           "merl": read_merl, "utia": read_utia, "bsdf": read_bsdf}
FORMATS = tuple(READERS)
"""The measurement formats clothlab reads (fabric.yaml ``measurement.format`` names one, or ``auto``)."""
AUTO = "auto"
"""``format="auto"`` (like None) detects the format with :func:`detect_format`."""
FORMAT_CHOICES = (AUTO, *FORMATS)
"""Every value ``measurement.format`` accepts."""
OPTION_CHOICES = {**{name: tuple(values) for name, values in CONVENTION_CHOICES.items()}, "up": tuple(SAMPLE_UP),
                  "delimiter": tuple(DELIMITERS), "header": HEADER_CHOICES, "negative": NEGATIVE}
"""The allowed values of each reader option (the conventions of a table, the pab-opto sample ``up``, the
text importer's delimiter and header, UTIA's handling of negative values)."""
OPTION_CHECKS = {"text": check_generic_options, "merl": check_merl_options, "utia": check_utia_options,
                 "bsdf": check_bsdf_options}
"""Per reader, a check of its option values that needs no file (raises with ``field`` = the option)."""
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
            first = handle.read(4096)
            handle.seek(0)
            head = [handle.readline(MAX_LINE_CHARS) for _ in range(_DETECT_LINES)]
    except OSError as exc:
        raise InputError(f"cannot read the measurement file: {exc.strerror or exc}", path=path) from None
    binary = _binary_format(path, first[:len(TENSOR_MAGIC)], first)
    if binary is not None:
        return binary
    text = b"".join(head).decode("utf-8", errors="replace").removeprefix("\ufeff")
    if not text.strip():
        if find_sidecar(path) is not None:
            return "clothlab"
        raise InputError("file is empty; expected a measurement table", path=path, line=1)
    lines = text.splitlines()
    if any(_CLOTHLAB.match(line) for line in lines) or find_sidecar(path) is not None:
        return "clothlab"
    if any(_PABOPTO.match(line) for line in lines):
        return "pabopto"
    if any(_ASTM.match(line) for line in lines):
        return "astm"
    raise InputError(
        "unknown measurement format: expected a clothlab table ('# clothlab-table: 1' header or a sidecar "
        f"{path.name}.yaml), an ASTM E1392 file (NUM_POINTS / VARS keywords), pab-opto files ('#format:', "
        "'#intheta' or '#incident_angle' lines) or a MERL / UTIA / RGL-EPFL binary; or pass format= one of "
        + ", ".join(FORMATS) + " (text: a lab's own table with its column mapping)", path=path, line=1,
        field="format")


def _looks_binary(head: bytes) -> bool:
    """True when the first bytes hold a NUL or are not UTF-8 (a truncated multi-byte end allowed)."""
    if b"\x00" in head:
        return True
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return exc.start < len(head) - 3
    return False


def _binary_format(path: Path, first: bytes, head: bytes) -> str | None:
    """``bsdf``, ``utia`` or ``merl`` when the first bytes, size and name say so, else None (a text file).

    A ``.binary`` / ``.bin`` file that is binary but does not match its layout is still given to the MERL /
    UTIA reader, so that the message names what is wrong (truncated, bad dims header) at its byte offset.
    """
    if first == TENSOR_MAGIC:
        return "bsdf"
    suffix = path.suffix.lower()
    if suffix == ".bsdf" and (_looks_binary(head) or not head):  # empty: the reader names the truncation
        return "bsdf"
    if suffix == ".bin" and (path.stat().st_size == UTIA_BYTES or _looks_binary(head) or not head):
        return "utia"
    if suffix == ".binary":
        if len(first) < MERL_HEADER_BYTES:  # too short for any table: the MERL reader names the truncation
            return "merl"
        dims = [int.from_bytes(first[k:k + 4], "little", signed=True) for k in (0, 4, 8)]
        if all(0 < n <= MAX_MERL_DIM for n in dims) or _looks_binary(head):
            return "merl"
    return None


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
    check = OPTION_CHECKS.get(format)
    if check is not None:  # the values themselves, before the file is read
        try:
            check(**options)
        except ClothlabError as exc:
            raise InputError(exc.detail, path=path, field=exc.field) from None


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
