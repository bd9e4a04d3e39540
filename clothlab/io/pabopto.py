"""pab-opto "Mountain" goniophotometer text files (docs/formats.md, "pab-opto goniophotometer text").

One file per incident direction; ``#`` header lines, then rows ``theta_o phi_o value(s)`` (whitespace
separated, degrees).  Header lines read (keyword with or without a colon, case-insensitive):

- ``#format: theta phi DSF|BSDF|BRDF|BTDF`` (required).  DSF = BSDF * cos(theta_o), so DSF values are divided
  by cos(theta_o); BSDF/BRDF/BTDF values are BSDF in 1/sr.
- ``#intheta t`` and ``#inphi p``, or ``#incident_angle t p`` (required; degrees).
- ``#upphi u`` (default 0): the instrument azimuth of the sample's "up" direction.
- ``#colorimetry: CIE-Y|CIE-XYZ`` (default CIE-Y): one value column ``Y`` or three ``X, Y, Z``.
- ``#sample_name "..."``, ``#datapoints_in_file N`` (checked against the number of rows when given).
Other ``#`` lines of the header block are ignored.

Azimuth mapping (as Radiance's pabopto2bsdf turns files to "Y-up": phi + 90 - upphi): the sample's up
direction is taken to be the warp (``up='warp'``, default; ``up='weft'`` if the sample was mounted turned),
azimuths are counter-clockwise seen from above, so clothlab phi = phi_file - upphi + 90 deg for up = warp
(+ 0 deg for up = weft), for incident and exitant directions alike.

Reflection only: a file lit from the back side (incident theta > 90 deg) is rejected with an InputError;
rows with theta_o in (90, 180] deg (light transmitted through the sample) are skipped and counted in
``provenance['transmission_rows_skipped']``, so a full BSDF measurement can be loaded for its reflection part.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import InputError
from clothlab.io.measurement import Measurement
from clothlab.io.table import (
    DSF,
    RawRows,
    check_rows,
    check_unique_directions,
    convert_rows,
    parse_number,
    parse_rows,
    read_text_lines,
)

FORMAT_QUANTITY = {"DSF": DSF, "BSDF": "brdf", "BRDF": "brdf", "BTDF": "brdf"}
COLORIMETRY_CHANNELS = {"CIE-Y": ("Y",), "CIE-XYZ": ("X", "Y", "Z")}
SAMPLE_UP = {"warp": "warp", "weft": "weft"}
_HEADER_LINE = re.compile(r"^#\s*([A-Za-z_]+)\s*:?\s*(.*)$")


@dataclass
class _PabFile:
    path: Path
    quantity: str
    channels: tuple[str, ...]
    sample_name: str | None
    upphi: float
    raw: RawRows
    skipped: int


def _numbers(text: str, count: int, *, path, line: int, key: str) -> list[float]:
    fields = text.split()
    if len(fields) != count:
        raise InputError(f"#{key} needs {count} number{'s' if count > 1 else ''}, found {text!r}",
                         path=path, line=line, field=key)
    return [parse_number(f, path=path, line=line, column=key) for f in fields]


def _read_file(path: Path) -> _PabFile:
    lines = read_text_lines(path)
    found: dict[str, tuple[object, int]] = {}
    start = 0
    while start < len(lines) and lines[start].startswith("#"):
        lineno = start + 1
        start += 1
        match = _HEADER_LINE.match(lines[start - 1].strip())
        if not match:
            continue
        key, value = match.group(1).lower(), match.group(2).strip()
        if key == "format":
            tokens = value.split()
            kind = tokens[-1].upper() if tokens else ""
            if len(tokens) != 3 or [t.lower() for t in tokens[:2]] != ["theta", "phi"] or kind not in FORMAT_QUANTITY:
                raise InputError(f"format {value!r} not understood; expected 'theta phi "
                                 f"{'|'.join(FORMAT_QUANTITY)}'", path=path, line=lineno, field="format")
            found[key] = (FORMAT_QUANTITY[kind], lineno)
        elif key in ("intheta", "inphi", "upphi"):
            found[key] = (_numbers(value, 1, path=path, line=lineno, key=key)[0], lineno)
        elif key == "incident_angle":
            theta, phi = _numbers(value, 2, path=path, line=lineno, key=key)
            found["intheta"], found["inphi"] = (theta, lineno), (phi, lineno)
        elif key == "colorimetry":
            if value.upper() not in COLORIMETRY_CHANNELS:
                raise InputError(f"colorimetry {value!r} not understood; expected "
                                 f"{' | '.join(COLORIMETRY_CHANNELS)}", path=path, line=lineno, field=key)
            found[key] = (COLORIMETRY_CHANNELS[value.upper()], lineno)
        elif key == "sample_name":
            found[key] = (value.strip().strip('"'), lineno)
        elif key == "datapoints_in_file":
            count = _numbers(value, 1, path=path, line=lineno, key=key)[0]
            if count != int(count) or count < 0:
                raise InputError(f"datapoints_in_file {value!r} is not a count", path=path, line=lineno, field=key)
            found[key] = (int(count), lineno)

    if "format" not in found:
        raise InputError("no '#format: theta phi DSF|BSDF|BRDF|BTDF' header line", path=path, line=1)
    for key in ("intheta", "inphi"):
        if key not in found:
            raise InputError(f"incident direction missing: expected '#intheta t' and '#inphi p' or "
                             f"'#incident_angle t p' (degrees); no {key} found", path=path, line=1, field=key)
    theta_i, theta_line = found["intheta"]
    phi_i, phi_line = found["inphi"]
    if not np.isfinite(theta_i) or not 0.0 <= theta_i <= 90.0:
        back = np.isfinite(theta_i) and 90.0 < theta_i <= 180.0
        raise InputError(
            f"incident theta {theta_i!r} is outside [0, 90] deg"
            + ("; the file is lit from the back side and clothlab handles front-side reflection only: "
               "leave back-side files out" if back else ""),
            path=path, line=theta_line, field="intheta")
    if not np.isfinite(phi_i):
        raise InputError(f"incident phi {phi_i!r} is not finite", path=path, line=phi_line, field="inphi")
    channels = found.get("colorimetry", (COLORIMETRY_CHANNELS["CIE-Y"], 0))[0]
    upphi = found.get("upphi", (0.0, 0))[0]
    if not np.isfinite(upphi):
        raise InputError(f"upphi {upphi!r} is not finite", path=path, line=found["upphi"][1], field="upphi")

    names = ("theta", "phi", *channels)
    rows = []
    for lineno, line in enumerate(lines[start:], start + 1):
        text = line.strip()
        if text.startswith("#"):
            raise InputError("'#' header line after the data rows; header lines come first", path=path, line=lineno)
        if text:
            rows.append((lineno, text))
    table = parse_rows(rows, names, path=path, split=str.split, separator=" ")
    row_lines = [lineno for lineno, _ in rows]
    if "datapoints_in_file" in found and found["datapoints_in_file"][0] != len(rows):
        count, lineno = found["datapoints_in_file"]
        raise InputError(f"datapoints_in_file says {count} but the file has {len(rows)} data rows",
                         path=path, line=lineno, field="datapoints_in_file")
    transmitted = (table[:, 0] > 90.0) & (table[:, 0] <= 180.0)
    table = table[~transmitted]
    angles = np.column_stack([np.full(len(table), theta_i), np.full(len(table), phi_i), table[:, :2]])
    raw = RawRows(path=str(path), lines=np.array(row_lines, dtype=int)[~transmitted], angles=angles,
                  values=table[:, 2:], channels=channels, angle_names=("intheta", "inphi", "theta", "phi"))
    return _PabFile(path, found["format"][0], channels, found.get("sample_name", (None, 0))[0], upphi, raw,
                    int(transmitted.sum()))


def _input_files(source) -> list[Path]:
    if isinstance(source, str | Path):
        source = Path(source)
        if not source.exists():
            raise InputError("file or directory not found", path=source)
        if source.is_dir():
            files = sorted(p for p in source.iterdir() if p.is_file() and not p.name.startswith("."))
            if not files:
                raise InputError("directory holds no pab-opto files", path=source)
            return files
        return [source]
    files = [Path(p) for p in source]
    if not files:
        raise InputError("no pab-opto files given")
    return files


def read_pabopto(source: str | Path | Iterable, *, up: str = "warp") -> Measurement:
    """Merge the pab-opto files of one sample (a directory, one file, or a list of files) into a Measurement.

    up : which yarn direction the sample's up direction (``#upphi``) is, 'warp' (default) or 'weft'.
    Channels are ('Y',) or ('X', 'Y', 'Z') (``#colorimetry``), values BRDF in 1/sr.
    """
    if up not in SAMPLE_UP:
        raise InputError(f"unknown sample up direction {up!r}; expected warp | weft", field="up")
    files = [_read_file(p) for p in _input_files(source)]
    first = files[0]
    names = {f.sample_name for f in files if f.sample_name is not None}
    for f in files[1:]:
        if f.channels != first.channels:
            raise InputError(f"colorimetry gives channels {f.channels}, but {first.path.name} has {first.channels};"
                             " all files of one sample must use the same colorimetry", path=f.path)
    if len(names) > 1:
        raise InputError(f"files of different samples mixed: sample names {sorted(names)}", path=first.path.parent)
    parts = []
    for f in files:
        check_rows(f.raw, angle_unit="deg", quantity=f.quantity)
        parts.append(convert_rows(f.raw, angle_unit="deg", quantity=f.quantity, azimuth_zero=SAMPLE_UP[up],
                                  azimuth_sense="ccw", azimuth_offset=-f.upphi))
    theta_i, phi_i, theta_o, phi_o, values = (np.concatenate([p[k] for p in parts]) for k in range(5))
    if len(theta_i) == 0:
        raise InputError("no reflection rows (theta <= 90 deg) in the pab-opto files", path=first.path)
    check_unique_directions(theta_i, phi_i, theta_o, phi_o,
                            [(f.raw.path, int(n)) for f in files for n in f.raw.lines])
    provenance = {
        "source_format": "pab-opto",
        "files": [f.path.name for f in files],
        "colorimetry": "CIE-XYZ" if len(first.channels) == 3 else "CIE-Y",
        "sample_up": up,
        "transmission_rows_skipped": sum(f.skipped for f in files),
    }
    if names:
        provenance["sample_name"] = names.pop()
    source_name = source if isinstance(source, str | Path) else first.path
    return Measurement(theta_i, phi_i, theta_o, phi_o, values, first.channels, None, provenance, str(source_name))
