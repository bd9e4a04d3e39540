"""fits/<name>/: the saved result of a fit, written atomically (an existing one is kept unless forced).

:func:`save_fit` writes a :class:`clothlab.fit.runner.FitResult`; :func:`load_fit` reads one back as a
:class:`SavedFit` with the same :meth:`~SavedFit.fit_report`; :func:`load_fitted` gives the model, parameters
and coefficients ready to evaluate.  Layout (read by :mod:`clothlab.report` too):

- ``fit.json``        parameters (value, unit, free, bounds, start, at_bound, truth), Gauss-Newton standard
                      errors and correlations, coefficients, error percentiles (in-sample and cross-validated),
                      objective, evaluations, time by stage, seed, versions, config + hash, notes
- ``predictions.csv`` theta_i, phi_i, theta_o, phi_o [deg], measured_<c>, model_<c>, sigma_<c>,
                      diffuse_<c>, specular_warp_<c>, specular_weft_<c> (1/sr)
- ``slices.csv``      dense model curves in each exitant direction's incidence plane
- ``trace.csv``       evaluation, time_s, value, best, stage
- ``fabric.yaml``     the configuration as given
- ``weave.wv``        the weave with the fitted parameters (the fit directory is self-contained for eval)
- ``posterior.json``, ``posterior_samples.csv``  when a posterior was sampled (:mod:`clothlab.fit.posterior`)

CSV numbers carry 10 significant digits (figures, not a data archive: the measurement file is the data).
"""

from __future__ import annotations

import csv
import io
import json
import math
import platform
import shutil
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

import numpy as np

from clothlab import __version__
from clothlab.atomic import atomic_directory
from clothlab.config.build import model_from_fit
from clothlab.errors import InputError, ResultError
from clothlab.fit.fitreport import Reportable
from clothlab.frames import spherical_to_vector
from clothlab.untrusted import load_json_file
from clothlab.weave.wvformat import format_wv

MAX_SLICE_DIRECTIONS = 24
"""Most exitant directions slices.csv holds (the report's slice figure shows a grid of panels; a table with
thousands of exitant directions gets the ones with the most measured rows)."""
VERSIONED = ("numpy", "scipy", "numba", "nlopt", "matplotlib", "PyYAML", "emcee")


def package_versions() -> dict:
    """Versions of Python, clothlab and the libraries a fit's numbers depend on (None if not installed)."""
    out = {"python": platform.python_version(), "clothlab": __version__}
    for name in VERSIONED:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def checkpoint_path(config, fits_dir=None) -> Path:
    """Where an interrupted posterior run keeps its chain: a hidden file next to fits/<name>/ (the fit
    directory itself is only written, atomically, when everything is done)."""
    root = fits_dir if fits_dir is not None else config.output.fits
    return root / f".{config.name}.posterior-checkpoint.npz"


def _csv_text(header, columns) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for row in zip(*columns, strict=True):
        writer.writerow([f"{float(v):.10g}" if isinstance(v, float | np.floating) else v for v in row])
    return buf.getvalue()


def _json_safe(value):
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Path):
        return str(value)
    return value


def write_fit_directory(dest, *, fit: dict, predictions: dict, slices: dict, trace: dict, config_text: str | None,
                        weave_text: str | None = None, extra: dict | None = None, copies: dict | None = None,
                        force: bool = False) -> Path:
    """Write the files of a fit result into ``dest`` atomically; refuses an existing dest without ``force``.
    ``copies``: {name in dest: source file} copied byte for byte (a model's input files, e.g. its weights)."""
    dest = Path(dest)
    with atomic_directory(dest, force=force) as tmp:
        for name, source in (copies or {}).items():
            (tmp / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, tmp / name)
        (tmp / "fit.json").write_text(json.dumps(_json_safe(fit), indent=2, allow_nan=False) + "\n")
        for name, table in (("predictions.csv", predictions), ("slices.csv", slices), ("trace.csv", trace)):
            (tmp / name).write_text(_csv_text(list(table), [np.asarray(v).tolist() for v in table.values()]))
        if config_text is not None:
            (tmp / "fabric.yaml").write_text(config_text)
        if weave_text is not None:
            (tmp / "weave.wv").write_text(weave_text)
        for name, content in (extra or {}).items():  # *.json: a JSON document; *.csv: a column table
            if name.endswith(".json"):
                (tmp / name).write_text(json.dumps(_json_safe(content), indent=1, allow_nan=False) + "\n")
            else:
                (tmp / name).write_text(_csv_text(list(content), [np.asarray(v).tolist() for v in content.values()]))
    return dest


def read_fit_json(fit_dir) -> dict:
    """fit.json of a fit directory, with a clear error when it is missing or not valid JSON."""
    path = Path(fit_dir) / "fit.json"
    if not path.is_file():
        raise InputError("no fit.json here: not a fit directory (run `clothlab fit fabric.yaml` first)", path=path)
    data = load_json_file(path, what="fit.json")
    if not isinstance(data, dict):
        raise InputError(f"expected a JSON object, found {type(data).__name__}", path=path)
    return data


def _number(value, field: str, fit_dir: Path) -> float:
    """A finite JSON number from fit.json, or InputError naming the file and the dotted field."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"expected a finite number, found {value!r}", path=fit_dir / "fit.json", field=field)
    return float(value)


def load_fitted(fit_dir):
    """(model, params, coefficients {name: (C,)}, channels) of a saved fit, ready to evaluate."""
    fit_dir = Path(fit_dir)
    fit = read_fit_json(fit_dir)
    model = model_from_fit(fit, fit_dir)  # kind, weave.wv, quadrature and options as fitted
    try:
        params = {k: _number(v["value"], f"parameters.{k}.value", fit_dir) for k, v in fit["parameters"].items()}
        channels = tuple(fit["measurement"]["channels"])
        coefficients = {k: np.array([_number(v[c], f"coefficients.{k}.{c}", fit_dir) for c in channels])
                        for k, v in fit["coefficients"].items()}
        if not coefficients or not channels:
            raise KeyError("coefficients and measurement.channels must not be empty")
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"fit.json lacks or mangles a required entry ({exc})", path=fit_dir / "fit.json") from None
    return model, params, coefficients, channels


# ---------------------------------------------------------------------------------------------- writing
def _parameter_entries(result) -> dict:
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


def fit_summary(result) -> dict:
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
                  **_settings_with_copies(problem.model)},  # the quadrature of integrating models, else the options
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
                            "standard_errors_s (Gauss-Newton), cross_validation_s and posterior_s follow it; "
                            "posterior_s sums resumed sessions"},
        "seed": cfg.fit.optimizer.seed,
        "optimizer": {"global": cfg.fit.optimizer.global_algorithm, "local": cfg.fit.optimizer.local_algorithm,
                      "max_evals": cfg.fit.optimizer.max_evals, "status": getattr(opt, "message", "")},
        "warnings": list(result.warnings),
        "uncertainty": result.uncertainty,
        **({"refinement": result.refinement} if getattr(result, "refinement", None) else {}),
        "cross_validation": result.cross_validation,
        "evaluation_speed": result.evaluation_speed,
        "posterior": None if result.posterior is None else {
            "file": "posterior.json", "not_determined": result.posterior.to_json()["not_determined"],
            "converged": bool(result.posterior.converged)},
    }


def prediction_table(result) -> dict:
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


def slice_table(result, step: float = 1.0) -> dict:
    """slices.csv: the model in each exitant direction's incidence plane, signed theta_i in [-89, 89] deg
    (positive on the mirror side, phi_i = phi_o + 180)."""
    problem = result.problem
    m = problem.measurement
    exitant = slice_directions(m.theta_o, m.phi_o)
    signed = np.arange(-89.0, 89.0 + 0.5 * step, step)
    theta_o = np.repeat(exitant[:, 0], len(signed))
    phi_o = np.repeat(exitant[:, 1], len(signed))
    signed_all = np.tile(signed, len(exitant))
    phi_i = np.where(signed_all >= 0, phi_o + 180.0, phi_o) % 360.0
    wi = spherical_to_vector(np.abs(signed_all), phi_i)
    wo = spherical_to_vector(theta_o, phi_o)
    # the fit's own design (the orientation average of an isotropic measurement included), its coefficients
    values = problem.designs([result.params], normalised=True, wi=wi, wo=wo)[0] @ result.solution.coefficients
    table = {"theta_o": theta_o, "phi_o": phi_o, "signed_theta_i": signed_all}
    for c, ch in enumerate(m.channels):
        table[f"model_{ch}"] = values[:, c]
    return table


def slice_directions(theta_o, phi_o, limit: int = MAX_SLICE_DIRECTIONS) -> np.ndarray:
    """(K, 2) distinct exitant directions (theta_o, phi_o) for slices.csv, sorted; at most ``limit`` of them
    (those with the most measured rows, ties to the lower angles)."""
    unique, counts = np.unique(np.stack([np.asarray(theta_o, float), np.asarray(phi_o, float)], axis=1),
                               axis=0, return_counts=True)
    if len(unique) > limit:
        keep = np.sort(np.argsort(-counts, kind="stable")[:limit])
        unique = unique[keep]
    return unique


def check_finite_result(result, predictions: dict) -> None:
    """ResultError unless the parameters, coefficients, predictions and error percentiles are all finite:
    a fit never saves a non-finite number where a number is expected."""
    def bad(where: str, value) -> None:
        raise ResultError(f"the fit produced a non-finite {where} ({value!r}); nothing was saved. Check the "
                          "measurement for extreme values", path=getattr(result.config, "path", None))

    for name, value in result.params.items():
        if not math.isfinite(float(value)):
            bad(f"parameter {name}", value)
    for name, coef in result.coefficients.items():
        coef = np.asarray(coef, dtype=np.float64)
        if not np.isfinite(coef).all():
            bad(f"coefficient {name}", coef.tolist())
    for name, column in predictions.items():
        column = np.asarray(column)
        if column.dtype.kind == "f" and not np.isfinite(column).all():
            bad(f"value in predictions column {name} (row {int(np.flatnonzero(~np.isfinite(column))[0])})",
                float(column[~np.isfinite(column)][0]))

    def walk(where: str, value) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{where}.{k}", v)
        elif isinstance(value, float | np.floating) and not math.isfinite(float(value)):
            bad(f"error percentile {where}", float(value))

    walk("errors", result.errors)


def trace_table(result, every: int = 10) -> dict:
    """trace.csv columns from the optimiser's TraceRow records: every row where the best value improved, every
    ``every``-th row and the last one (enough for the trace plot, a tenth of the size)."""
    rows = result.optimum.trace
    trace = [r for i, r in enumerate(rows) if i % every == 0 or i == len(rows) - 1 or i == 0
             or r.best < rows[i - 1].best or r.stage != rows[i - 1].stage]
    return {"evaluation": [r.index for r in trace], "time_s": [r.time for r in trace],
            "value": [r.value for r in trace], "best": [r.best for r in trace], "stage": [r.stage for r in trace]}


def posterior_files(result) -> dict:
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


def _copy_name(option: str, path: Path) -> str:
    """Where a fit directory keeps the copy of a file option's file: ``<option>/<file name>``."""
    return f"{option}/{path.name}"


def _settings_with_copies(model) -> dict:
    """``model.settings()`` with each file option naming its copy in the fit directory (:func:`_copy_name`),
    so fit.json holds no machine-specific path and the directory evaluates anywhere."""
    settings = model.settings()
    files = model.option_files()
    if files:
        settings = {**settings, "options": {**settings.get("options", {}),
                                            **{name: _copy_name(name, paths[0]) for name, paths in files.items()}}}
    return settings


def save_fit(result, *, force: bool = False, fits_dir=None) -> Path:
    """Write fits/<name>/ for ``result`` (a FitResult) under ``fits_dir`` (default: the configuration's
    ``output.fits``); returns the directory.  Removes the posterior checkpoint the run kept."""
    cfg = result.config
    dest = (fits_dir if fits_dir is not None else cfg.output.fits) / cfg.name
    config_text = cfg.path.read_text() if cfg.path is not None else None
    predictions = prediction_table(result)
    check_finite_result(result, predictions)
    extra = posterior_files(result)
    weave = result.problem.model.fitted_weave(result.params)
    out = write_fit_directory(dest, fit=fit_summary(result), predictions=predictions,
                               slices=slice_table(result), trace=trace_table(result), config_text=config_text,
                               weave_text=format_wv(weave), extra=extra, force=force,
                               copies={_copy_name(name, p): p
                                       for name, paths in result.problem.model.option_files().items() for p in paths})
    if result.posterior is not None:  # the fit directory now holds the result: the checkpoint has served
        checkpoint_path(cfg, fits_dir).unlink(missing_ok=True)
    return out


# ---------------------------------------------------------------------------------------------- reading back
class SavedFit(Reportable):
    """A fit read back from its directory: ``fit`` (fit.json), ``posterior`` (posterior.json or None) and
    ``path``; reports like the FitResult that was saved (:meth:`fit_report`, ``_repr_html_``)."""

    def __init__(self, path: Path, fit: dict, posterior: dict | None = None):
        self.path, self.fit, self.posterior = Path(path), fit, posterior

    @property
    def name(self) -> str:
        return self.fit["name"]

    @property
    def params(self) -> dict:
        """Every parameter's fitted (or fixed) value, in its declared unit."""
        return {name: entry["value"] for name, entry in self.fit["parameters"].items()}

    @property
    def coefficients(self) -> dict:
        """Coefficient name -> (C,) array in the order of the measurement's channels."""
        channels = self.fit["measurement"]["channels"]
        return {name: np.array([v[c] for c in channels], dtype=np.float64)
                for name, v in self.fit["coefficients"].items()}

    def _report_sources(self) -> tuple[dict, dict | None]:
        return self.fit, self.posterior


def load_fit(fit_dir) -> SavedFit:
    """The fit saved in ``fit_dir`` (fit.json, and posterior.json when a posterior was sampled)."""
    fit_dir = Path(fit_dir)
    fit = read_fit_json(fit_dir)
    for key in ("name", "parameters", "coefficients", "measurement"):
        if key not in fit:
            raise InputError(f"fit.json lacks the entry {key!r}", path=fit_dir / "fit.json")
    posterior = None
    path = fit_dir / "posterior.json"
    if path.is_file():
        posterior = load_json_file(path, what="posterior.json")
    return SavedFit(fit_dir, fit, posterior)
