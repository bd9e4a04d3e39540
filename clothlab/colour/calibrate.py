"""``clothlab calibrate``: a colour correction from a photographed ColorChecker, applied to a table.

The chart file is a CSV with columns R, G, B (linear camera values, one row per patch in the chart's
standard order, 24 rows for the ColorChecker 24; an optional ``patch`` column is kept for the report).
The correction (:mod:`clothlab.colour.chart`, colour-science) maps camera RGB to linear sRGB (D65)
of the chart's reference values; its delta E 2000 before / after is printed and, with ``report``, written
as a page.  ``apply`` corrects a measurement table (values and sigma) and writes a new clothlab table;
values a correction maps below zero (colours outside the chart's gamut) are raised to 1e-6 of the channel
maximum, counted and recorded in the table's provenance.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from clothlab.errors import InputError


def read_chart(path) -> tuple[np.ndarray, list[str]]:
    """(N, 3) patch values and patch names of a chart CSV; errors name the line and column."""
    path = Path(path)
    if not path.is_file():
        raise InputError("chart file not found", path=path)
    with path.open(newline="") as fh:
        rows = [(i, r) for i, r in enumerate(csv.reader(fh), start=1) if r and not r[0].lstrip().startswith("#")]
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
            try:
                v = float(row[i])
            except (IndexError, ValueError):
                raise InputError(f"expected a number, found {row[i] if i < len(row) else '(nothing)'!r}",
                                 path=path, line=line, field=c) from None
            if not np.isfinite(v) or v < 0:
                raise InputError(f"value {v!r} must be finite and >= 0", path=path, line=line, field=c)
            cells.append(v)
        values.append(cells)
        names.append(row[header.index("patch")] if "patch" in header else str(len(names) + 1))
    return np.array(values), names


def calibrate_command(chart, *, method="Cheung 2004", degree=None, apply=None, output=None, report=None,
                      force=False) -> int:
    from clothlab.colour.chart import chart_reference, delta_e_2000, fit_correction

    measured, names = read_chart(chart)
    reference = chart_reference()
    if len(measured) != len(reference):
        raise InputError(f"the chart has {len(measured)} patches, the ColorChecker reference {len(reference)}",
                         path=chart)
    correction = fit_correction(measured, reference, method, degree=degree)
    s = correction.summary
    before_s, after_s = s["delta_e_2000_before"], s["delta_e_2000_after"]
    print(f"{method}: delta E 2000 before mean {before_s['mean']:.2f} (max {before_s['max']:.2f}), "
          f"after mean {after_s['mean']:.2f} (max {after_s['max']:.2f})")
    if apply is not None:
        from clothlab.io.loader import load_measurement
        from clothlab.io.table import write_table

        if output is None:
            raise InputError("--apply needs -o OUTPUT for the corrected table", field="--output")
        import dataclasses

        corrected = correction.apply_measurement(load_measurement(apply))
        floor = 1e-6 * np.max(corrected.values, axis=0, keepdims=True)
        low = corrected.values < floor
        if low.any():  # out-of-gamut colours map below zero; a BRDF table holds no negative values
            print(f"warning: {int(low.sum())} corrected values below {floor.min():.3g} (out of the chart's gamut) "
                  "were raised to 1e-6 x the channel maximum; recorded in the table's provenance")
            corrected = dataclasses.replace(
                corrected, values=np.where(low, floor, corrected.values),
                provenance={**corrected.provenance, "colour_correction_floored_values": int(low.sum())})
        print(write_table(corrected, output, overwrite=force))
    if report is not None:
        from clothlab.report.studies import write_study_report

        after = delta_e_2000(correction.apply(measured), reference)
        before = delta_e_2000(measured, reference)
        result = {"method": method, "options": correction.options, "matrix": correction.matrix.tolist(),
                  "summary": s, "patches": [{"patch": n, "delta_e_before": float(b), "delta_e_after": float(a)}
                                            for n, b, a in zip(names, before, after, strict=True)]}
        print(f"report: {write_study_report(result, report, title='clothlab calibrate: colour correction')}")
    return 0
