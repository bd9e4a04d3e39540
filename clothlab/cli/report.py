"""``clothlab report [fits/<name> ...]``: an HTML page with PNG plots per fit, and a comparison page when
several fits are given."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import add_force, add_output


def add_parser(sub):
    p = sub.add_parser("report", help="HTML report of fits (default: every fit under ./fits)",
                       description="Build reports/<name>/index.html (plots, percentile tables) for each fit "
                                   "directory, and a comparison page when there are several.")
    p.add_argument("fits", nargs="*", type=Path, metavar="fits/<name>",
                   help="fit directories (default: every directory with a fit.json under ./fits)")
    add_output(p, "reports directory (default: reports)", metavar="DIR", default=Path("reports"),
               deprecated=("--out",))
    add_force(p, "reports")
    p.add_argument("--comparison-name", default="comparison",
                   help="name of the multi-fit comparison report (default: comparison)")
    return p


def run(args) -> int:
    from clothlab.errors import ConfigError
    from clothlab.report.build import build_comparison, build_report

    fits = list(args.fits)
    if not fits:
        root = Path("fits")
        fits = sorted(d for d in root.iterdir() if (d / "fit.json").is_file()) if root.is_dir() else []
        if not fits:
            raise ConfigError("no fit directories given and none found under ./fits (run `clothlab fit` first)")
    for fit_dir in fits:
        out = build_report(fit_dir, args.output, force=args.force)
        print(f"{fit_dir} -> {out / 'index.html'}")
    if len(fits) > 1:
        out = build_comparison(fits, args.output, name=args.comparison_name, force=args.force)
        print(f"comparison of {len(fits)} fits -> {out / 'index.html'}")
    return 0
