"""A colour correction from a photographed ColorChecker (what ``clothlab calibrate`` does), applied to a table.

The chart file is a CSV with columns R, G, B (linear camera values, one row per patch in the chart's
standard order, 24 rows for the ColorChecker 24; an optional ``patch`` column names the patches).
:func:`calibrate_chart` fits the correction (:mod:`clothlab.colour.chart`, colour-science) from camera RGB to
linear sRGB (D65) of the chart's reference values and returns it with its delta E 2000 before / after per
patch; :func:`correct_measurement` corrects a measurement (values and sigma); values a correction maps below
zero (colours outside the chart's gamut) are raised to 1e-6 of the channel maximum, counted and recorded in
the provenance.
"""

from __future__ import annotations

import csv
import dataclasses
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clothlab.colour.chart import (
    Correction,
    chart_reference,
    check_patch_value,
    check_patches,
    delta_e_2000,
    fit_correction,
)
from clothlab.errors import InputError
from clothlab.progress import get_logger
from clothlab.untrusted import MAX_TABLE_BYTES, parse_number, read_text


def read_chart(path) -> tuple[np.ndarray, list[str]]:
    """(N, 3) patch values and patch names of a chart CSV; errors name the line and column."""
    path = Path(path)
    text = read_text(path, limit=MAX_TABLE_BYTES, what="chart file")
    rows = [(i, r) for i, r in enumerate(csv.reader(io.StringIO(text, newline="")), start=1)
            if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputError("empty chart file", path=path)
    header = [h.strip() for h in rows[0][1]]
    missing = [c for c in ("R", "G", "B") if c not in header]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)}; expected R, G, B (linear camera values)",
                         path=path, line=rows[0][0])
    values, names = [], []
    for line, row in rows[1:]:
        cells = []
        for c in ("R", "G", "B"):
            i = header.index(c)
            if i >= len(row):
                raise InputError("expected a number, found (nothing)", path=path, line=line, field=c)
            v = parse_number(row[i], path=path, line=line, field=c)
            check_patch_value(v, path=path, line=line, field=c)
            cells.append(v)
        values.append(cells)
        names.append(row[header.index("patch")] if "patch" in header else str(len(names) + 1))
    check_patches(np.array(values), path=path)
    return np.array(values), names


@dataclass
class ChartCalibration:
    """A colour correction fitted to a photographed chart: the :class:`~clothlab.colour.chart.Correction`
    (its ``summary`` holds delta E 2000 before / after), the patch names, the measured camera values and the
    chart's reference values, both (N, 3) linear RGB."""

    correction: Correction
    names: list[str]
    measured: np.ndarray
    reference: np.ndarray

    def patches(self) -> list[dict]:
        """Per patch: its name and delta E 2000 before and after the correction."""
        before = delta_e_2000(self.measured, self.reference)
        after = delta_e_2000(self.correction.apply(self.measured), self.reference)
        return [{"patch": n, "delta_e_before": float(b), "delta_e_after": float(a)}
                for n, b, a in zip(self.names, before, after, strict=True)]

    def to_dict(self) -> dict:
        """The calibration as a JSON-ready document (method, options, matrix, summary, patches)."""
        c = self.correction
        return {"method": c.method, "options": c.options, "matrix": c.matrix.tolist(), "summary": c.summary,
                "patches": self.patches()}


def calibrate_chart(chart, *, method: str = "Cheung 2004", degree: int | None = None) -> ChartCalibration:
    """Fit ``method`` (one of :data:`~clothlab.colour.chart.METHODS`) from the chart CSV ``chart`` (see
    :func:`read_chart`) to the ColorChecker reference in linear sRGB (D65)."""
    measured, names = read_chart(chart)
    reference = chart_reference()
    if len(measured) != len(reference):
        raise InputError(f"the chart has {len(measured)} patches, the ColorChecker reference {len(reference)}",
                         path=chart)
    return ChartCalibration(fit_correction(measured, reference, method, degree=degree), names, measured, reference)


FLOOR = 1e-6
"""Corrected values below FLOOR x the channel maximum (colours outside the chart's gamut) are raised to it."""


def correct_measurement(correction: Correction, measurement):
    """``measurement`` corrected (values and sigma, :meth:`Correction.apply_measurement`), with values below
    :data:`FLOOR` x the channel maximum raised to it (a BRDF table holds no negative values); the number
    raised is logged as a warning and recorded in the provenance (``colour_correction_floored_values``)."""
    corrected = correction.apply_measurement(measurement)
    floor = FLOOR * np.max(corrected.values, axis=0, keepdims=True)
    low = corrected.values < floor
    if not low.any():
        return corrected
    get_logger(__name__).warning(
        f"{int(low.sum())} corrected values below {floor.min():.3g} (out of the chart's gamut) were raised to "
        f"{FLOOR:g} x the channel maximum; recorded in the table's provenance")
    return dataclasses.replace(corrected, values=np.where(low, floor, corrected.values),
                               provenance={**corrected.provenance, "colour_correction_floored_values": int(low.sum())})
