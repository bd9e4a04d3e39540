"""Run a fit from a validated configuration: build, optimise, summarise, then cross-validate and sample.

``run_fit(config)`` returns a :class:`FitResult`; ``save_fit(result)`` writes fits/<name>/
(:mod:`clothlab.fit.store`).  The steps, each in its own module:

1. the problem (:func:`clothlab.fit.problem.build_problem`): measurement, weave, model; the free parameters
   start from fabric.yaml ``model.params`` (else the weave's values);
2. the optimisation (:func:`clothlab.fit.optimize.multistart_minimize`): seeded global + local starts, then
   the polish - or, with no free parameter, one NNLS solve of the linear coefficients; a ``kind: neural``
   fit with ``model.options.refine`` then polishes with the exact model (:mod:`clothlab.fit.refine`);
3. at the optimum: the coefficients as albedos (kd, ks_j), the relative-error percentiles (Irawan &
   Marschner 2012, sec. 8), at-bound and geometry notes, Gauss-Newton standard errors
   (:mod:`clothlab.fit.uncertainty`);
4. when configured: k-fold cross-validation (:mod:`clothlab.fit.crossval`) and the emcee posterior
   (:mod:`clothlab.fit.posterior`), resumable from its checkpoint.

Progress goes through :mod:`clothlab.progress` (silent unless configured).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from clothlab.fit import crossval
from clothlab.fit import posterior as posterior_sampling
from clothlab.fit.fitreport import Reportable
from clothlab.fit.metrics import error_percentiles
from clothlab.fit.optimize import multistart_minimize, polish
from clothlab.fit.periodic import release_periodic_bounds
from clothlab.fit.problem import FitProblem, Solution, build_problem, collinearity_notes, evaluation_speed
from clothlab.fit.refine import refine_exact
from clothlab.fit.store import (
    checkpoint_path,
    fit_summary,
    package_versions,
    posterior_files,
    prediction_table,
    save_fit,
    slice_table,
    trace_table,
)
from clothlab.fit.uncertainty import gauss_newton
from clothlab.models.components import coefficient_name
from clothlab.progress import get_logger

__all__ = ["FitResult", "run_fit", "save_fit", "build_problem", "multistart_minimize", "polish", "fit_summary",
           "prediction_table", "slice_table", "trace_table", "posterior_files", "checkpoint_path",
           "package_versions", "collinearity_notes", "evaluation_speed"]

log = get_logger(__name__)

NOTHING_TO_SAMPLE = "posterior skipped: no free parameters, nothing to sample (the coefficients are solved exactly)"


@dataclass(repr=False)
class FitResult(Reportable):
    """The outcome of one fit (everything fit.json holds, plus the arrays behind it).

    ``fit_report()`` gives the full report (text), ``_repr_html_()`` the same as tables for Jupyter."""

    config: object
    problem: FitProblem
    params: dict
    solution: Solution  # at the optimum, normalised components
    coefficients: dict  # name -> (C,) albedos
    optimum: object  # OptimizeResult
    errors: dict
    start_objective: float
    wall_time: float
    warnings: list = field(default_factory=list)
    cross_validation: dict | None = None
    evaluation_speed: dict | None = None
    posterior: object = None  # PosteriorResult (clothlab.fit.posterior) when sampled
    timings: dict = field(default_factory=dict)  # seconds per stage: optimisation, cross_validation, posterior
    uncertainty: dict | None = None  # Gauss-Newton standard errors and correlations (clothlab.fit.uncertainty)
    refinement: dict | None = None  # kind neural with refine: the exact model's polish (clothlab.fit.refine)

    @property
    def name(self) -> str:
        return self.config.name

    def _report_sources(self) -> tuple[dict, dict | None]:
        return fit_summary(self), None if self.posterior is None else self.posterior.to_json()


def _notes_at_optimum(problem, params, optimum, coefficients) -> list[str]:
    notes = list(problem.model.geometry_warnings(params))
    for name, cap in getattr(problem, "geometry_caps", {}).items():
        notes.append(f"fit.valid_geometry: the {cap['bound']} bound of {name} was moved from {cap['declared']:g} to "
                     f"{cap['capped']:.6g}, the limit of the geometry the model accepts at the start values")
    for name, lo, hi in zip(problem.free, optimum.at_lower, optimum.at_upper, strict=True):
        if lo or hi:
            notes.append(f"{name} ended at its {'lower' if lo else 'upper'} bound "
                         f"({params[name]:.6g}): not determined by these data within the bounds")
    check = getattr(optimum, "box_check", None)
    if check and check.get("moved"):
        moved = ", ".join(f"{name} {value:.6g}" for name, value in check["params"].items())
        notes.append(f"the optimum moves when every bound is moved out by {100 * check['enlarged_by']:g} % of its "
                     f"range: objective {check['objective']:.6g} < {check['objective_in_box']:.6g} at {moved}; "
                     "the bounds (fit.bounds) may exclude the best fit")
    notes += collinearity_notes(problem.design(params, normalised=True), problem.component_names)
    for name, coef in coefficients.items():
        if np.all(coef == 0.0):
            notes.append(f"coefficient {name} is 0 in every channel: that component is not seen in the data")
    return notes


def _cross_validate(result, problem, params, config, runner=None) -> None:
    """Cross-validation into ``result`` (the folds as tasks on ``runner`` when given); a problem (data too few for
    the folds, any error inside a fold refit, a fold task failing twice) becomes a note and a warning, never an
    exception: a CV problem never costs the fit."""
    k = config.fit.cv_folds
    try:
        cv = crossval.cross_validate(problem, params, k=k, seed=config.fit.optimizer.seed,
                                     percentiles=config.report.percentiles, scheme=config.fit.cv_scheme,
                                     refit=config.fit.cv_refit, optimizer=config.fit.optimizer, runner=runner)
    except Exception as exc:  # noqa: BLE001 - the fit is kept; the failure is reported as a note
        detail = str(exc) if isinstance(exc, crossval.CrossValidationError) else f"{type(exc).__name__}: {exc}"
        note = f"cross-validation ({k}-fold) not run: {detail}"
        result.cross_validation = {"k": k, "failed": detail, "notes": [note]}
        result.warnings.append(note)
        log.warning("%s: %s", config.name, note)
        return
    result.cross_validation = cv
    result.timings["cross_validation_s"] = cv["wall_time_s"]
    if cv.get("failed"):
        note = f"cross-validation ({k}-fold) incomplete: {cv['failed']}"
        result.warnings.append(note)
        log.warning("%s: %s", config.name, note)
        return
    log.debug("%s: cross-validation (%s) %.1f s, held-out median %.4g", config.name, cv["scheme"],
              cv["wall_time_s"], cv["held_out"]["p50"])


def run_fit(config, *, measurement=None, progress=None, posterior=None, fits_dir=None,
            posterior_progress: bool = True, runner=None) -> FitResult:
    """Fit the model of ``config`` to its measurement (or to ``measurement`` when given).

    ``progress(row)``, optional, is called with each evaluation's :class:`clothlab.fit.optimize.TraceRow`
    (the progress display itself is :mod:`clothlab.progress`'s).  Then, when configured: k-fold
    cross-validation (``fit.cv_folds`` >= 2) and the emcee posterior (``fit.posterior``, or ``posterior`` = a
    PosteriorConfig given here, e.g. by ``clothlab fit --posterior``), resumable from its checkpoint
    (:func:`clothlab.fit.store.checkpoint_path` under ``fits_dir``) if interrupted; ``posterior_progress``
    False silences the sampler's progress; ``runner`` (a :class:`clothlab.parallel.Runner`) runs the
    cross-validation folds as one task each (same figures; :func:`clothlab.fit.crossval.cross_validate`) and may
    evaluate the posterior's walkers in chunks when that is faster (same chain;
    :func:`clothlab.fit.posterior.run_posterior`).
    With no free parameter only the coefficients are solved and the
    posterior is skipped (noted).
    """
    started = time.perf_counter()
    problem = build_problem(config, measurement)
    opt = config.fit.optimizer
    x0 = problem.to_unit(problem.start)
    start_objective = problem(x0)
    log.debug("%s: %d free parameters, %d values, start objective %.6g", config.name, len(problem.free),
              problem.y.size, start_objective)
    optimum = release_periodic_bounds(problem, multistart_minimize(problem, x0, opt, progress))
    refinement = None
    if problem.model.refine and problem.free:  # kind neural: the exact model from there
        optimum, refinement = refine_exact(problem, optimum, opt, progress)
        optimum = release_periodic_bounds(problem, optimum)
    params = problem.from_unit(optimum.x)
    solution = problem.solve(params, normalised=True)
    coefficients = {coefficient_name(n): solution.coefficients[i] for i, n in enumerate(problem.component_names)}
    errors = error_percentiles(problem.y, solution.prediction, config.report.percentiles,
                               problem.measurement.channels)
    notes = _notes_at_optimum(problem, params, optimum, coefficients)
    optimised = time.perf_counter() - started
    if refinement is not None:
        before, after = refinement["encoder"]["objective_exact"], refinement["refined"]["objective_exact"]
        notes.append(f"parameters refined with the exact {refinement['kind']} model from the fit through the "
                     f"network's encoder ({refinement['evaluations']} evaluations): its objective {before:.6g} -> "
                     f"{after:.6g}; the coefficients and errors are the network's at the refined parameters")
    result = FitResult(config, problem, params, solution, coefficients, optimum, errors, start_objective,
                       optimised, notes, timings={"optimisation_s": optimised}, refinement=refinement)
    log.debug("%s: optimisation %d evaluations, %.1f s, objective %.6g", config.name, optimum.nevals, optimised,
              optimum.fun)
    tic = time.perf_counter()
    result.uncertainty = gauss_newton(problem, params)
    result.timings["standard_errors_s"] = time.perf_counter() - tic
    result.evaluation_speed = evaluation_speed(problem, params)
    if config.fit.cv_folds >= 2:
        _cross_validate(result, problem, params, config, runner)
    post = posterior or config.fit.posterior
    if post is not None and not problem.free:
        result.warnings.append(NOTHING_TO_SAMPLE)
        log.info("%s: %s", config.name, NOTHING_TO_SAMPLE)
    elif post is not None:
        path = checkpoint_path(config, fits_dir)
        path.parent.mkdir(parents=True, exist_ok=True)
        result.posterior = posterior_sampling.run_posterior(
            problem, params, walkers=post.walkers, steps=post.steps, max_steps=post.max_steps, seed=opt.seed,
            checkpoint_path=path, progress=posterior_progress, runner=runner)
        result.warnings += [w for w in result.posterior.to_json()["warnings"] if w not in result.warnings]
        result.timings["posterior_s"] = result.posterior.wall_time
        log.debug("%s: posterior %d steps, %.1f s, %s", config.name, result.posterior.steps,
                  result.posterior.wall_time, "converged" if result.posterior.converged else "not converged")
    result.wall_time = time.perf_counter() - started
    return result
