"""Reading a saved fit directory for the report (files only: the report never evaluates a model).

Layout of ``fits/<name>/`` (written by the fit code):

- ``fit.json``        - parameters, coefficients, errors, optimiser facts (required)
- ``predictions.csv`` - theta_i, phi_i, theta_o, phi_o (deg, clothlab convention: phi counter-clockwise from
  the weft +x, warp is +y), then per channel c ``measured_<c>``, ``model_<c>`` and optionally ``sigma_<c>``,
  ``diffuse_<c>``, ``specular_warp_<c>``, ``specular_weft_<c>``; BRDF in 1/sr (required)
- ``slices.csv``      - theta_o, phi_o, signed_theta_i (deg; positive on the mirror side, phi_o + 180),
  ``model_<c>``: dense model curves in each exitant direction's incidence plane (optional)
- ``trace.csv``       - evaluation, time_s, value, best, stage (optional)
- ``posterior.json``  - posterior summary (optional; later work)

The relative error is the paper's metric (Irawan & Marschner 2012, sec. 8: median and 80th-percentile
relative error per fabric): ``(model - measured) / measured`` per sample and channel.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clothlab.config.schema import DEFAULT_PERCENTILES
from clothlab.errors import InputError
from clothlab.io.table import ANGLE_COLUMNS as DIRECTION_COLUMNS
from clothlab.io.table import MAX_VALUE, MIN_VALUE
from clothlab.models.registry import PAPER_KIND
from clothlab.untrusted import (
    MAX_NUMBER_CHARS,
    MAX_TABLE_BYTES,
    load_json_file,
    parse_number,
    plain_numeric_text,
    read_text,
)

SLICE_COLUMNS = ("theta_o", "phi_o", "signed_theta_i")
TRACE_COLUMNS = ("evaluation", "time_s", "value", "best", "stage")
#: Decimal places (degrees) to which exitant directions are rounded when rows are grouped by them.
EXITANT_DECIMALS = 3


@dataclass
class FitRecord:
    """Everything a report reads from one fit directory.  Tables are dicts column name -> (N,) array."""

    path: Path
    fit: dict
    predictions: dict[str, np.ndarray]
    channels: tuple[str, ...]
    slices: dict[str, np.ndarray] | None = None
    trace: dict[str, np.ndarray] | None = None
    posterior: dict | None = None
    posterior_samples: dict[str, np.ndarray] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.fit["name"]


def read_csv_table(path, *, required=(), text_columns=(), finite: bool = True) -> dict[str, np.ndarray]:
    """Read a CSV with a header row into {column: (N,) float64 array} (``text_columns`` stay str).

    Numbers are plain decimal notation (:func:`clothlab.untrusted.parse_number`); with ``finite=False`` empty
    cells and 'nan' / 'inf' are also read (as NaN / inf: an optimiser trace may hold them).  Raises
    :class:`InputError` naming the file, line and column for a missing file, a missing required column, a
    ragged row, an empty or non-numeric value.
    """
    path = Path(path)
    text = read_text(path, limit=MAX_TABLE_BYTES, what="file")
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise InputError(f"cannot read the file ({exc})", path=path) from None
    rows = [(number, row) for number, row in enumerate(rows, start=1) if any(cell.strip() for cell in row)]
    if not rows:
        raise InputError("the file is empty; expected a header row and data rows", path=path, line=1)
    header_line, header = rows[0]
    header = [cell.strip() for cell in header]
    if len(set(header)) != len(header):
        raise InputError(f"duplicate column names in the header {header}", path=path, line=header_line)
    missing = [name for name in required if name not in header]
    if missing:
        raise InputError(f"missing column(s) {missing}; the header has {header}", path=path, line=header_line)
    if len(rows) == 1:
        raise InputError("the file has a header but no data rows", path=path, line=header_line + 1)
    for number, row in rows[1:]:
        if len(row) != len(header):
            raise InputError(f"row has {len(row)} fields, the header has {len(header)}", path=path, line=number)
    table = {}
    for index, name in enumerate(header):
        cells = [row[index].strip() for _, row in rows[1:]]
        if name in text_columns:
            table[name] = np.asarray(cells, dtype=str)
            continue
        fast = _plain_column(cells)
        if fast is not None:
            table[name] = fast
            continue
        values = []  # the strict cell-by-cell parse, which names the first bad cell
        for (number, _), cell in zip(rows[1:], cells, strict=True):
            if not finite and (not cell or cell.lower().lstrip("+-") in ("nan", "inf", "infinity")):
                values.append(float(cell) if cell else math.nan)
                continue
            values.append(parse_number(cell, path=path, line=number, field=name))
        table[name] = np.asarray(values, dtype=np.float64)
    return table


def _plain_column(cells: list[str]) -> np.ndarray | None:
    """The column as float64 when every cell is a finite number in plain decimal notation (one vectorised
    conversion: a 380,000-row predictions.csv in well under a second instead of a minute), else None (the
    caller's strict parse then names the bad cell)."""
    if not cells or not all(cells) or not plain_numeric_text("".join(cells)) or \
            max(map(len, cells)) > MAX_NUMBER_CHARS:
        return None
    try:
        values = np.asarray(cells, dtype=np.float64)
    except ValueError:  # '1e', '+-1', '1,2' ...: characters of numbers that do not make one
        return None
    return values if np.isfinite(values).all() else None


def read_json(path) -> dict:
    """Read a JSON object; :class:`InputError` naming the file (and line) if missing or malformed."""
    path = Path(path)
    data = load_json_file(path, what="file")
    if not isinstance(data, dict):
        raise InputError(f"expected a JSON object, found {type(data).__name__}", path=path)
    return data


def channels_of(table: dict) -> tuple[str, ...]:
    """Channel names c for which both ``measured_<c>`` and ``model_<c>`` columns exist, in column order."""
    return tuple(
        name[len("measured_"):]
        for name in table
        if name.startswith("measured_") and f"model_{name[len('measured_'):]}" in table
    )


def is_usable_dir_name(name) -> bool:
    """True for a non-empty name that is one path component (no '/' or '\\', not '.' or '..')."""
    return isinstance(name, str) and bool(name.strip()) and name not in (".", "..") and not any(
        c in name for c in "/\\")


def _finite(value, path: Path, field: str) -> float:
    """``value`` if it is a finite JSON number, else InputError naming fit.json and the dotted field."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"expected a finite number, found {value!r}", path=path, field=field)
    return float(value)


ANGLE_RANGES = {"theta_i": (0.0, 90.0), "theta_o": (0.0, 90.0), "phi_i": (-360.0, 360.0),
                "phi_o": (-360.0, 360.0), "signed_theta_i": (-90.0, 90.0)}
"""Directions of predictions.csv and slices.csv (deg, clothlab's convention)."""
BRDF_PREFIXES = ("measured_", "model_", "sigma_", "diffuse_", "specular_")


def _check_columns(table: dict, path: Path) -> None:
    """Directions within :data:`ANGLE_RANGES`; BRDF columns (1/sr, :data:`BRDF_PREFIXES`) 0 or normal
    positive numbers up to 1e30 (what a measurement table may hold, :mod:`clothlab.io.table`)."""
    for name, (low, high) in ANGLE_RANGES.items():
        if name in table:
            bad = np.flatnonzero((table[name] < low) | (table[name] > high))
            if bad.size:
                raise InputError(f"{name} = {table[name][bad[0]]:g} deg in data row {bad[0] + 1} lies outside "
                                 f"[{low:g}, {high:g}] deg (clothlab's convention)", path=path, field=name)
    for name, values in table.items():
        if not name.startswith(BRDF_PREFIXES):
            continue
        size = np.abs(values)
        bad = np.flatnonzero((values < 0) | (size > MAX_VALUE) | ((size > 0) & (size < MIN_VALUE)))
        if bad.size:
            raise InputError(f"{values[bad[0]]:g} in data row {bad[0] + 1} is not a BRDF value: expected 0 or a "
                             f"normal positive number up to {MAX_VALUE:g}", path=path, field=name)


def _check_trace(trace: dict, path: Path) -> None:
    """Objective values of trace.csv: inf or NaN where the optimiser met them, else 0 or a normal magnitude up
    to 1e30 (the trace plot is logarithmic); evaluation numbers and times finite and >= 0."""
    for name in ("evaluation", "time_s"):
        bad = np.flatnonzero(~np.isfinite(trace[name]) | (trace[name] < 0))
        if bad.size:
            raise InputError(f"{trace[name][bad[0]]:g} in data row {bad[0] + 1}: expected a finite number >= 0",
                             path=path, field=name)
    for name in ("value", "best"):
        size = np.abs(trace[name])
        bad = np.flatnonzero(np.isfinite(size) & ((size > MAX_VALUE) | ((size > 0) & (size < MIN_VALUE))))
        if bad.size:
            raise InputError(f"{trace[name][bad[0]]:g} in data row {bad[0] + 1} is not an objective value: expected "
                             f"0, inf, nan or a normal number up to {MAX_VALUE:g} in magnitude", path=path, field=name)


def _check_posterior(post: dict, path: Path) -> None:
    """The shapes the report reads from posterior.json (objects, lists, numbers), each refused naming its field."""
    def kind(value, types, field, what):
        if value is not None and not isinstance(value, types):
            raise InputError(f"expected {what}, found {type(value).__name__}", path=path, field=field)

    for key in ("parameters", "convergence", "correlation", "predictive_slices"):
        kind(post.get(key), dict, key, "an object")
    kind(post.get("not_determined"), list, "not_determined", "a list of parameter names")
    for name, entry in (post.get("parameters") or {}).items():
        kind(entry, dict, f"parameters.{name}", "an object")
    kind((post.get("convergence") or {}).get("acceptance_fraction"), dict, "convergence.acceptance_fraction",
         "an object")
    corr = post.get("correlation") or {}
    kind(corr.get("names"), list, "correlation.names", "a list")
    kind(corr.get("matrix"), list, "correlation.matrix", "a list of rows")
    for i, row in enumerate(corr.get("matrix") or []):
        kind(row, list, f"correlation.matrix.{i}", "a row (list)")
    bands = (post.get("predictive_slices") or {}).get("bands")
    kind(bands, dict, "predictive_slices.bands", "an object of percentile bands")
    for key, band in (bands or {}).items():
        if not key.startswith("p"):  # e.g. draws
            continue
        kind(band, list, f"predictive_slices.bands.{key}", "a list of rows of numbers")
        try:
            values = np.asarray(band, dtype=np.float64)
        except (TypeError, ValueError):
            values = np.array([np.nan])
        if values.ndim not in (1, 2) or not np.isfinite(values).all() or any(isinstance(r, bool) for r in band):
            raise InputError("expected rows of finite numbers (one per slice point)", path=path,
                             field=f"predictive_slices.bands.{key}")


def _check_predictions(predictions: dict, channels, path: Path) -> None:
    """The measured and model columns the report shows: every value finite (read strictly already), model
    values not all zero, some measured value positive (the relative error of sec. 8 needs one), at least two
    rows."""
    n = len(next(iter(predictions.values())))
    if n < 2:
        raise InputError(f"{n} data row; a fit's predictions hold at least 2", path=path)
    _check_columns(predictions, path)
    for c in channels:
        if not np.any(predictions[f"model_{c}"]):
            raise InputError(f"every value of model_{c} is 0: not the predictions of a fit", path=path,
                             field=f"model_{c}")
        if not np.any(predictions[f"measured_{c}"] > 0):
            raise InputError(f"no value of measured_{c} is positive: no relative error can be computed (Irawan & "
                             "Marschner 2012, sec. 8), not the measurement of a fit", path=path,
                             field=f"measured_{c}")


def read_fit_json(path) -> dict:
    """fit.json as :func:`read_json` reads it; a ``NaN`` or ``Infinity`` (which clothlab never writes) is
    refused naming its dotted field, e.g. ``objective.final`` (:func:`clothlab.untrusted.load_json_text`)."""
    return read_json(path)


def _check_model_and_objective(fit: dict, path: Path) -> None:
    """A known model kind (the report describes the fit by it), a positive measured count, a finite final
    objective."""
    from clothlab.models.registry import MODEL_KINDS

    model = fit.get("model")
    kind = model.get("kind") if isinstance(model, dict) else None
    if not isinstance(kind, str) or kind not in MODEL_KINDS:
        found = "missing" if kind is None else f"{kind!r}"
        raise InputError(f"the model kind is {found}; expected one of {', '.join(MODEL_KINDS)}", path=path,
                         field="model.kind")
    n = fit["measurement"].get("n")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise InputError(f"expected a positive count of measured values, found {n!r}", path=path,
                         field="measurement.n")
    objective = fit.get("objective")
    if objective is None:  # a fit written without the optimiser's record (e.g. a generating model)
        return
    if not isinstance(objective, dict) or "final" not in objective:
        raise InputError(f"expected an object with the final objective value, found {objective!r}", path=path,
                         field="objective")
    _finite(objective["final"], path, "objective.final")
    for key, value in objective.items():
        if value is not None and key != "final":
            _finite(value, path, f"objective.{key}")


def _check_fit_json(fit: dict, path: Path) -> None:
    name = fit.get("name")
    if not is_usable_dir_name(name):
        raise InputError(f"name {name!r} is not usable as a directory name; expected a non-empty name "
                         "without '/' or '\\'", path=path, field="name")
    for key in ("parameters", "coefficients", "errors", "model", "measurement", "config", "objective",
                "optimizer", "versions"):
        if key in fit and fit[key] is not None and not isinstance(fit[key], dict):
            raise InputError(f"expected an object, found {type(fit[key]).__name__}", path=path, field=key)
    for key in ("parameters", "coefficients", "measurement"):  # a baseline may have no parameters
        if key not in fit or not isinstance(fit[key], dict) or (key != "parameters" and not fit[key]):
            raise InputError(f"the entry {key!r} is missing or empty", path=path, field=key)
    for pname, entry in fit["parameters"].items():
        if not isinstance(entry, dict) or "value" not in entry:
            raise InputError("expected an object with at least a 'value'", path=path, field=f"parameters.{pname}")
        _finite(entry["value"], path, f"parameters.{pname}.value")
    channels = (fit.get("measurement") or {}).get("channels")
    if not isinstance(channels, list) or not channels or not all(isinstance(c, str) for c in channels):
        raise InputError(f"expected a non-empty list of channel names, found {channels!r}", path=path,
                         field="measurement.channels")
    for cname, per_channel in fit["coefficients"].items():
        if not isinstance(per_channel, dict):
            raise InputError("expected an object channel -> value", path=path, field=f"coefficients.{cname}")
        for c in channels:
            _finite(per_channel.get(c), path, f"coefficients.{cname}.{c}")
    if "warnings" in fit and not isinstance(fit["warnings"], list):
        raise InputError("expected a list of strings", path=path, field="warnings")
    _check_model_and_objective(fit, path)
    for key in ("cross_validation", "uncertainty", "timings", "evaluation_speed"):  # optional sections the page
        section = fit.get(key)                                                        # reads entry by entry
        if section is not None and not isinstance(section, dict):
            raise InputError(f"expected an object, found {type(section).__name__}", path=path, field=key)
    cv = fit.get("cross_validation") or {}
    for key in ("held_out", "in_sample", "train_folds"):
        if cv.get(key) is not None and not isinstance(cv[key], dict):
            raise InputError(f"expected an object of error percentiles, found {type(cv[key]).__name__}", path=path,
                             field=f"cross_validation.{key}")


def load_fit_dir(fit_dir) -> FitRecord:
    """Load a fit directory; :class:`InputError` naming the file if a required one is missing or corrupt."""
    fit_dir = Path(fit_dir)
    if not fit_dir.is_dir():
        raise InputError("not a directory; expected a fit directory such as fits/<name>/ with fit.json and "
                         "predictions.csv", path=fit_dir)
    fit_path = fit_dir / "fit.json"
    fit = read_fit_json(fit_path)
    _check_fit_json(fit, fit_path)

    pred_path = fit_dir / "predictions.csv"
    predictions = read_csv_table(pred_path, required=DIRECTION_COLUMNS)
    found = channels_of(predictions)
    declared = (fit.get("measurement") or {}).get("channels")
    if declared:
        absent = [f"{kind}_{c}" for c in declared for kind in ("measured", "model")
                  if f"{kind}_{c}" not in predictions]
        if absent:
            raise InputError(f"fit.json declares channels {list(declared)} but column(s) {absent} are missing",
                             path=pred_path, line=1)
        channels = tuple(declared)
    elif found:
        channels = found
    else:
        raise InputError(f"no channel columns: expected pairs measured_<c>, model_<c>; the header has "
                         f"{list(predictions)}", path=pred_path, line=1)
    _check_predictions(predictions, channels, pred_path)
    n = fit["measurement"].get("n")
    rows = len(predictions["theta_i"])
    if n is not None and n != rows:
        raise InputError(f"measurement.n = {n} but {pred_path.name} holds {rows} rows", path=fit_path,
                         field="measurement.n")

    record = FitRecord(fit_dir, fit, predictions, channels)
    slices_path, trace_path, posterior_path = (fit_dir / n for n in ("slices.csv", "trace.csv", "posterior.json"))
    if slices_path.exists():
        record.slices = read_csv_table(slices_path, required=SLICE_COLUMNS)
        _check_columns(record.slices, slices_path)
    else:
        record.notes.append("slices.csv is absent: no incidence-plane slice plot.")
    if trace_path.exists():
        record.trace = read_csv_table(trace_path, required=TRACE_COLUMNS, text_columns=("stage",), finite=False)
        _check_trace(record.trace, trace_path)
    else:
        record.notes.append("trace.csv is absent: no optimiser trace plot.")
    if posterior_path.exists():
        record.posterior = read_json(posterior_path)
        _check_posterior(record.posterior, posterior_path)
        samples_path = fit_dir / "posterior_samples.csv"
        if samples_path.exists():
            record.posterior_samples = read_csv_table(samples_path)  # samples of the chain: finite numbers
    return record


def luminance(table: dict, prefix: str, channels) -> np.ndarray:
    """Channel mean of ``<prefix>_<c>`` columns: the single value shown for RGB data."""
    return np.mean([table[f"{prefix}_{c}"] for c in channels], axis=0)


def channel_values(table: dict, prefix: str, channel: str, channels) -> np.ndarray:
    """``<prefix>_<channel>``, or the channel mean when ``channel == 'luminance'``."""
    if channel == "luminance":
        return luminance(table, prefix, channels)
    key = f"{prefix}_{channel}"
    if key not in table:
        raise InputError(f"no column {key!r}; channels are {list(channels)} or 'luminance'", field="channel")
    return np.asarray(table[key], dtype=np.float64)


def signed_relative_error(measured, model) -> np.ndarray:
    """(model - measured) / measured; NaN where measured <= 0 or either is not finite (sec. 8 metric)."""
    measured = np.asarray(measured, dtype=np.float64)
    model = np.asarray(model, dtype=np.float64)
    ok = np.isfinite(measured) & np.isfinite(model) & (measured > 0)
    out = np.full(np.broadcast(measured, model).shape, np.nan)
    np.divide(model - measured, measured, out=out, where=ok)
    return out


def percentile_key(q: float) -> str:
    """'p50' for 50, 'p97.5' for 97.5: the key under which a percentile is stored."""
    return f"p{q:g}"


def error_percentiles(table: dict, channels, percentiles=DEFAULT_PERCENTILES) -> dict:
    """Percentiles and mean of |relative error| (fractions) of a predictions table, fit.json's ``errors``.

    ``overall`` pools every (sample, channel) value, ``per_channel`` has one entry per channel; samples
    with measured <= 0 or non-finite values are skipped (``n`` counts the rest).  Computed by
    :func:`clothlab.fit.metrics.error_percentiles` (Irawan & Marschner 2012, sec. 8).
    """
    from clothlab.fit.metrics import error_percentiles as percentiles_of

    measured = np.stack([table[f"measured_{c}"] for c in channels], axis=1)
    model = np.stack([table[f"model_{c}"] for c in channels], axis=1)
    return percentiles_of(measured, model, percentiles, list(channels))


def exitant_groups(table: dict) -> list[tuple[float, float, np.ndarray]]:
    """[(theta_o, phi_o, row indices)] for each distinct exitant direction, sorted by theta_o then phi_o."""
    theta = np.round(np.asarray(table["theta_o"], dtype=np.float64), EXITANT_DECIMALS)
    phi = np.round(np.asarray(table["phi_o"], dtype=np.float64), EXITANT_DECIMALS)
    keys, inverse = np.unique(np.stack([theta, phi], axis=1), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    rows = np.split(np.argsort(inverse, kind="stable"), np.cumsum(np.bincount(inverse, minlength=len(keys)))[:-1])
    return [(float(t), float(p), r) for (t, p), r in zip(keys, rows, strict=True)]  # rows ascending in each


#: Published fit quality on the real measurements: (median, 80th percentile) relative error in percent,
#: Irawan & Marschner 2012, sec. 8.  Keys are clothlab's fabric / preset names.
PAPER_RELATIVE_ERRORS = {
    "cotton-twill": (21.0, 36.0),
    "cotton-denim": (18.0, 34.0),
    "wool-gabardine": (12.0, 27.0),
    "polyester-lining": (19.0, 39.0),
    "silk-charmeuse": (40.0, 69.0),
    "silk-shantung": (28.0, 54.0),
}
PAPER_SOURCE = "Irawan & Marschner 2012, sec. 8 (their fits to real measurements)"


def fabric_name(fit: dict) -> str:
    """The fabric a fit is about: the weave preset, else config 'name', else the fit name (so an IM and a
    Kang fit of the same preset name the same fabric)."""
    weave = (fit.get("model") or {}).get("weave")
    if isinstance(weave, str) and weave.startswith("preset:"):
        return weave[len("preset:"):]
    config_name = (fit.get("config") or {}).get("name")
    if isinstance(config_name, str) and config_name:
        return config_name
    return str(fit.get("name", ""))


def optimisation_seconds(fit: dict) -> float | None:
    """Wall time of the fit proper (global + local optimisation, all starts), without cross-validation and
    posterior sampling, from fit.json 'timings'; 'wall_time_s' for a fit that ran neither."""
    timings = fit.get("timings") or {}
    if "optimisation_s" in timings:
        return timings["optimisation_s"]
    return fit.get("wall_time_s")


def model_setting(fit: dict) -> str:
    """The evaluation setting of a fit's model in a few words, as its model class describes the settings
    recorded in fit.json (:meth:`clothlab.models.base.Model.describe_settings`: e.g. the quadrature of an
    integrating model, the options of others)."""
    from clothlab.errors import ConfigError
    from clothlab.models.base import Model
    from clothlab.models.registry import DEFAULT_KIND, model_class

    model = dict(fit.get("model") or {})
    if model.get("options") is None:  # fits saved before the model recorded its options
        model["options"] = ((fit.get("config") or {}).get("model") or {}).get("options") or {}
    try:
        cls = model_class(model.get("kind", DEFAULT_KIND))
    except ConfigError:  # a kind this version does not know: its options as recorded
        cls = Model
    return cls.describe_settings(model)


def free_parameters(fit: dict) -> dict[str, dict]:
    """The fitted free parameters of a fit.json: {name: {"value", "unit"}} in the model's declared order."""
    return {name: {"value": entry.get("value"), "unit": entry.get("unit")}
            for name, entry in (fit.get("parameters") or {}).items() if entry.get("free", True)}


#: The model whose fits the published figures of :data:`PAPER_RELATIVE_ERRORS` are (Irawan & Marschner 2012,
#: sec. 8): a row of another model does not show them as its reference.
PAPER_MODEL_KIND = PAPER_KIND
#: Provenance key naming the paper fabric a measurement is (or simulates), e.g. ``paper_fabric: cotton-twill``.
PAPER_FABRIC_KEY = "paper_fabric"


def _paper_key(value) -> str | None:
    """The :data:`PAPER_RELATIVE_ERRORS` key a provenance value names exactly (case, '_' and spaces ignored)."""
    if not isinstance(value, str):
        return None
    normal = "-".join(value.lower().replace("_", " ").replace("-", " ").split())
    return normal if normal in PAPER_RELATIVE_ERRORS else None


def paper_fabric(fit: dict) -> str | None:
    """The key of :data:`PAPER_RELATIVE_ERRORS` when the measured data are the paper's fabric, else None.

    Read from the measurement's provenance (fit.json ``measurement.provenance``, the table header's
    ``provenance``): ``paper_fabric: <name>`` says so explicitly (``paper_fabric: none`` / ``false`` says
    not).  Without the key, clothlab's own simulated example tables (``generator: clothlab simulate ...``
    with ``fabric`` and ``variant`` written by ``clothlab simulate --paper-examples``) count as the paper
    fabric they name.  The fit's name, config name or weave preset never decide it: starting from a preset
    does not make a measurement the paper's fabric.
    """
    provenance = (fit.get("measurement") or {}).get("provenance")
    if not isinstance(provenance, dict):
        return None
    if PAPER_FABRIC_KEY in provenance:
        return _paper_key(provenance[PAPER_FABRIC_KEY])
    generator = provenance.get("generator")
    if (isinstance(generator, str) and generator.startswith("clothlab simulate")
            and provenance.get("variant") in ("clean", "noisy")):
        return _paper_key(provenance.get("fabric"))
    return None


def paper_figures_apply(fit: dict) -> bool:
    """True when the paper's published figures are this fit's reference: the data are the paper's fabric
    (:func:`paper_fabric`) and the model is the one the paper fitted (:data:`PAPER_MODEL_KIND`)."""
    return paper_fabric(fit) is not None and (fit.get("model") or {}).get("kind", PAPER_MODEL_KIND) == PAPER_MODEL_KIND


def shown_channel(channels) -> tuple[str, str]:
    """(key for :func:`channel_values`, label) of the single value the maps show: the channel itself, by its
    own name, for one channel; the channel mean ('luminance' key) for several, labelled with their names."""
    channels = tuple(channels)
    if len(channels) == 1:
        return channels[0], channels[0]
    return "luminance", f"mean of {', '.join(channels)}"


def selection_rows(fit: dict) -> list[dict]:
    """The model-selection result of a fit.json as a list of dicts (empty when there is none).

    Accepted shapes of ``fit["selection"]``: a list of dicts, or a dict whose ``candidates`` (or
    ``ranking`` / ``runners_up`` / ``rows``) entry is one.  Each dict describes one candidate (the columns of
    :data:`clothlab.fit.select.TABLE_COLUMNS`).
    """
    selection = fit.get("selection")
    if isinstance(selection, dict):
        for key in ("candidates", "ranking", "runners_up", "rows"):
            if isinstance(selection.get(key), list):
                selection = selection[key]
                break
    if not isinstance(selection, list):
        return []
    return [row for row in selection if isinstance(row, dict)]


def is_simulated(provenance) -> bool:
    """True when measurement provenance marks the data as simulated.

    Accepted forms: ``simulated: true``, or a 'kind' / 'type' / 'source' / 'origin' / 'instrument' value
    containing 'simulat' (e.g. 'simulated', 'clothlab simulate').
    """
    if not isinstance(provenance, dict):
        return False
    flag = provenance.get("simulated")
    if isinstance(flag, bool):
        return flag
    if isinstance(flag, str) and flag.strip().lower() in ("true", "yes", "1"):
        return True
    return any(isinstance(provenance.get(key), str) and "simulat" in provenance[key].lower()
               for key in ("kind", "type", "source", "origin", "instrument"))
