"""Generic text / CSV reflectance tables with the conventions given by the user (``clothlab import``).

A lab's own export - whitespace, comma or semicolon separated, optional comment lines and an optional row of
column names - is read with a column mapping and the file's conventions stated explicitly (nothing is
guessed but the delimiter when ``delimiter='auto'``), validated like every other table
(:func:`clothlab.io.table.rows_to_measurement`: finite numbers, 0 <= theta <= 90 deg, values >= 0, sigma > 0,
no repeated direction pair) and converted once into clothlab's convention (docs/design.md principle 1).

Column mapping (``columns``), one entry per clothlab column:

- positional: ``theta_i,phi_i,theta_o,phi_o,R,G,B`` names the file's columns in order (``-`` skips one);
- by header name: ``theta_i=ti,phi_i=pi,theta_o=tv,phi_o=pv,R=red`` maps clothlab names to the names in the
  file's header row;
- omitted: the file's header row must name ``theta_i, phi_i, theta_o, phi_o`` itself; every other column is
  a channel (``sigma_<channel>`` columns are uncertainties).

Every name other than the four angles and ``sigma_<channel>`` is a value channel, named as given (or renamed
in order with ``channels``).  The result is a :class:`~clothlab.io.measurement.Measurement`;
:func:`import_table` writes it as a clothlab table (atomically, never over an existing file without
``overwrite``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError, InputError
from clothlab.io.measurement import Measurement
from clothlab.io.table import (
    _CHANNEL_NAME,
    ANGLE_COLUMNS,
    SIGMA_PREFIX,
    RawRows,
    check_azimuth_offset,
    check_choice,
    check_row_count,
    conventions_provenance,
    parse_rows,
    read_text_lines,
    rows_to_measurement,
    write_table,
)

DELIMITERS = {"auto": None, "whitespace": None, "comma": ",", "semicolon": ";", "tab": "\t"}
"""``delimiter`` choices and their separator (whitespace: runs of blanks and tabs)."""
HEADER_CHOICES = ("auto", "yes", "no")
"""``header``: whether the first non-comment line names the columns (auto: it does if it is not numeric)."""
SKIP = "-"
_NAME_START = re.compile(r"^[\"']?[A-Za-z_]")
_NOT_NAMES = ("nan", "inf", "infinity", "+inf", "-inf")


def _is_header(fields) -> bool:
    """True when every field of a row looks like a column name (starts with a letter or '_', and is not a
    spelling of NaN or infinity, which are bad numbers in a data row)."""
    return all(_NAME_START.match(f) and f.lower().strip("\"'") not in _NOT_NAMES for f in fields)


@dataclass(frozen=True)
class ColumnMap:
    """Which file column holds each clothlab column: ``positions`` (index per name) or ``names`` (header name
    per name)."""

    order: tuple[str, ...]
    positions: dict | None = None
    names: dict | None = None
    width: int | None = None
    """Positional form: how many columns the mapping names, skipped ('-') ones included."""


def parse_columns(spec) -> ColumnMap | None:
    """A :class:`ColumnMap` from ``"theta_i,phi_i,..."`` / ``"theta_i=ti,..."`` (or a list of entries); None
    for None.  ConfigError (field ``columns``) for a malformed mapping."""
    if spec is None:
        return None
    entries = _name_list(spec, "columns")
    if not entries or not all(entries):
        raise ConfigError(f"columns must be comma-separated names, got {spec!r}", field="columns")
    by_name = [e for e in entries if "=" in e]
    if by_name and len(by_name) != len(entries):
        raise ConfigError("columns mixes positional names and name=header entries; use one form",
                          field="columns")
    if by_name:
        pairs = [tuple(part.strip() for part in e.split("=", 1)) for e in entries]
        order = tuple(p[0] for p in pairs)
        _check_names(order)
        if any(not header for _, header in pairs):
            raise ConfigError(f"columns entry with an empty header name in {spec!r}", field="columns")
        return ColumnMap(order, names=dict(pairs))
    order = tuple(e for e in entries if e != SKIP)
    _check_names(order)
    return ColumnMap(order, positions={name: k for k, name in enumerate(entries) if name != SKIP},
                     width=len(entries))


def _name_list(value, field: str) -> list[str]:
    """The stripped entries of a comma-separated string or a list of strings; ConfigError (``field``) for any
    other value (a number, a mapping, a list holding a non-string)."""
    if isinstance(value, str):
        return [e.strip() for e in value.split(",")]
    if not isinstance(value, list | tuple) or not all(isinstance(e, str) for e in value):
        raise ConfigError(f"{field} must be comma-separated names or a list of names, got {value!r}", field=field)
    return [e.strip() for e in value]


def _check_names(order) -> None:
    seen = set()
    for name in order:
        if name in seen:
            raise ConfigError(f"column {name!r} is mapped twice", field="columns")
        seen.add(name)
        if re.search(r"[\s,#'\"]", name):
            raise ConfigError(f"column name {name!r} holds a space, comma or quote", field="columns")
    missing = [a for a in ANGLE_COLUMNS if a not in seen]
    if missing:
        raise ConfigError(f"columns must map {', '.join(missing)} (the four angles theta_i, phi_i, theta_o, "
                          "phi_o and at least one channel)", field="columns")
    value_names = [n for n in order if n not in ANGLE_COLUMNS and not n.startswith(SIGMA_PREFIX)]
    if not value_names:
        raise ConfigError("columns map no value channel after the four angles", field="columns")
    sigma_names = [n for n in order if n.startswith(SIGMA_PREFIX)]
    for name in sigma_names:
        if name[len(SIGMA_PREFIX):] not in value_names:
            raise ConfigError(f"column {name!r} names no channel ({', '.join(value_names)})", field="columns")
    if sigma_names and len(sigma_names) != len(value_names):
        raise ConfigError("sigma columns must be given for every channel or none", field="columns")


def _splitter(delimiter: str, sample: str):
    """(split function, separator name) for a delimiter choice; ``auto`` looks at ``sample``."""
    if delimiter == "auto":
        delimiter = "semicolon" if ";" in sample else "comma" if "," in sample else "tab" if "\t" in sample \
            else "whitespace"
    separator = DELIMITERS[delimiter]
    if separator is None:
        return str.split, "whitespace"
    return (lambda text: [f.strip() for f in text.split(separator)]), delimiter


def check_options(*, columns=None, delimiter: str = "auto", comment: str = "#", header: str = "auto",
                  angle_unit: str = "deg", azimuth_zero: str = "weft", azimuth_sense: str = "ccw",
                  azimuth_offset: float = 0.0, quantity: str = "brdf", channels=None):
    """The options of :func:`read_generic` checked without reading a file: (column map, azimuth offset), or a
    ConfigError whose ``field`` is the option at fault (so fabric.yaml's ``measurement.options`` and the
    command line name it before anything is read)."""
    for name, value in (("angle_unit", angle_unit), ("quantity", quantity), ("azimuth_zero", azimuth_zero),
                        ("azimuth_sense", azimuth_sense)):
        check_choice(name, value)
    azimuth_offset = check_azimuth_offset(azimuth_offset, error=ConfigError)
    if not isinstance(delimiter, str) or delimiter not in DELIMITERS:
        raise ConfigError(f"unknown delimiter {delimiter!r}; expected one of {' | '.join(DELIMITERS)}",
                          field="delimiter")
    if not isinstance(header, str) or header not in HEADER_CHOICES:
        raise ConfigError(f"unknown header {header!r}; expected one of {' | '.join(HEADER_CHOICES)}",
                          field="header")
    if not isinstance(comment, str) or len(comment) > 1 or (comment and (
            comment.isalnum() or comment in "+-.,;" or comment.isspace() or not comment.isprintable())):
        raise ConfigError(f"comment must be one printable character that cannot start a number and is not a "
                          f"separator, or empty; got {comment!r}", field="comment")
    mapping = parse_columns(columns)
    if channels is not None:
        _name_list(channels, "channels")
        if mapping is not None:  # the channel count is known from the mapping
            _channel_names(channels, [n for n in mapping.order if n not in ANGLE_COLUMNS
                                      and not n.startswith(SIGMA_PREFIX)])
    return mapping, azimuth_offset


def read_generic(path, *, columns=None, delimiter: str = "auto", comment: str = "#", header: str = "auto",
                 angle_unit: str = "deg", azimuth_zero: str = "weft", azimuth_sense: str = "ccw",
                 azimuth_offset: float = 0.0, quantity: str = "brdf", channels=None) -> Measurement:
    """Load a text table with the given column mapping and conventions into clothlab's convention.

    delimiter : auto | whitespace | comma | semicolon | tab.   comment : lines starting with it are skipped
    (``""`` for none; text after it on a data line is dropped too).   header : auto | yes | no (auto: a
    header when every field of the first row starts with a letter).
    angle_unit : deg | rad.   azimuth_zero : weft | warp (x | y).   azimuth_sense : ccw | cw (seen from above).
    azimuth_offset : degrees counter-clockwise added after the zero/sense conversion (phi = 0 -> weft).
    quantity : brdf | reflectance_factor | cosine_weighted.   channels : new names for the value channels,
    in order (comma-separated or a list).
    """
    conventions = {"angle_unit": angle_unit, "quantity": quantity, "azimuth_zero": azimuth_zero,
                   "azimuth_sense": azimuth_sense}
    mapping, azimuth_offset = check_options(columns=columns, delimiter=delimiter, comment=comment, header=header,
                                            azimuth_offset=azimuth_offset, channels=channels, **conventions)
    path = Path(path)
    rows = []
    lines = read_text_lines(path)
    for lineno, line in enumerate(lines, 1):
        text = line.split(comment, 1)[0] if comment else line
        if text.strip():
            rows.append((lineno, text.strip()))
    if not rows:
        raise InputError("no data rows (only blank or comment lines)", path=path, line=max(len(lines), 1))
    split, separator = _splitter(delimiter, rows[0][1] if len(rows) == 1 else rows[1][1])
    has_header = header == "yes" or (header == "auto" and _is_header(split(rows[0][1])))
    file_names = header_line = None
    if has_header:
        header_line, header_text = rows.pop(0)
        file_names = [n.strip().strip('"').strip("'") for n in split(header_text)]
        if not rows:
            raise InputError("no data rows after the header row", path=path, line=header_line)
    order, index, names_for_messages = _resolve(mapping, file_names, path,
                                                header_line if has_header else rows[0][0])
    width = len(file_names) if file_names is not None else (mapping.width or max(index.values()) + 1)
    field_names = list(file_names) if file_names is not None else [
        next((n for n, k in index.items() if k == j), f"column {j + 1}") for j in range(width)]
    table = parse_rows(rows, field_names, path=path, split=split,  # a tab is shown as a space in messages
                       separator=" " if separator in ("whitespace", "tab") else DELIMITERS[separator])
    value_names = [n for n in order if n not in ANGLE_COLUMNS and not n.startswith(SIGMA_PREFIX)]
    sigma_names = [n for n in order if n.startswith(SIGMA_PREFIX)]  # all or none, checked by _check_names
    try:
        new_names = _channel_names(channels, value_names)
    except ConfigError as exc:  # e.g. three names for the two channels the file's header row holds
        raise InputError(exc.detail, path=path, line=header_line if has_header else rows[0][0],
                         field="channels") from None
    raw = RawRows(
        path=str(path), lines=np.array([lineno for lineno, _ in rows]),
        angles=table[:, [index[a] for a in ANGLE_COLUMNS]],
        values=table[:, [index[n] for n in value_names]], channels=tuple(new_names),
        sigma=table[:, [index[SIGMA_PREFIX + n] for n in value_names]] if sigma_names else None,
        angle_names=tuple(names_for_messages[a] for a in ANGLE_COLUMNS))
    provenance = {"source_format": "text", "source_file": path.name,
                  **conventions_provenance(conventions, azimuth_offset)}
    return rows_to_measurement(raw, **conventions, provenance=provenance, source=path,
                               azimuth_offset=azimuth_offset)


def _resolve(mapping: ColumnMap | None, file_names, path, header_line):
    """(clothlab names in order, file column index per name, file column name per name for messages)."""
    if mapping is None:
        if file_names is None:
            raise InputError("the file has no header row naming its columns; give columns "
                             "(e.g. theta_i,phi_i,theta_o,phi_o,R,G,B)", path=path, line=header_line,
                             field="columns")
        mapping = ColumnMap(tuple(file_names), names={n: n for n in file_names})
        try:
            _check_names(mapping.order)
        except ConfigError as exc:
            raise InputError(f"header row: {exc.detail}; or give columns", path=path, line=header_line) from None
    if mapping.names is not None:
        if file_names is None:
            raise InputError("columns map header names (name=header) but the file has no header row (its first "
                             "row is data, or header: no)", path=path, line=header_line, field="columns")
        index = {}
        for name, wanted in mapping.names.items():
            hits = [k for k, n in enumerate(file_names) if n == wanted]
            if len(hits) != 1:
                raise InputError(f"header row has {len(hits)} columns named {wanted!r} (for {name}); expected "
                                 f"one, among {', '.join(file_names)}", path=path, line=header_line,
                                 field=wanted)
            index[name] = hits[0]
        return mapping.order, index, {n: mapping.names[n] for n in mapping.order}
    if file_names is not None and max(mapping.positions.values()) >= len(file_names):
        raise InputError(f"columns name {max(mapping.positions.values()) + 1} columns but the header row has "
                         f"{len(file_names)}", path=path, line=header_line, field="columns")
    return mapping.order, dict(mapping.positions), {n: n for n in mapping.order}


def _channel_names(channels, value_names):
    if channels is None:
        return value_names
    names = _name_list(channels, "channels")
    if len(names) != len(value_names) or len(set(names)) != len(names) or not all(names):
        raise ConfigError(f"channels must give {len(value_names)} distinct names (for {', '.join(value_names)}), "
                          f"got {channels!r}", field="channels")
    for name in names:
        if not _CHANNEL_NAME.match(name) or name in ANGLE_COLUMNS or name.startswith(SIGMA_PREFIX):
            raise ConfigError(f"bad channel name {name!r}: expected a name without spaces, commas or quotes that "
                              f"is not an angle column and does not start with '{SIGMA_PREFIX}'", field="channels")
    return names


def import_table(source, output, *, overwrite: bool = False, **options) -> tuple[Path, Measurement]:
    """Read ``source`` with :func:`read_generic` (``options``) and write it as a clothlab table at ``output``
    (atomic; ResultExistsError unless ``overwrite``).  Returns the path written and the measurement."""
    measurement = read_generic(source, **options)
    check_row_count(measurement.n, source)
    return write_table(measurement, output, overwrite=overwrite), measurement
