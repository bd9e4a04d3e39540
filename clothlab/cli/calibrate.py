"""``clothlab calibrate chart.csv``: a colour correction from a photographed ColorChecker (colour-science),
its delta E 2000 before / after, optionally applied to a measurement table and written as a page."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import LazyText, add_force, add_output, count_type, names_of, one_of

METHODS = names_of("clothlab.colour.chart", "METHODS")


def add_parser(sub):
    p = sub.add_parser("calibrate", help="colour correction from a photographed ColorChecker (colour-science)",
                       description="Fit a colour correction from camera RGB of a photographed ColorChecker to its "
                                   "reference (linear sRGB, D65); print delta E 2000 before / after.")
    p.add_argument("chart", type=Path, help="CSV with R, G, B linear camera values per patch (24 rows)")
    p.add_argument("--method", default="Cheung 2004", type=one_of(METHODS, "method"),
                   help=LazyText(lambda: f"one of {', '.join(repr(m) for m in METHODS())} (default 'Cheung 2004')"))
    p.add_argument("--degree", type=count_type(1, 10), help="root-polynomial / Vandermonde degree")
    p.add_argument("--apply", type=Path, metavar="TABLE", help="correct this measurement table (needs -o)")
    add_output(p, "corrected table (with --apply)", metavar="TABLE")
    p.add_argument("--report", type=Path, metavar="DIR", help="write a page with delta E 2000 before / after")
    add_force(p, "corrected table")
    return p


def run(args) -> int:
    from clothlab.colour.calibrate import calibrate_chart
    from clothlab.errors import InputError

    if args.apply is not None and args.output is None:
        raise InputError("--apply needs -o OUTPUT for the corrected table", field="--output")
    calibration = calibrate_chart(args.chart, method=args.method, degree=args.degree)
    print(present_calibration(calibration))
    if args.apply is not None:
        from clothlab.colour.calibrate import correct_measurement
        from clothlab.io.loader import load_measurement
        from clothlab.io.table import write_table

        corrected = correct_measurement(calibration.correction, load_measurement(args.apply))
        print(write_table(corrected, args.output, overwrite=args.force))
    if args.report is not None:
        from clothlab.report.study_pages import write_study_report

        page = write_study_report(calibration.to_dict(), args.report, title="clothlab calibrate: colour correction")
        print(f"report: {page}")
    return 0


def present_calibration(calibration) -> str:
    """``<method>: delta E 2000 before mean .. (max ..), after mean .. (max ..)``."""
    s = calibration.correction.summary
    before, after = s["delta_e_2000_before"], s["delta_e_2000_after"]
    return (f"{calibration.correction.method}: delta E 2000 before mean {before['mean']:.2f} "
            f"(max {before['max']:.2f}), after mean {after['mean']:.2f} (max {after['max']:.2f})")
