"""clothlab's own measurement table: a CSV with a YAML header, round-trip exact.

Layout (docs/formats.md, "clothlab's own table")::

    # clothlab-table: 1
    # angle_unit: deg            # deg | rad
    # quantity: brdf             # brdf [1/sr] | reflectance_factor [= pi BRDF] | cosine_weighted [= BRDF cos theta_i]
    # azimuth_zero: weft         # weft | warp (also x | y): where phi = 0 points
    # azimuth_sense: ccw         # ccw | cw, seen from above the fabric
    # azimuth_offset: 0          # optional, deg counter-clockwise, added once at loading (phi = 0 -> weft)
    # channels: [R, G, B]
    # provenance: {instrument: ..., reference_standard: Spectralon, sample_name: ...}
    theta_i,phi_i,theta_o,phi_o,R,G,B,sigma_R,sigma_G,sigma_B
    30.0,0.0,30.0,180.0,0.12,0.10,0.08,0.01,0.01,0.01

The header is the block of ``#`` lines at the top of the file: with the leading ``#`` (and one space) removed
it is a YAML mapping (YAML comments and multi-line values allowed).  It may instead live in a sidecar
``<file>.yaml`` (e.g. ``brdf.csv.yaml``) or ``<stem>.yaml`` (``brdf.yaml``) with the same keys; if both
the file and a sidecar declare a key they must agree (a conflict is an error), keys found in only one are
taken from it.  All keys but ``azimuth_offset`` (default 0) and ``provenance`` are required, so no
convention is ever guessed.

``azimuth_offset`` (degrees, counter-clockwise seen from above, |offset| <= 360) rotates the file's azimuths
once, at loading, after the zero/sense conversion: phi_clothlab = phi(azimuth_zero, azimuth_sense) + offset
(mod 360), so that phi = 0 lies along the weft.  It is for a sample whose weft lies at -offset in the file's
converted azimuth (an unknown or turned warp direction, issue 14 item 2).

Columns may come in any order: the four angles, one column per channel, and optionally ``sigma_<channel>``
(one-standard-deviation uncertainty, same quantity and unit as the value) for all channels or none.
Blank lines are ignored; ``#`` lines are only allowed in the header block.

Loading converts once into clothlab's form (:class:`~clothlab.io.measurement.Measurement`): degrees, azimuth via
:func:`clothlab.frames.azimuth_to_clothlab`, BRDF in 1/sr (reflectance_factor / pi, cosine_weighted /
cos theta_i; sigma the same).  When a file's conventions differ from clothlab's own (deg, brdf, weft, ccw),
they are recorded in ``provenance['source_header']``.  Polar angles must lie in [0, 90] deg (90 included).

The row validation and conversion helpers here (:class:`RawRows`, :func:`rows_to_measurement`,
:func:`check_unique_directions`) are shared by the ASTM and pab-opto loaders.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from clothlab.atomic import atomic_write_text
from clothlab.errors import ConfigError, InputError, ResultExistsError
from clothlab.frames import AZIMUTH_SENSE, AZIMUTH_ZERO, azimuth_from_clothlab, azimuth_to_clothlab
from clothlab.io.measurement import Measurement
from clothlab.untrusted import (
    MAX_NUMBER_CHARS,
    MAX_TABLE_BYTES,
    decode_text,
    load_yaml_text,
    plain_numeric_text,
    read_bounded_bytes,
)
from clothlab.untrusted import parse_number as strict_number

TABLE_VERSION = 1
ANGLE_COLUMNS = ("theta_i", "phi_i", "theta_o", "phi_o")
ANGLE_UNITS = ("deg", "rad")
#: Quantities a table may hold and what each is relative to the BRDF f_r (1/sr).
QUANTITIES = {
    "brdf": "BRDF f_r in 1/sr",
    "reflectance_factor": "pi * f_r (Spectralon-relative reflectance factor)",
    "cosine_weighted": "f_r * cos(theta_i)",
}
#: Internal quantity of pab-opto files: DSF = BSDF * cos(theta_o).
DSF = "dsf"
_COSINE_COLUMN = {"cosine_weighted": "theta_i", DSF: "theta_o"}
_QUANTITY_NOUN = {"brdf": "BRDF", "reflectance_factor": "reflectance factor",
                  "cosine_weighted": "cosine-weighted BRDF", DSF: "DSF"}
SIGMA_PREFIX = "sigma_"
CLOTHLAB_CONVENTIONS = {"angle_unit": "deg", "quantity": "brdf", "azimuth_zero": "weft", "azimuth_sense": "ccw"}
HEADER_KEYS = ("clothlab-table", "angle_unit", "quantity", "azimuth_zero", "azimuth_sense", "azimuth_offset",
               "channels", "provenance")
_OPTIONAL_KEYS = ("azimuth_offset", "provenance")
_REQUIRED_KEYS = tuple(key for key in HEADER_KEYS if key not in _OPTIONAL_KEYS)
MAX_AZIMUTH_OFFSET = 360.0
"""Largest |azimuth_offset| (deg) a header or an importer accepts (one turn)."""
_ALLOWED = {
    "angle_unit": ANGLE_UNITS,
    "quantity": tuple(QUANTITIES),
    "azimuth_zero": tuple(AZIMUTH_ZERO),
    "azimuth_sense": AZIMUTH_SENSE,
}
CONVENTION_CHOICES = _ALLOWED
"""The allowed keywords of each convention (angle_unit, quantity, azimuth_zero, azimuth_sense)."""
_TOP_KEY = re.compile(r"^(?![-?] )([^\s:#'\"\[\]{},][^:]*?)\s*:(\s|$)")
_CHANNEL_NAME = re.compile(r"^[^\s,#'\"]+$")


# --------------------------------------------------------------------------------------------------------
# Shared by all measurement loaders: validated rows in a file's own conventions -> Measurement
# --------------------------------------------------------------------------------------------------------

@dataclass
class RawRows:
    """Numbers as read from a file, before conversion.

    angles : (N, 4) theta_i, phi_i, theta_o, phi_o in the file's unit and azimuth convention.
    values, sigma : (N, C) in the file's quantity.   lines : (N,) 1-based line of each row in ``path``.
    angle_names : how the file names the four angle columns (for messages).
    """

    path: str
    lines: np.ndarray
    angles: np.ndarray
    values: np.ndarray
    channels: tuple[str, ...]
    sigma: np.ndarray | None = None
    angle_names: tuple[str, ...] = ANGLE_COLUMNS


def read_text_lines(path) -> list[str]:
    """The lines of a UTF-8 text file ('\\n' or '\\r\\n' endings), or InputError naming the bad line.

    The file must be a regular file of at most :data:`clothlab.untrusted.MAX_TABLE_BYTES`; a leading UTF-8
    byte-order mark is dropped (:func:`clothlab.untrusted.decode_text`).
    """
    data = read_bounded_bytes(path, limit=MAX_TABLE_BYTES, what="measurement file")
    text = decode_text(data, path=Path(path), what="measurement file")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [line[:-1] if line.endswith("\r") else line for line in lines]


def parse_number(text: str, *, path, line: int, column: str) -> float:
    """A finite float in plain decimal notation from one field (:func:`clothlab.untrusted.parse_number`), or
    InputError naming file, line and column."""
    return strict_number(text, path=path, line=line, field=column)


def _split_csv(text: str) -> list[str]:
    return text.split(",")


def parse_rows(rows: list[tuple[int, str]], columns, *, path, split=_split_csv, separator: str = ",") -> np.ndarray:
    """(N, K) floats from (line number, text) rows; InputError naming line and column of the first bad row.

    ``split`` cuts a row into fields (comma-separated by default); ``separator`` is only for messages.
    """
    fields = []
    for lineno, text in rows:
        row = split(text)
        if len(row) != len(columns):
            raise InputError(f"row has {len(row)} fields, expected {len(columns)} ({separator.join(columns)})",
                             path=path, line=lineno, field=columns[len(row)] if len(row) < len(columns) else None)
        fields.append(row)
    if all(plain_numeric_text(text) for _, text in rows) and all(
            len(text) <= MAX_NUMBER_CHARS for row in fields for text in row):
        try:  # fast path for rows of plain decimal numbers; the strict per-field parse names a culprit
            table = np.array([[float(text) for text in row] for row in fields], dtype=np.float64).reshape(
                len(rows), len(columns))
        except ValueError:
            table = None
        if table is not None and np.isfinite(table).all():
            return table
    # rows with other characters (a ';' separator, tabs) or a bad field: the strict per-field parse
    return np.array([[parse_number(text, path=path, line=lineno, column=column)
                      for text, column in zip(row, columns, strict=True)]
                     for row, (lineno, _) in zip(fields, rows, strict=True)], dtype=np.float64).reshape(
        len(rows), len(columns))


def _first(mask: np.ndarray) -> tuple[int, int] | None:
    """(row, column) of the first True entry of a 2-D mask in row-major order, or None."""
    hits = np.argwhere(mask)
    return None if len(hits) == 0 else (int(hits[0, 0]), int(hits[0, 1]))


MAX_VALUE = 1e30
"""Largest magnitude of a value or sigma accepted (1/sr or the file's quantity); a BRDF above it is a unit or
parsing mistake, and squares of such values overflow in a fit."""
MIN_VALUE = float(np.finfo(np.float64).tiny)
"""Smallest non-zero magnitude accepted (the smallest normal float64, 2.2e-308): a denormal value loses
precision and its square underflows to 0 inside least squares."""
MIN_ROWS = 2
"""Fewest rows of a measurement (one row cannot be fitted or summarised by percentiles)."""
RADIAN_SUSPECT_DEG = (1.6, 6.3)
"""A ``deg`` table whose polar angles all lie below 1.6 (just above pi/2) and whose azimuths all lie within
6.3 (just above 2 pi) holds radians."""


def _check_magnitude(array: np.ndarray, raw: RawRows, names) -> None:
    """InputError at the first denormal or huge (> :data:`MAX_VALUE`) entry of ``array``."""
    magnitude = np.abs(array)
    bad = _first(((magnitude > 0.0) & (magnitude < MIN_VALUE)) | (magnitude > MAX_VALUE))
    if bad is not None:
        row, col = bad
        value = float(array[row, col])
        what = (f"is denormal (0 < |value| < {MIN_VALUE:.3g}); write 0 or a normal number" if abs(value) < 1.0
                else f"exceeds {MAX_VALUE:g} in magnitude; check the unit and the quantity")
        raise InputError(f"value {value!r} {what}", path=raw.path, line=int(raw.lines[row]), field=names[col])


def _check_angle_plausibility(raw: RawRows, angle_unit: str) -> None:
    """Azimuths within one turn either side of zero; a deg table with every angle below 1.6 deg refused."""
    names = raw.angle_names
    turn = 360.0 if angle_unit == "deg" else 2.0 * math.pi
    phis = raw.angles[:, [1, 3]]
    bad = _first(np.abs(phis) > turn)
    if bad is not None:
        row, col = bad
        raise InputError(f"value {float(phis[row, col])!r} is outside [-{turn:g}, {turn:g}] {angle_unit}; an "
                         "azimuth lies within one turn", path=raw.path, line=int(raw.lines[row]),
                         field=names[2 * col + 1])
    polar_max, azimuth_max = RADIAN_SUSPECT_DEG
    if (angle_unit == "deg" and len(raw.angles) > 1 and float(raw.angles[:, [0, 2]].max()) < polar_max
            and float(np.abs(phis).max()) < azimuth_max):
        raise InputError(
            f"every polar angle lies below {polar_max} deg and every azimuth within {azimuth_max} deg: these look "
            "like radians; declare angle_unit: rad", path=raw.path, line=int(raw.lines[0]), field="angle_unit")


def check_rows(raw: RawRows, *, angle_unit: str, quantity: str) -> None:
    """Validate rows in their file units: finite numbers, 0 <= theta <= 90 deg, |phi| within one turn,
    values >= 0 and sigma > 0 with normal magnitudes in [2.2e-308, 1e30], angles that are not radians in a
    deg table."""
    names = raw.angle_names
    columns = (*names, *raw.channels)
    numbers = np.concatenate([raw.angles, raw.values], axis=1)
    bad = _first(~np.isfinite(numbers))
    if bad is not None:
        row, col = bad
        raise InputError(f"value {float(numbers[row, col])!r} is not finite; expected a finite number",
                         path=raw.path, line=int(raw.lines[row]), field=columns[col])
    _check_magnitude(raw.values, raw, raw.channels)
    if len(raw.values) > 1:
        for col in np.flatnonzero(~raw.values.any(axis=0)):
            raise InputError(f"every value of channel {raw.channels[col]} is 0 ({len(raw.values)} rows): a "
                             "measurement holds reflected light", path=raw.path, line=int(raw.lines[0]),
                             field=raw.channels[col])
    _check_angle_plausibility(raw, angle_unit)
    right_angle = 90.0 if angle_unit == "deg" else math.pi / 2
    thetas = raw.angles[:, [0, 2]]
    bad = _first((thetas < 0.0) | (thetas > right_angle))
    if bad is not None:
        row, col = bad
        raise InputError(
            f"value {float(thetas[row, col])!r} is outside [0, {right_angle!r}] {angle_unit}; a polar angle is "
            f"measured from the surface normal and clothlab handles reflection only",
            path=raw.path, line=int(raw.lines[row]), field=names[2 * col])
    bad = _first(raw.values < 0.0)
    if bad is not None:
        row, col = bad
        raise InputError(
            f"value {float(raw.values[row, col])!r} is negative; {_QUANTITY_NOUN[quantity]} values must be >= 0",
            path=raw.path, line=int(raw.lines[row]), field=raw.channels[col])
    if quantity in _COSINE_COLUMN:
        index = ANGLE_COLUMNS.index(_COSINE_COLUMN[quantity])
        theta = raw.angles[:, index] if angle_unit == "rad" else np.deg2rad(raw.angles[:, index])
        grazing = np.flatnonzero(np.cos(theta) < 1e-12)
        if len(grazing):
            row = int(grazing[0])
            raise InputError(
                f"value {float(raw.angles[row, index])!r} gives cos({names[index]}) = 0, where a "
                f"{_QUANTITY_NOUN[quantity]} value cannot be converted to a BRDF; drop grazing rows",
                path=raw.path, line=int(raw.lines[row]), field=names[index])
    if raw.sigma is not None:
        sigma_names = [SIGMA_PREFIX + c for c in raw.channels]
        bad = _first(~np.isfinite(raw.sigma))
        if bad is not None:
            row, col = bad
            raise InputError(f"value {float(raw.sigma[row, col])!r} is not finite; expected a finite number",
                             path=raw.path, line=int(raw.lines[row]), field=sigma_names[col])
        bad = _first(raw.sigma <= 0.0)
        if bad is not None:
            row, col = bad
            raise InputError(
                f"value {float(raw.sigma[row, col])!r} is not positive; an uncertainty (one standard deviation) "
                f"must be > 0", path=raw.path, line=int(raw.lines[row]), field=sigma_names[col])
        _check_magnitude(raw.sigma, raw, sigma_names)


def last_data_line(path) -> int | None:
    """The 1-based number of the last non-blank line of a text file that is not a '#' comment (where a table's
    last data row is), or None for a directory or a file that cannot be read as text."""
    try:
        lines = read_text_lines(path)
    except (InputError, OSError):
        return None
    for number in range(len(lines), 0, -1):
        text = lines[number - 1].strip()
        if text and not text.startswith("#"):
            return number
    return max(len(lines), 1)


def check_row_count(n: int, path, line=None) -> None:
    """InputError unless a measurement has at least :data:`MIN_ROWS` rows (naming ``line``, else the last data
    line of a text file)."""
    if n < MIN_ROWS:
        if line is None:
            line = last_data_line(path)
        raise InputError(f"{n} data row{'s' if n != 1 else ''}; a measurement needs at least {MIN_ROWS} "
                         "(error percentiles and a fit of one direction pair mean nothing)", path=path, line=line)


def convert_rows(raw: RawRows, *, angle_unit: str, quantity: str, azimuth_zero: str, azimuth_sense: str,
                 azimuth_offset: float = 0.0):
    """Rows in clothlab's convention: (theta_i, phi_i, theta_o, phi_o) in degrees, values and sigma in 1/sr.

    ``azimuth_offset`` (file units) is added to both azimuths before :func:`azimuth_to_clothlab`.
    """
    angles = raw.angles if angle_unit == "deg" else np.rad2deg(raw.angles)
    theta_i = np.minimum(angles[:, 0], 90.0)
    theta_o = np.minimum(angles[:, 2], 90.0)
    offset = azimuth_offset if angle_unit == "deg" else math.degrees(azimuth_offset)

    def azimuth(phi):  # in [0, 360) (frames.wrap_azimuth)
        return azimuth_to_clothlab(phi + offset if offset else phi, zero=azimuth_zero, sense=azimuth_sense)

    values, sigma = raw.values, raw.sigma
    if quantity == "reflectance_factor":
        values = values / np.pi
        sigma = None if sigma is None else sigma / np.pi
    elif quantity in _COSINE_COLUMN:
        theta = theta_i if _COSINE_COLUMN[quantity] == "theta_i" else theta_o
        cos = np.cos(np.deg2rad(theta))[:, None]
        values = values / cos
        sigma = None if sigma is None else sigma / cos
    return theta_i, azimuth(angles[:, 1]), theta_o, azimuth(angles[:, 3]), values, sigma


def check_unique_directions(theta_i, phi_i, theta_o, phi_o, locations) -> None:
    """InputError for the first repeated (theta_i, phi_i, theta_o, phi_o) (clothlab convention).

    locations : sequence of (path, line) per row, for the message.
    """
    seen: dict[tuple[float, float, float, float], int] = {}
    for row, key in enumerate(zip(theta_i.tolist(), phi_i.tolist(), theta_o.tolist(), phi_o.tolist(),
                                  strict=True)):
        first = seen.setdefault(key, row)
        if first != row:
            path, line = locations[row]
            first_path, first_line = locations[first]
            where = f"line {first_line}" if first_path == path else f"{first_path}:{first_line}"
            raise InputError(
                f"duplicate row: the same (theta_i, phi_i, theta_o, phi_o) = {key} (clothlab convention, "
                f"degrees) as {where}; average repeated measurements before loading",
                path=path, line=line, field="theta_i,phi_i,theta_o,phi_o")


def file_azimuth_offset(offset_deg: float, *, angle_unit: str, azimuth_sense: str) -> float:
    """The offset in file units (for :func:`convert_rows`) equivalent to adding ``offset_deg`` (deg,
    counter-clockwise) after the zero/sense conversion: a clockwise file subtracts it."""
    signed = offset_deg if azimuth_sense == "ccw" else -offset_deg
    return signed if angle_unit == "deg" else math.radians(signed)


def check_azimuth_offset(value, *, error=InputError, **where) -> float:
    """``value`` as a float if it is a finite number (not a bool) with |value| <= 360 deg, else ``error``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise error(f"azimuth_offset must be a number of degrees, got {value!r}", field="azimuth_offset", **where)
    try:
        value = float(value)
    except OverflowError:  # an integer beyond the float range
        value = math.inf
    if not math.isfinite(value) or abs(value) > MAX_AZIMUTH_OFFSET:
        raise error(f"azimuth_offset {value!r} is not a finite angle within [-{MAX_AZIMUTH_OFFSET:g}, "
                    f"{MAX_AZIMUTH_OFFSET:g}] deg", field="azimuth_offset", **where)
    return value


def rows_to_measurement(raw: RawRows, *, angle_unit: str, quantity: str, azimuth_zero: str,
                        azimuth_sense: str, provenance: dict, source=None,
                        azimuth_offset: float = 0.0) -> Measurement:
    """Validate ``raw`` (:func:`check_rows`, duplicates) and convert it to a :class:`Measurement`.

    ``azimuth_offset`` : degrees counter-clockwise added to both azimuths after the zero/sense conversion.
    """
    check_rows(raw, angle_unit=angle_unit, quantity=quantity)
    theta_i, phi_i, theta_o, phi_o, values, sigma = convert_rows(
        raw, angle_unit=angle_unit, quantity=quantity, azimuth_zero=azimuth_zero, azimuth_sense=azimuth_sense,
        azimuth_offset=file_azimuth_offset(azimuth_offset, angle_unit=angle_unit, azimuth_sense=azimuth_sense))
    check_unique_directions(theta_i, phi_i, theta_o, phi_o, [(raw.path, int(n)) for n in raw.lines])
    return Measurement(theta_i, phi_i, theta_o, phi_o, values, raw.channels, sigma, provenance,
                       None if source is None else str(source))


def conventions_provenance(conventions: dict, azimuth_offset: float = 0.0) -> dict:
    """``{'source_header': conventions}`` when they (or a non-zero ``azimuth_offset``, deg) differ from
    clothlab's own, else ``{}``."""
    if azimuth_offset == 0.0 and all(conventions.get(k) == v for k, v in CLOTHLAB_CONVENTIONS.items()):
        return {}
    header = {k: conventions[k] for k in CLOTHLAB_CONVENTIONS}
    if azimuth_offset != 0.0:
        header["azimuth_offset"] = float(azimuth_offset)
    return {"source_header": header}


def check_choice(name: str, value, *, error=ConfigError, **where) -> None:
    """``error`` unless ``value`` is one of the allowed keywords of ``name`` (angle_unit, quantity, ...)."""
    allowed = _ALLOWED[name]
    if not isinstance(value, str) or value not in allowed:
        raise error(f"unknown {name.replace('_', ' ')} {value!r}; expected one of {' | '.join(allowed)}",
                    field=name, **where)


# --------------------------------------------------------------------------------------------------------
# The clothlab table
# --------------------------------------------------------------------------------------------------------

@dataclass
class _Header:
    """Header mapping and, per key, where it was declared (path, line)."""

    values: dict
    where: dict


def _parse_yaml_header(text_lines: list[str], first_line: int, path) -> _Header:
    """YAML mapping from header lines (already without their '#'); ``first_line`` is the file line of [0]."""
    text = "\n".join(text_lines)
    try:
        data = load_yaml_text(text, path=path) if text.strip() else {}
    except InputError as exc:
        line = None if exc.line is None else first_line + exc.line - 1
        raise InputError(f"header is not valid YAML ({exc.detail})", path=path, line=line) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError("header must be 'key: value' lines (a YAML mapping)", path=path, line=first_line)
    where: dict = {}
    for offset, content in enumerate(text_lines):
        match = _TOP_KEY.match(content)
        if match:
            key = match.group(1).strip()
            if key in where:
                raise InputError(f"header key {key!r} is declared twice (first on line {where[key][1]})",
                                 path=path, line=first_line + offset, field=key)
            where[key] = (str(path), first_line + offset)
    for key in data:
        where.setdefault(str(key), (str(path), None))
    return _Header({str(k): v for k, v in data.items()}, where)


def find_sidecar(path: Path) -> Path | None:
    """The sidecar header of a table: ``<file>.yaml`` or ``<stem>.yaml``; InputError if both exist."""
    candidates = [path.with_name(path.name + ".yaml")]
    if path.suffix and path.suffix != ".yaml":
        candidates.append(path.with_suffix(".yaml"))
    found = [c for c in candidates if c.is_file()]
    if len(found) > 1:
        raise InputError(f"two sidecar headers {found[0].name} and {found[1].name}; keep one", path=path)
    return found[0] if found else None


def _merge_headers(in_file: _Header | None, sidecar: _Header | None, path) -> _Header:
    if in_file is None and sidecar is None:
        raise InputError(
            "no clothlab-table header: expected '# clothlab-table: 1' and the other header lines at the top "
            f"of the file, or a sidecar {Path(path).name}.yaml", path=path, line=1)
    if in_file is None or sidecar is None:
        return in_file or sidecar
    values, where = dict(sidecar.values), dict(sidecar.where)
    for key, value in in_file.values.items():
        if key in values and values[key] != value:
            side_path, side_line = sidecar.where[key]
            raise InputError(
                f"header key {key!r} is {value!r} here but {values[key]!r} in the sidecar "
                f"{side_path}{'' if side_line is None else ':' + str(side_line)}; make them agree or delete one",
                path=path, line=in_file.where[key][1], field=key)
        values[key] = value
        where[key] = in_file.where[key]
    return _Header(values, where)


def _validate_header(header: _Header, path) -> dict:
    """Checked header: conventions, channels (tuple of str) and provenance (dict)."""
    def at(key):
        key_path, line = header.where.get(key, (str(path), None))
        return {"path": key_path, "line": line}

    for key in header.values:
        if key not in HEADER_KEYS:
            raise InputError(f"unknown header key {key!r}; expected one of {', '.join(HEADER_KEYS)}",
                             field=key, **at(key))
    for key in _REQUIRED_KEYS:
        if key not in header.values:
            hint = f" ({' | '.join(_ALLOWED[key])})" if key in _ALLOWED else ""
            raise InputError(f"header key {key!r}{hint} is missing; clothlab never guesses a file's conventions",
                             path=path, field=key)
    values = header.values
    version = values["clothlab-table"]
    if version != TABLE_VERSION or isinstance(version, bool):
        raise InputError(f"unsupported clothlab-table version {version!r}; this clothlab reads version "
                         f"{TABLE_VERSION}", field="clothlab-table", **at("clothlab-table"))
    for key in _ALLOWED:
        check_choice(key, values[key], error=InputError, **at(key))
    channels = values["channels"]
    if isinstance(channels, str):
        channels = [channels]
    if not isinstance(channels, list) or not channels:
        raise InputError(f"channels must be a non-empty list of names like [R, G, B], got {channels!r}",
                         field="channels", **at("channels"))
    names = []
    for name in channels:
        if isinstance(name, int) and not isinstance(name, bool):
            name = str(name)
        if (not isinstance(name, str) or not _CHANNEL_NAME.match(name) or name in ANGLE_COLUMNS
                or name.startswith(SIGMA_PREFIX)):
            raise InputError(
                f"bad channel name {name!r}: expected a name without spaces, commas or quotes that is not an "
                f"angle column and does not start with '{SIGMA_PREFIX}'", field="channels", **at("channels"))
        if name in names:
            raise InputError(f"channel {name!r} is listed twice", field="channels", **at("channels"))
        names.append(name)
    provenance = values.get("provenance")
    if provenance is None:
        provenance = {}
    if not isinstance(provenance, dict):
        raise InputError(f"provenance must be a mapping (key: value), got {provenance!r}",
                         field="provenance", **at("provenance"))
    checked = {key: values[key] for key in _ALLOWED}
    offset = values.get("azimuth_offset", 0.0)
    checked.update(channels=tuple(names), provenance=provenance,
                   azimuth_offset=check_azimuth_offset(offset, **at("azimuth_offset")))
    return checked


def _split_header(lines: list[str]) -> tuple[list[str], int]:
    """Header lines without '#' (and one following space) and the index of the first non-header line."""
    header = []
    index = 0
    while index < len(lines) and lines[index].startswith("#"):
        content = lines[index][1:]
        header.append(content[1:] if content.startswith(" ") else content)
        index += 1
    return header, index


def _read_columns(line: str, lineno: int, path, channels: tuple[str, ...]) -> tuple[list[str], bool]:
    """Column names of the table and whether sigma columns are present; validates names."""
    names = [name.strip() for name in line.split(",")]
    expected = [*ANGLE_COLUMNS, *channels]
    sigma_names = [SIGMA_PREFIX + c for c in channels]
    listing = ", ".join(expected) + f" and optionally {', '.join(sigma_names)}"
    seen = set()
    for name in names:
        if name in seen:
            raise InputError(f"column {name!r} appears twice", path=path, line=lineno, field=name)
        seen.add(name)
        if name not in expected and name not in sigma_names:
            raise InputError(f"unknown column {name!r}; expected {listing}", path=path, line=lineno,
                             field=name or "(empty)")
    for name in expected:
        if name not in seen:
            raise InputError(f"required column {name!r} is missing; expected {listing}", path=path,
                             line=lineno, field=name)
    given = [name for name in sigma_names if name in seen]
    if given and len(given) != len(sigma_names):
        missing = next(name for name in sigma_names if name not in seen)
        raise InputError(f"column {missing!r} is missing: sigma columns must be given for all channels or none",
                         path=path, line=lineno, field=missing)
    return names, bool(given)


def _parse_table_lines(lines: list[str], path, sidecar: _Header | None) -> Measurement:
    """The whole table parser, on lines of text (``path`` for messages only)."""
    header_lines, start = _split_header(lines)
    in_file = _parse_yaml_header(header_lines, 1, path) if header_lines else None
    header = _validate_header(_merge_headers(in_file, sidecar, path), path)
    channels = header["channels"]

    rows = [(i + 1, line) for i, line in enumerate(lines[start:], start) if line.strip()]
    for lineno, line in rows:
        if line.lstrip().startswith("#"):
            raise InputError("'#' lines belong to the header block at the top of the file, before any "
                             "other line", path=path, line=lineno)
    if not rows:
        raise InputError("empty table: no column names line and no data rows", path=path,
                         line=max(len(lines), 1))
    column_line, column_text = rows[0]
    names, has_sigma = _read_columns(column_text, column_line, path, channels)
    data = rows[1:]
    if not data:
        raise InputError("empty table: no data rows after the column names", path=path, line=column_line)

    table = parse_rows(data, names, path=path)

    index = {name: c for c, name in enumerate(names)}
    raw = RawRows(
        path=str(path),
        lines=np.array([lineno for lineno, _ in data]),
        angles=table[:, [index[name] for name in ANGLE_COLUMNS]],
        values=table[:, [index[name] for name in channels]],
        channels=channels,
        sigma=table[:, [index[SIGMA_PREFIX + c] for c in channels]] if has_sigma else None,
    )
    conventions = {key: header[key] for key in _ALLOWED}
    offset = header["azimuth_offset"]
    provenance = {**header["provenance"], **conventions_provenance(conventions, offset)}
    return rows_to_measurement(raw, **conventions, provenance=provenance, source=path, azimuth_offset=offset)


def read_table(path) -> Measurement:
    """Load a clothlab table (CSV + YAML header or sidecar) into clothlab's convention.

    Every problem raises :class:`InputError` naming file, line and column.

    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = Path(tmp) / "brdf.csv"
    ...     _ = path.write_text("# clothlab-table: 1\\n# angle_unit: deg\\n# quantity: reflectance_factor\\n"
    ...                         "# azimuth_zero: warp\\n# azimuth_sense: cw\\n# channels: [Y]\\n"
    ...                         "theta_i,phi_i,theta_o,phi_o,Y\\n30,30,0,0,0.5\\n")
    ...     m = read_table(path)
    >>> float(m.phi_i[0]), round(float(m.values[0, 0]), 6)  # clothlab azimuth; BRDF = reflectance / pi
    (60.0, 0.159155)
    >>> read_table("missing.csv")
    Traceback (most recent call last):
    ...
    clothlab.errors.InputError: missing.csv: ...
    """
    path = Path(path)
    lines = read_text_lines(path)
    sidecar_path = find_sidecar(path)
    sidecar = None
    if sidecar_path is not None:
        sidecar = _parse_yaml_header(read_text_lines(sidecar_path), 1, sidecar_path)
    return _parse_table_lines(lines, path, sidecar)


def _plain(value, where: str = "provenance"):
    """Provenance as plain YAML data (numpy scalars/arrays and tuples become Python numbers and lists)."""
    if isinstance(value, dict):
        return {k: _plain(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v, where) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist(), where)
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, str | int | float | bool):
        return value
    try:
        yaml.safe_dump(value)
    except yaml.YAMLError:
        raise TypeError(f"{where} holds a {type(value).__name__}, which a table header cannot store") from None
    return value


_HEADER_DUMPER = None


def _header_dumper():
    """PyYAML's safe dumper that also quotes every string clothlab's strict reader would take for a number
    (e.g. a channel named ``1e3``, which YAML 1.1 leaves plain), so that a written header reads back as
    written."""
    global _HEADER_DUMPER
    if _HEADER_DUMPER is None:
        class HeaderDumper(yaml.SafeDumper):
            pass

        HeaderDumper.add_implicit_resolver(
            "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?$"),
            list("-+0123456789."))
        _HEADER_DUMPER = HeaderDumper
    return _HEADER_DUMPER


def _header_text(header: dict) -> list[str]:
    """'# '-prefixed YAML lines of the header (block mapping; innermost lists and mappings inline)."""
    dumped = yaml.dump(header, Dumper=_header_dumper(), sort_keys=False, allow_unicode=True, width=2**31,
                       default_flow_style=None)
    return [f"# {line}".rstrip() for line in dumped.rstrip("\n").split("\n")]


def format_table(m: Measurement, *, quantity: str = "brdf", angle_unit: str = "deg",
                 azimuth_zero: str = "weft", azimuth_sense: str = "ccw", azimuth_offset: float = 0.0) -> str:
    """The text of a clothlab table holding ``m`` in the requested conventions (floats as repr; exact with
    ``azimuth_offset=0``, which is then not written).

    >>> m = Measurement(np.array([30.0, 45.0]), np.array([0.0, 90.0]), np.array([30.0, 0.0]),
    ...                 np.array([180.0, 0.0]), np.array([[0.12], [0.3]]), ("Y",))
    >>> print(format_table(m), end="")
    # clothlab-table: 1
    # angle_unit: deg
    # quantity: brdf
    # azimuth_zero: weft
    # azimuth_sense: ccw
    # channels: [Y]
    theta_i,phi_i,theta_o,phi_o,Y
    30.0,0.0,30.0,180.0,0.12
    45.0,90.0,0.0,0.0,0.3
    >>> print(format_table(m, azimuth_zero="warp").splitlines()[-1])  # azimuths from the warp in the file
    45.0,0.0,0.0,270.0,0.3
    """
    for name, value in (("quantity", quantity), ("angle_unit", angle_unit), ("azimuth_zero", azimuth_zero),
                        ("azimuth_sense", azimuth_sense)):
        check_choice(name, value)
    azimuth_offset = check_azimuth_offset(azimuth_offset, error=ConfigError)
    theta_i, theta_o = m.theta_i, m.theta_o

    def file_azimuth(phi):
        return azimuth_from_clothlab(np.mod(phi - azimuth_offset, 360.0) if azimuth_offset else phi,
                                     zero=azimuth_zero, sense=azimuth_sense)

    phi_i, phi_o = file_azimuth(m.phi_i), file_azimuth(m.phi_o)
    angles = [theta_i, phi_i, theta_o, phi_o]
    if angle_unit == "rad":
        angles = [np.deg2rad(a) for a in angles]
    values, sigma = m.values, m.sigma
    if quantity == "reflectance_factor":
        values = values * np.pi
        sigma = None if sigma is None else sigma * np.pi
    elif quantity == "cosine_weighted":
        cos = np.cos(np.deg2rad(theta_i))[:, None]
        values = values * cos
        sigma = None if sigma is None else sigma * cos
    header = {"clothlab-table": TABLE_VERSION, "angle_unit": angle_unit, "quantity": quantity,
              "azimuth_zero": azimuth_zero, "azimuth_sense": azimuth_sense}
    if azimuth_offset:
        header["azimuth_offset"] = azimuth_offset
    header["channels"] = list(m.channels)
    if m.provenance:
        header["provenance"] = _plain(dict(m.provenance))
    names = [*ANGLE_COLUMNS, *m.channels]
    columns = [*angles, *values.T]
    if sigma is not None:
        names += [SIGMA_PREFIX + c for c in m.channels]
        columns += list(sigma.T)
    body = np.stack(columns, axis=1).tolist() if m.n else []
    lines = _header_text(header) + [",".join(names)] + [",".join(map(repr, row)) for row in body]
    return "\n".join(lines) + "\n"


def write_table(m: Measurement, path, *, overwrite: bool = False, quantity: str = "brdf",
                angle_unit: str = "deg", azimuth_zero: str = "weft", azimuth_sense: str = "ccw",
                azimuth_offset: float = 0.0) -> Path:
    """Write ``m`` as a clothlab table, atomically; returns the path.

    With the defaults, ``read_table(write_table(m, p))`` reproduces ``m`` exactly (floats are written with
    ``repr``; azimuths must be in [0, 360) as every loader produces; provenance must be plain YAML data -
    tuples come back as lists).  The text is parsed back before writing, so an invalid measurement (NaN,
    negative values, duplicate directions ...) raises :class:`InputError` and nothing is written.
    An existing file raises :class:`ResultExistsError` unless ``overwrite``.

    >>> import tempfile
    >>> m = Measurement(np.array([30.0]), np.array([0.0]), np.array([30.0]), np.array([180.0]),
    ...                 np.array([[0.12, 0.1, 0.08]]), ("R", "G", "B"))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_table(write_table(m, Path(tmp) / "brdf.csv"))
    >>> back.channels, back.values.tolist() == m.values.tolist()
    (('R', 'G', 'B'), True)
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise ResultExistsError(f"{path} already exists; pass overwrite=True (--force) to replace it", path=path)
    text = format_table(m, quantity=quantity, angle_unit=angle_unit, azimuth_zero=azimuth_zero,
                        azimuth_sense=azimuth_sense, azimuth_offset=azimuth_offset)
    try:
        _parse_table_lines(text.split("\n")[:-1], path, None)
    except InputError as exc:
        raise InputError(f"the measurement cannot be written as a valid table: {exc.detail}",
                         path=path, line=exc.line, field=exc.field) from None
    return atomic_write_text(path, text)
