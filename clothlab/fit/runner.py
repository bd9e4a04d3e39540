"""Run a fit from a validated configuration: load, build, optimise, summarise, save.

``run_fit(config)`` returns a :class:`FitResult`; ``save_fit(result)`` writes fits/<name>/
(:mod:`clothlab.fit.store`).  Steps: the measurement is loaded and the weave resolved; the model's free
parameters start from fabric.yaml ``model.params`` (else the weave's values); nlopt runs a seeded global stage
then a local polish (:func:`clothlab.fit.optimize.minimize`); the linear coefficients are re-solved at the
optimum and converted to albedos (kd, ks_j; :mod:`clothlab.models.irawan.model`); relative-error
percentiles (paper sec. 8) and at-bound flags are computed.
"""

from __future__ import annotations

import platform
import time
import warnings
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata

import numpy as np

from clothlab import __version__
from clothlab.errors import GeometryWarning
from clothlab.fit.metrics import error_percentiles
from clothlab.fit.problem import FitProblem, Solution
from clothlab.frames import spherical_to_vector
from clothlab.models.components import coefficient_name

VERSIONED = ("numpy", "scipy", "numba", "nlopt", "matplotlib", "PyYAML", "emcee")


def package_versions() -> dict:
    out = {"python": platform.python_version(), "clothlab": __version__}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


@dataclass
class FitResult:
    """The outcome of one fit (everything fit.json holds, plus the arrays behind it)."""

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

    @property
    def name(self) -> str:
        return self.config.name


def build_problem(config, measurement=None):
    """Measurement, weave and model of a configuration -> FitProblem."""
    from clothlab.io.loader import load_measurement
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    if measurement is None:
        measurement = load_measurement(config.measurement.path, None if config.measurement.format == "auto"
                                       else config.measurement.format, **config.measurement.options)
    weave = resolve_weave(config.model.weave, config.base_dir)
    q = config.model.quadrature
    model = build_model(config.model.kind, weave, (q.rule, q.nodes), **config.model.options)
    return FitProblem(model, measurement, config.fit.free, config.model.params, config.fit.bounds, config.fit.metric)


def multistart_minimize(problem, x0, opt, progress=None):
    """``opt.starts`` independent seeded global + local runs (budget split evenly); the best is kept and the
    traces are concatenated (stage names carry the start number when there are several)."""
    from dataclasses import replace

    from clothlab.fit.optimize import minimize

    k = len(problem.free)
    budget = max(opt.max_evals // opt.starts, 1)
    best, trace, offset, time_offset = None, [], 0, 0.0
    for start in range(opt.starts):
        result = minimize(problem, x0, np.zeros(k), np.ones(k), global_algorithm=opt.global_algorithm,
                          local_algorithm=opt.local_algorithm, max_evals=budget, seed=opt.seed + start,
                          max_time=opt.max_time, callback=progress)
        best_before = best.fun if best is not None else np.inf
        for row in result.trace:
            stage = row.stage if opt.starts == 1 else f"{row.stage}#{start + 1}"
            trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage=stage,
                                      best=min(row.best, best_before)))
        offset += result.nevals
        time_offset += result.wall_time
        if best is None or result.fun < best.fun:
            best = result
    best = replace(best, trace=trace, nevals=offset, wall_time=time_offset)
    return polish(problem, best, opt, progress)


#: A polish round that improves the objective by less than this (relative) ends the polish.
POLISH_RTOL = 1e-6
#: Evaluations of one local search inside the polish.
POLISH_ROUND_EVALS = 600


def polish(problem, best, opt, progress=None):
    """Restart local searches from ``best`` (an OptimizeResult) until a round of [opt's local algorithm,
    LN_SBPLX] improves the objective by less than :data:`POLISH_RTOL` relative or ``opt.polish_evals`` is
    spent.  A restart gets a fresh trust region / simplex: on this objective (piecewise smooth under a
    fixed-node rule) BOBYQA often reports convergence early, and SBPLX copes with the roughness.  The
    result is never worse than ``best``; its trace continues best's, stage 'polish'."""
    from dataclasses import replace

    from clothlab.fit.optimize import minimize

    budget = opt.polish_evals
    if budget <= 0:
        return best
    k = len(problem.free)
    algorithms = tuple(dict.fromkeys(a for a in (opt.local_algorithm, "LN_SBPLX") if a))
    x, fun, trace, offset, time_offset = best.x, best.fun, list(best.trace), best.nevals, best.wall_time
    used, improved = 0, True
    while improved and used < budget:
        round_start = fun
        for algorithm in algorithms:
            evals = min(POLISH_ROUND_EVALS, budget - used)
            if evals <= 0:
                break
            result = minimize(problem, x, np.zeros(k), np.ones(k), global_algorithm=None,
                              local_algorithm=algorithm, max_evals=evals, seed=opt.seed, callback=progress)
            for row in result.trace:
                trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage="polish",
                                          best=min(row.best, fun)))
            offset += result.nevals
            time_offset += result.wall_time
            used += result.nevals
            if result.fun < fun:
                x, fun = result.x, result.fun
                best = replace(best, x=x, fun=fun, at_lower=result.at_lower, at_upper=result.at_upper)
        improved = fun < round_start * (1.0 - POLISH_RTOL)
    status = dict(best.status, polish=f"{used} evaluations, objective {best.fun:.6g}")
    message = f"{best.message}; polish: {used} evaluations"
    return replace(best, trace=trace, nevals=offset, wall_time=time_offset, status=status, message=message)


def evaluation_speed(problem, params, repeats: int = 5) -> dict:
    """Direction pairs per second of one full model evaluation (all components) on the measured directions,
    best of ``repeats`` (memoised yarn integrals cleared, so this is the cost of a new parameter point)."""
    best = float("inf")
    for _ in range(repeats):
        memo = getattr(problem.model, "_memo", None)
        if memo is not None:
            memo.clear()
        t = time.perf_counter()
        problem.design(params)
        best = min(best, time.perf_counter() - t)
    return {"pairs_per_second": problem.measurement.n / best, "seconds_per_evaluation": best,
            "directions": problem.measurement.n}


def checkpoint_path(config, fits_dir=None):
    """Where an interrupted posterior run keeps its chain: a hidden file next to fits/<name>/ (the fit
    directory itself is only written, atomically, when everything is done)."""
    root = fits_dir if fits_dir is not None else config.output.fits
    return root / f".{config.name}.posterior-checkpoint.npz"


def run_fit(config, *, measurement=None, progress=None, posterior=None, fits_dir=None,
            posterior_progress: bool = True) -> FitResult:
    """Fit the model of ``config`` to its measurement.  ``progress(row)`` is called after each evaluation.

    Then, when configured: k-fold cross-validation (``fit.cv_folds`` >= 2) and the emcee posterior
    (``fit.posterior``, or ``posterior`` = a PosteriorConfig given here, e.g. by ``clothlab fit --posterior``),
    resumable from its checkpoint (:func:`checkpoint_path`) if interrupted.
    """

    started = time.perf_counter()
    problem = build_problem(config, measurement)
    opt = config.fit.optimizer
    x0 = problem.to_unit(problem.start)
    start_objective = problem(x0)
    optimum = multistart_minimize(problem, x0, opt, progress)
    params = problem.from_unit(optimum.x)
    solution = problem.solve(params, normalised=True)
    names = problem.component_names
    channels = problem.measurement.channels
    coefficients = {coefficient_name(n): solution.coefficients[i] for i, n in enumerate(names)}
    errors = error_percentiles(problem.y, solution.prediction, config.report.percentiles, channels)
    notes = []
    notes += problem.model.geometry_warnings(params)
    for name, lo, hi in zip(problem.free, optimum.at_lower, optimum.at_upper, strict=True):
        if lo or hi:
            notes.append(f"{name} ended at its {'lower' if lo else 'upper'} bound "
                         f"({params[name]:.6g}): not determined by these data within the bounds")
    notes += collinearity_notes(problem.design(params, normalised=True), names)
    for name, coef in coefficients.items():
        if np.all(coef == 0.0):
            notes.append(f"coefficient {name} is 0 in every channel: that component is not seen in the data")
    optimised = time.perf_counter() - started
    result = FitResult(config, problem, params, solution, coefficients, optimum, errors, start_objective,
                       optimised, notes, timings={"optimisation_s": optimised})
    result.evaluation_speed = evaluation_speed(problem, params)
    if config.fit.cv_folds >= 2:
        from clothlab.fit.crossval import cross_validate

        result.cross_validation = cross_validate(problem, params, k=config.fit.cv_folds, seed=opt.seed)
        result.timings["cross_validation_s"] = result.cross_validation["wall_time_s"]
    post = posterior or config.fit.posterior
    if post is not None:
        from clothlab.fit.posterior import run_posterior

        path = checkpoint_path(config, fits_dir)
        path.parent.mkdir(parents=True, exist_ok=True)
        result.posterior = run_posterior(problem, params, walkers=post.walkers, steps=post.steps,
                                         max_steps=post.max_steps, seed=opt.seed, checkpoint_path=path,
                                         progress=posterior_progress)
        result.warnings += [w for w in result.posterior.to_json()["warnings"] if w not in result.warnings]
        result.timings["posterior_s"] = result.posterior.wall_time
    result.wall_time = time.perf_counter() - started
    return result


def collinearity_notes(design: np.ndarray, names, threshold: float = 0.999) -> list[str]:
    """Warnings for pairs of components whose columns are nearly proportional over the measured directions:
    their linear coefficients (colours) are then not separately determined by the data."""
    from clothlab.models.components import coefficient_name

    out = []
    norms = np.linalg.norm(design, axis=0)
    for i in range(design.shape[1]):
        for j in range(i + 1, design.shape[1]):
            if norms[i] == 0.0 or norms[j] == 0.0:
                continue
            cosine = float(design[:, i] @ design[:, j] / (norms[i] * norms[j]))
            if cosine > threshold:
                out.append(f"components {names[i]} and {names[j]} are nearly proportional over these directions "
                           f"(cosine {cosine:.5f}): {coefficient_name(names[i])} and {coefficient_name(names[j])} "
                           "are not separately determined, only their combination is")
    return out


def _parameter_entries(result: FitResult) -> dict:
    problem = result.problem
    truth = (problem.measurement.provenance or {}).get("parameters", {}) if _is_simulated(problem) else {}
    free_bounds = {n: (lo, hi) for n, lo, hi in zip(problem.free, problem.lower, problem.upper, strict=True)}
    flags = {n: ("lower" if lo else "upper" if hi else None)
             for n, lo, hi in zip(problem.free, result.optimum.at_lower, result.optimum.at_upper, strict=True)}
    out = {}
    for spec in problem.model.params:
        name = spec.name
        if name not in result.params:
            continue
        lo, hi = free_bounds.get(name, spec.bounds)
        entry = {"value": result.params[name], "unit": spec.unit, "free": name in problem.free,
                 "lower": lo, "upper": hi, "start": problem.start[name], "at_bound": flags.get(name),
                 "doc": spec.doc}
        if name in truth:
            entry["truth"] = truth[name]
        out[name] = entry
    return out


def _is_simulated(problem) -> bool:
    return bool((problem.measurement.provenance or {}).get("simulated"))


def fit_summary(result: FitResult) -> dict:
    """The content of fit.json."""
    cfg = result.config
    problem = result.problem
    m = problem.measurement
    channels = list(m.channels)
    opt = result.optimum
    return {
        "name": cfg.name,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "clothlab_version": __version__,
        "versions": package_versions(),
        "config_hash": cfg.hash,
        "config": cfg.canonical(),
        "model": {"kind": cfg.model.kind, "weave": cfg.canonical()["model"]["weave"],
                  **problem.model.settings()},  # the quadrature of integrating models, else the options
        "measurement": {"path": cfg.canonical()["measurement"]["path"], "n": m.n, "channels": channels,
                        "provenance": {k: v for k, v in (m.provenance or {}).items()}},
        "parameters": _parameter_entries(result),
        "coefficients": {name: dict(zip(channels, map(float, coef), strict=True))
                         for name, coef in result.coefficients.items()},
        "coefficient_meaning": problem.model.coefficient_meaning,
        "metric": problem.metric,
        "errors": result.errors,
        "objective": {"start": result.start_objective, "final": float(opt.fun),
                      "final_normalised": result.solution.objective},
        "evaluations": int(opt.nevals),
        "wall_time_s": result.wall_time,
        "timings": {"total_s": result.wall_time, **result.timings,
                    "note": "optimisation_s: global + local stages of all starts (the fit proper); "
                            "cross_validation_s and posterior_s follow it; posterior_s sums resumed sessions"},
        "seed": cfg.fit.optimizer.seed,
        "optimizer": {"global": cfg.fit.optimizer.global_algorithm, "local": cfg.fit.optimizer.local_algorithm,
                      "max_evals": cfg.fit.optimizer.max_evals, "status": getattr(opt, "message", "")},
        "warnings": list(result.warnings),
        "cross_validation": result.cross_validation,
        "evaluation_speed": result.evaluation_speed,
        "posterior": None if result.posterior is None else {
            "file": "posterior.json", "not_determined": result.posterior.to_json()["not_determined"],
            "converged": bool(result.posterior.converged)},
    }


def prediction_table(result: FitResult) -> dict:
    """predictions.csv columns: angles, measured, model, sigma and per-component contributions."""
    problem = result.problem
    m = problem.measurement
    table = {"theta_i": m.theta_i, "phi_i": m.phi_i, "theta_o": m.theta_o, "phi_o": m.phi_o}
    design = problem.design(result.params, normalised=True)
    for c, ch in enumerate(m.channels):
        table[f"measured_{ch}"] = m.values[:, c]
        table[f"model_{ch}"] = result.solution.prediction[:, c]
        if m.sigma is not None:
            table[f"sigma_{ch}"] = m.sigma[:, c]
        for k, name in enumerate(problem.component_names):
            table[f"{name}_{ch}"] = design[:, k] * result.solution.coefficients[k, c]
    return table


def slice_table(result: FitResult, step: float = 1.0) -> dict:
    """slices.csv: the model in each exitant direction's incidence plane, signed theta_i in [-89, 89] deg
    (positive on the mirror side, phi_i = phi_o + 180)."""
    problem = result.problem
    m = problem.measurement
    exitant = np.unique(np.stack([m.theta_o, m.phi_o], axis=1), axis=0)
    signed = np.arange(-89.0, 89.0 + 0.5 * step, step)
    rows_to, rows_po, rows_s, wi, wo = [], [], [], [], []
    for to, po in exitant:
        phi_i = np.where(signed >= 0, po + 180.0, po) % 360.0
        wi.append(spherical_to_vector(np.abs(signed), phi_i))
        wo.append(np.repeat(spherical_to_vector(to, po)[None, :], len(signed), axis=0))
        rows_to.append(np.full(len(signed), to))
        rows_po.append(np.full(len(signed), po))
        rows_s.append(signed)
    wi, wo = np.concatenate(wi), np.concatenate(wo)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        comps = problem.model.components(wi, wo, result.params, normalised=True, warn=False)
    from clothlab.models.components import combine

    values = combine(comps, result.coefficients)
    table = {"theta_o": np.concatenate(rows_to), "phi_o": np.concatenate(rows_po),
             "signed_theta_i": np.concatenate(rows_s)}
    for c, ch in enumerate(m.channels):
        table[f"model_{ch}"] = values[:, c]
    return table


def trace_table(result: FitResult, every: int = 10) -> dict:
    """trace.csv columns from the optimiser's TraceRow records: every row where the best value improved, every
    ``every``-th row and the last one (enough for the trace plot, a tenth of the size)."""
    rows = result.optimum.trace
    trace = [r for i, r in enumerate(rows) if i % every == 0 or i == len(rows) - 1 or i == 0
             or r.best < rows[i - 1].best or r.stage != rows[i - 1].stage]
    return {"evaluation": [r.index for r in trace], "time_s": [r.time for r in trace],
            "value": [r.value for r in trace], "best": [r.best for r in trace], "stage": [r.stage for r in trace]}


def posterior_files(result: FitResult) -> dict:
    """posterior.json (summary, with posterior-predictive 5/50/95 % bands on the incidence-plane slices) and
    posterior_samples.csv (thinned samples in declared units, at most 4,000 rows)."""
    post = result.posterior
    if post is None:
        return {}
    summary = post.to_json()
    slices = slice_table(result)
    wi, wo = _slice_directions(slices)
    bands = post.predictive_bands(wi, wo)
    summary["predictive_slices"] = {"theta_o": slices["theta_o"], "phi_o": slices["phi_o"],
                                    "signed_theta_i": slices["signed_theta_i"], "bands": bands}
    samples = post.samples[np.linspace(0, len(post.samples) - 1, min(len(post.samples), 4000)).astype(int)]
    return {"posterior.json": summary,
            "posterior_samples.csv": {name: samples[:, j] for j, name in enumerate(post.names)}}


def _slice_directions(slices: dict):
    signed = np.asarray(slices["signed_theta_i"])
    phi_i = np.where(signed >= 0, np.asarray(slices["phi_o"]) + 180.0, slices["phi_o"]) % 360.0
    return (spherical_to_vector(np.abs(signed), phi_i),
            spherical_to_vector(np.asarray(slices["theta_o"]), np.asarray(slices["phi_o"])))


def save_fit(result: FitResult, *, force: bool = False, fits_dir=None):
    """Write fits/<name>/ for ``result``; returns the directory."""
    from clothlab.fit.store import write_fit_directory

    cfg = result.config
    dest = (fits_dir if fits_dir is not None else cfg.output.fits) / cfg.name
    from clothlab.weave.wvformat import format_wv

    config_text = cfg.path.read_text() if cfg.path is not None else None
    extra = posterior_files(result)
    weave = result.problem.model.fitted_weave(result.params)
    out = write_fit_directory(dest, fit=fit_summary(result), predictions=prediction_table(result),
                               slices=slice_table(result), trace=trace_table(result), config_text=config_text,
                               weave_text=format_wv(weave), extra=extra, force=force)
    if result.posterior is not None:  # the fit directory now holds the result: the checkpoint has served
        checkpoint_path(cfg, fits_dir).unlink(missing_ok=True)
    return out
