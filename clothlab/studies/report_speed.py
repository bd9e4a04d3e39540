"""Bench section ``report``: how long ``clothlab report`` of one fit takes (target :data:`REPORT_TARGET_S`).

Measured side by side in one run on the same fit directory: the whole command as a user runs it (a fresh
interpreter: ``python -m clothlab report FIT -o TMP --force``, imports included), and in-process
:func:`clothlab.report.build.build_report` with the figures drawn in one process and in two
(:func:`clothlab.report.build.render_figures`), alternated call by call.  The fit is the saved
polyester-lining example (with its posterior, so the corner plot is drawn) when the data directory has one,
else a short fit of the regenerated example (optimisation only) made in a temporary directory.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from clothlab.studies.data import StudyData, study_data

FABRIC = "polyester-lining"
REPORT_TARGET_S = 3.0


def _fit_dir(d: StudyData, tmp: Path) -> tuple[Path, str]:
    saved = d.fit_dir(FABRIC)
    if saved is not None:
        return saved, f"saved fit {saved}"
    from clothlab.fit.runner import run_fit
    from clothlab.fit.store import save_fit
    from clothlab.studies.posterior import optimisation_only

    result = run_fit(optimisation_only(d.load_config(FABRIC), max_evals=600, starts=1))
    return save_fit(result, fits_dir=tmp / "fits"), "a short fit of the regenerated example (no posterior)"


def report_speed(quick: bool, *, data: StudyData | None = None, fit_dir: Path | None = None,
                 runs: int | None = None) -> dict:
    """The figures above for ``fit_dir`` (default: the example's, :func:`_fit_dir`), ``runs`` of each (3 quick,
    5 full)."""
    from clothlab.report.build import build_report

    runs = runs or (3 if quick else 5)
    with study_data(data) as d, tempfile.TemporaryDirectory(prefix="clothlab-report-bench-") as tmp:
        tmp = Path(tmp)
        fit_dir, source = (Path(fit_dir), f"fit {fit_dir}") if fit_dir is not None else _fit_dir(d, tmp)
        command = [sys.executable, "-m", "clothlab", "-q", "report", str(fit_dir), "-o", str(tmp / "cli"), "--force"]
        cli = []
        for _ in range(runs):
            t = time.perf_counter()
            subprocess.run(command, capture_output=True, check=True)
            cli.append(time.perf_counter() - t)
        build_report(fit_dir, tmp / "warm", force=True)  # imports and first drawing outside the timings
        timed = {1: [], 2: []}
        for _ in range(runs):
            for processes in (1, 2):
                t = time.perf_counter()
                build_report(fit_dir, tmp / f"p{processes}", force=True, processes=processes)
                timed[processes].append(time.perf_counter() - t)
        figures = sorted(p.name for p in (tmp / "p2" / fit_dir.name).glob("*.png"))
    one, two = statistics.median(timed[1]), statistics.median(timed[2])
    return {"fit": source, "runs": runs, "figures": figures,
            "cli_seconds_best": min(cli), "cli_seconds_median": statistics.median(cli),
            "build_one_process_s": one, "build_two_processes_s": two, "ratio": one / two,
            "target_s": REPORT_TARGET_S, "meets_target": statistics.median(cli) <= REPORT_TARGET_S}


def run(context) -> dict:
    return report_speed(context.quick, data=context.data)


def lines(result: dict) -> list[str]:
    verdict = "meets" if result["meets_target"] else "misses"
    return ["== report ==",
            f"  {result['fit']}: {len(result['figures'])} figures",
            f"  clothlab report (fresh interpreter, imports included): median {result['cli_seconds_median']:.2f} s, "
            f"best {result['cli_seconds_best']:.2f} s of {result['runs']} ({verdict} the "
            f"{result['target_s']:g} s target)",
            f"  build_report in-process, median of {result['runs']} alternated: one process "
            f"{result['build_one_process_s']:.2f} s, figures in two processes {result['build_two_processes_s']:.2f} s "
            f"(ratio {result['ratio']:.2f})"]
