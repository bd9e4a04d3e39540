"""Build report directories from saved fit directories (files in, files out; no model evaluation).

``build_report(fits/<name>)``  -> ``reports/<name>/``: index.html, summary.json and the PNG figures.
``build_comparison([...])``    -> ``reports/comparison/``: one table row per fit (the paper's sec. 8 list:
median / 80th / 95th percentile relative error) next to the paper's published figures, and a bar chart.

Writes are atomic: everything goes into a hidden temporary directory next to the
target, renamed into place at the end (:func:`clothlab.atomic.atomic_directory`); an existing report is
replaced only with ``force=True``.
"""

from __future__ import annotations

import json
import math
import os
import signal
import threading
import warnings
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_directory
from clothlab.config.schema import DEFAULT_PERCENTILES
from clothlab.errors import ClothlabError, InputError
from clothlab.report import html, plots
from clothlab.report.data import (
    PAPER_RELATIVE_ERRORS,
    PAPER_SOURCE,
    FitRecord,
    error_percentiles,
    fabric_name,
    free_parameters,
    is_simulated,
    is_usable_dir_name,
    load_fit_dir,
    model_setting,
    optimisation_seconds,
    paper_fabric,
    paper_figures_apply,
    percentile_key,
    selection_rows,
)
from clothlab.report.sampling import SamplingLayout, sampling_layout

PNG_DPI = 110
#: Relative tolerance when the errors recorded in fit.json are compared with those recomputed here.
ERROR_AGREEMENT_RTOL = 1e-3


#: Every PNG stays below this height (px): the resolution drops for a figure taller than it at PNG_DPI.
MAX_PNG_HEIGHT = 2990


def save_figure(fig, path) -> None:
    """Save a figure as PNG at :data:`PNG_DPI` (lower when that would make it taller than
    :data:`MAX_PNG_HEIGHT` px) and release its memory.

    The axes are detached rather than ``fig.clear()``-ed: clearing resets every axes (new ticks, spines and
    locators) only for them to be thrown away, about 0.3 s over a report's figures."""
    dpi = min(PNG_DPI, MAX_PNG_HEIGHT / fig.get_figheight())
    fig.savefig(path, dpi=dpi, pil_kwargs={"compress_level": 1})
    for ax in list(fig.axes):
        fig.delaxes(ax)
    fig.clear()


#: Relative drawing cost of each figure (seconds of one measured report), used to split the figures
#: between two processes; unknown names count as 0.2.
FIGURE_COST = {"hemispheres": 0.72, "corner": 0.8, "slices": 0.47, "parameters": 0.28, "trace": 0.16,
               "error_histogram": 0.15, "residuals": 0.3, "parity": 0.2}


def _end_child(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass


def _split_jobs(jobs) -> tuple[list, list]:
    """Greedy split of the figure jobs into two groups of about equal drawing cost (:data:`FIGURE_COST`)."""
    groups, costs = ([], []), [0.0, 0.0]
    for job in sorted(jobs, key=lambda job: -FIGURE_COST.get(job[0], 0.2)):
        i = int(costs[1] < costs[0])
        groups[i].append(job)
        costs[i] += FIGURE_COST.get(job[0], 0.2)
    return groups


def render_figures(jobs, directory: Path, processes: int = 2, meanwhile=None) -> dict[str, str]:
    """Draw and save every figure job as ``<name>.png`` in ``directory``; returns {name: filename} in job order.
    ``meanwhile(figures)``, optional, is called with that dict once this process has drawn its share (the
    page can be written while the child still draws).

    With ``processes`` 2 and a single-threaded caller on a system with ``fork``, half of the figures (by
    drawing cost) are drawn in a forked child while this process draws the other half: matplotlib's Agg
    drawing is single-threaded, so this is what makes a report take about 60 % of the time on two cores.
    A caller running other Python threads (whose locks the child would inherit) or a system without
    ``fork`` gets everything drawn here; the only other threads allowed are native idle pools such as
    OpenBLAS's, which re-initialise after a fork (as with multiprocessing's fork start method).  A child
    that fails (or is killed) has its figures drawn again here, so an error is raised in this process with
    its usual message; an interrupt of this process ends the child first.
    """
    def draw(group):
        for name, build in group:
            save_figure(build(), directory / f"{name}.png")

    figures = {name: f"{name}.png" for name, _ in jobs}
    theirs, mine = _split_jobs(jobs) if processes >= 2 and len(jobs) > 1 else ([], list(jobs))
    pid = None
    if theirs and hasattr(os, "fork") and threading.active_count() == 1:
        with warnings.catch_warnings():  # Python >= 3.12 warns about the BLAS library's idle worker threads
            warnings.simplefilter("ignore", DeprecationWarning)
            pid = os.fork()
        if pid == 0:  # the child: draw its share and leave without running the parent's exit handlers
            status = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                draw(theirs)
                status = 0
            finally:
                os._exit(status)
    else:
        mine, theirs = list(jobs), []
    try:
        draw(mine)
        if meanwhile is not None:
            meanwhile(figures)
        status = os.waitpid(pid, 0)[1] if pid is not None else 0
    except BaseException:
        if pid is not None:  # interrupted or failed here: the child's figures are not wanted any more
            _end_child(pid)
        raise
    if status != 0:
        draw(theirs)
    return figures


def _figure_jobs(record: FitRecord, percentiles, layout: SamplingLayout | None = None,
                 notes: list[str] | None = None) -> list[tuple[str, object]]:
    """(name, zero-argument figure builder) for each figure the fit's files allow, in page order: the grid
    figures, or for a scattered sampling (:mod:`clothlab.report.sampling`) the scattered ones
    (:func:`_scattered_jobs`); then the figures common to both.  Report notes are appended to ``notes``."""
    layout = layout or sampling_layout(record.predictions)
    notes = notes if notes is not None else []
    jobs = _scattered_jobs(record, notes) if layout.scattered else _grid_jobs(record)
    jobs.append(("error_histogram", lambda: plots.plot_error_histogram(record.predictions, percentiles)))
    if record.fit.get("parameters"):
        jobs.append(("parameters", lambda: plots.plot_parameters(record.fit)))
    if record.trace is not None:
        jobs.append(("trace", lambda: plots.plot_fit_trace(record.trace)))
    if record.posterior_samples:
        declared = (record.posterior or {}).get("parameters", {})
        truths = {n: e.get("truth") for n, e in declared.items()}
        units = {n: e.get("unit") or (record.fit.get("parameters", {}).get(n) or {}).get("unit")
                 for n, e in declared.items()}
        jobs.append(("corner", lambda: plots.plot_corner(record.posterior_samples, truths, units)))
    return jobs


def _scattered_jobs(record: FitRecord, notes: list[str]) -> list[tuple[str, object]]:
    """Model maps at a few representative incident directions, slices where samples lie near their planes,
    residuals against the angles and the parity plot; the fitted model is rebuilt for the maps and slices
    (:mod:`clothlab.report.model_on_grid`)."""
    from clothlab.report import scatter_plots as sp
    from clothlab.report.data import shown_channel
    from clothlab.report.model_on_grid import load_fitted_model
    from clothlab.report.sampling import representative_incidents

    panels = representative_incidents(record.predictions)
    model, why = load_fitted_model(record.path)
    maps = None
    if model is not None:
        try:
            maps = sp.model_maps(model, panels, shown_channel(record.channels)[0])
        except (ClothlabError, ValueError, FloatingPointError) as exc:
            why = f"the fitted model could not be evaluated ({exc}): the maps show the measured points only"
            model = None
    if why:
        notes.append(why)
    chosen = sp.slice_panels(record.predictions, panels)
    jobs = [("hemispheres", lambda: sp.plot_scattered_hemispheres(record.predictions, panels, maps))]
    if chosen:
        jobs.append(("slices", lambda: sp.plot_scattered_slices(record.predictions, chosen, model)))
    else:
        notes.append(f"no incidence-plane slices: none of the {len(panels)} incident directions shown has "
                     f"{sp.MIN_SLICE_POINTS} or more samples within {plots.PLANE_TOLERANCE_DEG:g} deg of its plane.")
    if model is not None:
        notes.extend(model.notes)
    jobs += [("residuals", lambda: sp.plot_residuals(record.predictions)),
             ("parity", lambda: sp.plot_parity(record.predictions))]
    return jobs


def _grid_jobs(record: FitRecord) -> list[tuple[str, object]]:
    jobs = [("hemispheres", lambda: plots.plot_hemisphere_comparison(record.predictions))]
    if record.slices is not None:
        bands = ((record.posterior or {}).get("predictive_slices") or {}).get("bands")
        if bands is not None and len(np.asarray(bands.get("p5", []))) != len(record.slices["theta_o"]):
            bands = None
        jobs.append(("slices", lambda: plots.plot_incidence_slices(record.predictions, record.slices,
                                                                   bands=bands)))
    return jobs


def _finite_json(value):
    """A JSON-safe copy: non-finite floats become None (summary.json is strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_json(v) for v in value]
    return value


def _agreement_notes(recorded, computed: dict, percentiles) -> list[str]:
    """Notes where fit.json's recorded overall errors differ from the ones recomputed from predictions.csv."""
    recorded = (recorded or {}).get("overall") if isinstance(recorded, dict) else None
    if not isinstance(recorded, dict):
        return []
    notes = []
    for q in percentiles:
        key = percentile_key(q)
        old, new = recorded.get(key), computed["overall"].get(key)
        if isinstance(old, int | float) and isinstance(new, int | float) and math.isfinite(new):
            if abs(old - new) > ERROR_AGREEMENT_RTOL * max(abs(new), 1e-12):
                notes.append(f"fit.json records overall {key} = {old:.4g} but predictions.csv gives {new:.4g}; "
                             "the tables show the recomputed value.")
    return notes


def noise_floor_of(record: FitRecord) -> dict | None:
    """The measurement's scatter from repeated / reciprocal direction pairs of predictions.csv
    (:mod:`clothlab.fit.noise_floor`), or None when the table has no direction columns."""
    from clothlab.fit.noise_floor import noise_floor

    p = record.predictions
    columns = [f"measured_{c}" for c in record.channels]
    if not all(k in p for k in ("theta_i", "phi_i", "theta_o", "phi_o", *columns)):
        return None
    values = np.stack([np.asarray(p[c], dtype=np.float64) for c in columns], axis=1)
    return noise_floor(p["theta_i"], p["phi_i"], p["theta_o"], p["phi_o"], values)


def residual_diagnostics_of(record: FitRecord) -> dict | None:
    """The binned residuals of predictions.csv against the geometry (:mod:`clothlab.fit.residuals`), or None
    when the table lacks the columns."""
    from clothlab.fit.residuals import diagnostics

    p = record.predictions
    measured = [f"measured_{c}" for c in record.channels]
    model = [f"model_{c}" for c in record.channels]
    if not all(k in p for k in ("theta_i", "phi_i", "theta_o", "phi_o", *measured, *model)):
        return None
    y = np.stack([np.asarray(p[c], dtype=np.float64) for c in measured], axis=1)
    m = np.stack([np.asarray(p[c], dtype=np.float64) for c in model], axis=1)
    return diagnostics(p["theta_i"], p["phi_i"], p["theta_o"], p["phi_o"], y, m)


def _write_page(tmp: Path, record: FitRecord, figures: dict, errors: dict, notes: list, percentiles,
                layout: SamplingLayout) -> None:
    """summary.json and index.html of one fit's report in ``tmp``."""
    fit = record.fit
    paper_key = paper_fabric(fit)
    summary = {
        "name": record.name,
        "fit_dir": str(record.path),
        "fabric": fabric_name(fit),
        "model": fit.get("model"),
        "measurement": {**(fit.get("measurement") or {}),
                        "simulated": is_simulated((fit.get("measurement") or {}).get("provenance"))},
        "metric": "relative",
        "percentiles": list(percentiles),
        "errors": errors,
        "errors_recorded": fit.get("errors"),
        "paper_errors_percent": (None if paper_key is None else
                                 {"fabric": paper_key, "p50": PAPER_RELATIVE_ERRORS[paper_key][0],
                                  "p80": PAPER_RELATIVE_ERRORS[paper_key][1], "source": PAPER_SOURCE}),
        "parameters": fit.get("parameters"),
        "coefficients": fit.get("coefficients"),
        "timing": {"evaluations": fit.get("evaluations"), "wall_time_s": fit.get("wall_time_s"),
                   "stages_s": fit.get("timings"), "objective": fit.get("objective"), "seed": fit.get("seed"),
                   "optimizer": fit.get("optimizer")},
        "warnings": fit.get("warnings") or [],
        "notes": notes,
        "figures": figures,
        "posterior_present": record.posterior is not None,
        "sampling": {"kind": layout.kind, "reason": layout.reason},
        "selection": selection_rows(fit),
        "noise_floor": noise_floor_of(record),
        "residual_diagnostics": residual_diagnostics_of(record),
    }
    (tmp / "summary.json").write_text(
        json.dumps(_finite_json(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    page = html.render_report_html(fit, figures, {"errors": errors, "percentiles": percentiles,
                                                  "notes": notes, "posterior": record.posterior,
                                                  "sampling": layout, "noise_floor": summary["noise_floor"],
                                                  "residual_diagnostics": summary["residual_diagnostics"]})
    (tmp / "index.html").write_text(page, encoding="utf-8")


def build_report(fit_dir, reports_dir="reports", *, force: bool = False, percentiles=DEFAULT_PERCENTILES,
                 processes: int = 2) -> Path:
    """Write ``<reports_dir>/<fit name>/`` (index.html, summary.json, PNGs) from a fit directory.

    Returns the report directory.  Raises :class:`InputError` naming the file if fit.json or
    predictions.csv (or a present optional file) is missing or corrupt, and
    :class:`~clothlab.errors.ResultExistsError` if the report exists and ``force`` is false.  On any
    failure no partial report and no temporary directory is left behind.  ``processes`` 2 draws half of the
    figures in a forked child (:func:`render_figures`), 1 draws all of them here.
    """
    percentiles = tuple(percentiles)
    record = load_fit_dir(fit_dir)
    errors = error_percentiles(record.predictions, record.channels, percentiles)
    notes = list(record.notes) + _agreement_notes(record.fit.get("errors"), errors, percentiles)
    layout = sampling_layout(record.predictions)
    if layout.scattered:  # slices.csv holds exitant-direction planes: not what a scattered report shows
        notes = [n for n in notes if not n.startswith("slices.csv")]
    dest = Path(reports_dir) / record.name

    with atomic_directory(dest, force=force) as tmp:
        def page(figures):
            _write_page(tmp, record, figures, errors, notes, percentiles, layout)

        render_figures(_figure_jobs(record, percentiles, layout, notes), tmp, processes, meanwhile=page)
    return dest


def _comparison_row(record: FitRecord, reports_dir: Path, dest: Path) -> dict:
    fit = record.fit
    overall = error_percentiles(record.predictions, record.channels, DEFAULT_PERCENTILES)["overall"]
    paper_key = paper_fabric(fit)
    report = reports_dir / record.name / "index.html"
    return {
        "name": record.name,
        "fabric": fabric_name(fit),
        "model": (fit.get("model") or {}).get("kind"),
        "setting": model_setting(fit),
        "parameters": free_parameters(fit),
        "p50": overall["p50"], "p80": overall["p80"], "p95": overall["p95"], "n": overall["n"],
        "free": sum(1 for e in (fit.get("parameters") or {}).values() if e.get("free", True)),
        "evaluations": fit.get("evaluations"),
        "wall_time_s": optimisation_seconds(fit),
        "pairs_per_second": (fit.get("evaluation_speed") or {}).get("pairs_per_second"),
        "simulated": is_simulated((fit.get("measurement") or {}).get("provenance")),
        "generated_by": ((fit.get("measurement") or {}).get("provenance") or {}).get("model"),
        "paper": PAPER_RELATIVE_ERRORS.get(paper_key) if paper_figures_apply(fit) else None,
        "paper_fabric": paper_key,
        "link": f"../{record.name}/index.html" if report.exists() and dest.parent == reports_dir else None,
    }


def build_comparison(fit_dirs, reports_dir="reports", name: str = "comparison", force: bool = False) -> Path:
    """Write ``<reports_dir>/<name>/`` (index.html, comparison.png, summary.json) comparing several fits.

    One row per fit: fabric, model kind, the model's setting (:func:`model_setting`), the fitted free
    parameters with their declared units, median / 80th / 95th percentile relative error, free parameter
    count, evaluations, wall time, and the paper's published median / 80th figures on
    real measurements where the fabric matches (Irawan & Marschner 2012, sec. 8).  Returns the directory.
    """
    fit_dirs = list(fit_dirs)
    if not fit_dirs:
        raise InputError("no fit directories given; expected one or more fits/<name>/ directories")
    reports_dir = Path(reports_dir)
    if not is_usable_dir_name(name):
        raise InputError(f"comparison name {name!r} is not usable as a directory name; expected one path "
                         "component without '/' or '\\'", field="name")
    dest = reports_dir / name
    rows = [_comparison_row(load_fit_dir(d), reports_dir, dest) for d in fit_dirs]
    with atomic_directory(dest, force=force) as tmp:
        chart = [{"label": r["name"], "p50": r["p50"], "p80": r["p80"], "paper": r["paper"]} for r in rows]
        save_figure(plots.plot_error_comparison(chart), tmp / "comparison.png")
        figures = {"comparison": "comparison.png"}
        summary = {"name": name, "fits": [str(d) for d in fit_dirs], "rows": rows, "paper_source": PAPER_SOURCE}
        (tmp / "summary.json").write_text(
            json.dumps(_finite_json(summary), indent=2, allow_nan=False) + "\n", encoding="utf-8")
        (tmp / "index.html").write_text(html.render_comparison_html(rows, figures, title=name), encoding="utf-8")
    return dest
