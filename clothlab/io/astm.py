"""ASTM E1392-96-style gonioreflectometer files (docs/formats.md, "ASTM E1392-96 files").

Layout: header lines ``KEYWORD value`` - ``NUM_POINTS n`` and ``VARS theta_i,phi_i,theta_s,phi_s,<channels>``
are required, every other keyword is kept verbatim in ``provenance['astm_keywords']`` - then comma-separated
data rows in the VARS order.  ``theta_s``/``phi_s`` (scattered) are clothlab's ``theta_o``/``phi_o``
(``theta_o``/``phi_o`` and ``theta_r``/``phi_r`` are accepted too).  Angles are in radians unless
``angle_unit='deg'``; negative azimuths are wrapped by +2 pi (+360 deg), as the format's readers do.
The file carries no convention of its own, so the azimuth zero/sense and the quantity are options and are
recorded in ``provenance['source_header']`` when they differ from clothlab's.  Lines starting with ``#`` are
comments.  Rows are validated like a clothlab table (:func:`clothlab.io.table.rows_to_measurement`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_text
from clothlab.errors import InputError, ResultExistsError
from clothlab.frames import azimuth_from_clothlab
from clothlab.io.measurement import Measurement
from clothlab.io.table import (
    ANGLE_COLUMNS,
    RawRows,
    check_choice,
    conventions_provenance,
    parse_rows,
    read_text_lines,
    rows_to_measurement,
)

_ANGLE_ALIASES = {
    "theta_i": "theta_i", "phi_i": "phi_i",
    "theta_s": "theta_o", "phi_s": "phi_o",
    "theta_o": "theta_o", "phi_o": "phi_o",
    "theta_r": "theta_o", "phi_r": "phi_o",
}


def _is_data_line(text: str) -> bool:
    return text[:1].isdigit() or text[:1] in "+-."


def _split_fields(text: str) -> list[str]:
    return [f.strip() for f in text.split(",")] if "," in text else text.split()


def read_astm(path, *, angle_unit: str = "rad", azimuth_zero: str = "weft", azimuth_sense: str = "ccw",
              quantity: str = "brdf") -> Measurement:
    """Load an ASTM E1392-style file into clothlab's convention (degrees, BRDF in 1/sr).

    angle_unit : 'rad' (the format's usual unit) or 'deg'.   quantity : 'brdf' | 'reflectance_factor' |
    'cosine_weighted' (as for a clothlab table).   azimuth_zero / azimuth_sense : the file's azimuth
    convention (:func:`clothlab.frames.azimuth_to_clothlab`).
    """
    conventions = {"angle_unit": angle_unit, "quantity": quantity, "azimuth_zero": azimuth_zero,
                   "azimuth_sense": azimuth_sense}
    for name, value in conventions.items():
        check_choice(name, value)
    path = Path(path)
    lines = read_text_lines(path)
    keywords: dict[str, str] = {}
    keyword_lines: dict[str, int] = {}
    data: list[tuple[int, str]] = []
    for lineno, line in enumerate(lines, 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        if _is_data_line(text):
            data.append((lineno, text))
            continue
        if data:
            raise InputError(f"keyword line {text.split()[0]!r} after the data rows; header keywords come first",
                             path=path, line=lineno)
        keyword, value = (text.split(None, 1) + [""])[:2]
        key = keyword.upper()
        if key in keyword_lines:
            raise InputError(f"keyword {keyword} appears twice (first on line {keyword_lines[key]})",
                             path=path, line=lineno, field=keyword)
        keyword_lines[key] = lineno
        keywords[keyword] = value.strip()
    by_upper = {k.upper(): k for k in keywords}
    for required in ("NUM_POINTS", "VARS"):
        if required not in by_upper:
            raise InputError(f"keyword {required} is missing; an ASTM E1392 file declares NUM_POINTS n and "
                             "VARS theta_i,phi_i,theta_s,phi_s,<channels>", path=path, field=required)
    num_text = keywords.pop(by_upper["NUM_POINTS"])
    num_line = keyword_lines["NUM_POINTS"]
    try:
        num_points = int(num_text)
    except ValueError:
        raise InputError(f"NUM_POINTS {num_text!r} is not an integer", path=path, line=num_line,
                         field="NUM_POINTS") from None
    names, channels = _parse_vars(keywords.pop(by_upper["VARS"]), path, keyword_lines["VARS"])
    if not data:
        raise InputError("no data rows", path=path, line=max(len(lines), 1))
    if num_points != len(data):
        raise InputError(f"NUM_POINTS says {num_points} but the file has {len(data)} data rows",
                         path=path, line=num_line, field="NUM_POINTS")

    table = parse_rows(data, names, path=path, split=_split_fields)

    canonical = [_ANGLE_ALIASES.get(n.lower()) for n in names]
    angle_index = [canonical.index(a) for a in ANGLE_COLUMNS]
    angles = table[:, angle_index]
    full_turn = 2.0 * np.pi if angle_unit == "rad" else 360.0
    for column in (1, 3):  # wrap negative azimuths by one full turn
        finite_negative = np.isfinite(angles[:, column]) & (angles[:, column] < 0.0)
        angles[finite_negative, column] += full_turn
    raw = RawRows(
        path=str(path), lines=np.array([lineno for lineno, _ in data]), angles=angles,
        values=table[:, [i for i, c in enumerate(canonical) if c is None]], channels=channels,
        angle_names=tuple(names[i] for i in angle_index),
    )
    provenance = {"astm_keywords": keywords, **conventions_provenance(conventions)}
    return rows_to_measurement(raw, **conventions, provenance=provenance, source=path)


def _parse_vars(text: str, path, line: int) -> tuple[list[str], tuple[str, ...]]:
    names = [n.strip() for n in text.replace(" ", ",").split(",") if n.strip()]
    canonical = [_ANGLE_ALIASES.get(n.lower()) for n in names]
    for angle, file_name in zip(ANGLE_COLUMNS, ("theta_i", "phi_i", "theta_s", "phi_s"), strict=True):
        if canonical.count(angle) != 1:
            raise InputError(f"VARS must name {file_name} exactly once, found {text!r}; expected "
                             "theta_i,phi_i,theta_s,phi_s,<channels>", path=path, line=line, field="VARS")
    channels = tuple(n for n, c in zip(names, canonical, strict=True) if c is None)
    if not channels:
        raise InputError(f"VARS names no value channel after the four angles: {text!r}", path=path, line=line,
                         field="VARS")
    if len(set(channels)) != len(channels):
        raise InputError(f"VARS names a channel twice: {text!r}", path=path, line=line, field="VARS")
    return names, channels


def write_astm(m: Measurement, path, *, overwrite: bool = False, angle_unit: str = "rad",
               azimuth_zero: str = "weft", azimuth_sense: str = "ccw") -> Path:
    """Write ``m`` (BRDF values; sigma is not part of the format and is dropped) as an ASTM E1392 file.

    ``provenance['astm_keywords']`` (single-line strings) are written back as header keywords.
    """
    for name, value in (("angle_unit", angle_unit), ("azimuth_zero", azimuth_zero),
                        ("azimuth_sense", azimuth_sense)):
        check_choice(name, value)
    path = Path(path)
    if path.exists() and not overwrite:
        raise ResultExistsError(f"{path} already exists; pass overwrite=True (--force) to replace it", path=path)
    angles = [m.theta_i, azimuth_from_clothlab(m.phi_i, zero=azimuth_zero, sense=azimuth_sense),
              m.theta_o, azimuth_from_clothlab(m.phi_o, zero=azimuth_zero, sense=azimuth_sense)]
    if angle_unit == "rad":
        angles = [np.deg2rad(a) for a in angles]
    lines = [f"{key} {value}" for key, value in m.provenance.get("astm_keywords", {}).items()
             if key.upper() not in ("NUM_POINTS", "VARS")]
    lines += [f"NUM_POINTS {m.n}", "VARS " + ",".join(["theta_i", "phi_i", "theta_s", "phi_s", *m.channels])]
    rows = np.concatenate([np.stack(angles, axis=1), m.values], axis=1).tolist()
    lines += [",".join(map(repr, row)) for row in rows]
    return atomic_write_text(path, "\n".join(lines) + "\n")
