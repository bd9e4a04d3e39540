"""fits/<name>/: the saved result of a fit, written atomically (DESIGN.md principle 6).

Layout (read by :mod:`clothlab.report` and :func:`load_fit`):

- ``fit.json``        parameters (value, unit, free, bounds, start, at_bound, truth), coefficients,
                      error percentiles, objective, evaluations, wall time, seed, versions, config + hash
CSV numbers carry 10 significant digits (figures, not a data archive: the measurement file is the data).

- ``predictions.csv`` theta_i, phi_i, theta_o, phi_o [deg], measured_<c>, model_<c>, sigma_<c>,
                      diffuse_<c>, specular_warp_<c>, specular_weft_<c> (1/sr)
- ``slices.csv``      dense model curves in each exitant direction's incidence plane
- ``trace.csv``       evaluation, time_s, value, best, stage
- ``fabric.yaml``     the configuration as given
- ``weave.wv``        the weave with the fitted parameters (the fit directory is self-contained for eval)
- ``posterior.json``, ``posterior_samples.csv``  when a posterior was sampled (:mod:`clothlab.fit.posterior`)
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_directory
from clothlab.errors import InputError


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
                        weave_text: str | None = None, extra: dict | None = None, force: bool = False) -> Path:
    """Write the files of a fit result into ``dest`` atomically; refuses an existing dest without ``force``."""
    dest = Path(dest)
    with atomic_directory(dest, force=force) as tmp:
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
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"fit.json is not valid JSON: {exc.msg}", path=path, line=exc.lineno) from None


def load_fitted(fit_dir):
    """(model, params, coefficients {name: (C,)}, channels) of a saved fit, ready to evaluate."""
    from clothlab.models.registry import build_model
    from clothlab.weave.wvformat import parse_wv

    fit_dir = Path(fit_dir)
    fit = read_fit_json(fit_dir)
    weave_path = fit_dir / "weave.wv"
    if not weave_path.is_file():
        raise InputError("weave.wv is missing from the fit directory", path=weave_path)
    try:
        kind = fit["model"]["kind"]
        q = fit["model"].get("quadrature") or {}
        params = {k: float(v["value"]) for k, v in fit["parameters"].items()}
        channels = tuple(fit["measurement"]["channels"])
        coefficients = {k: np.array([float(v[c]) for c in channels]) for k, v in fit["coefficients"].items()}
        # the model's constructor options as fitted (e.g. kang: alternating, tile_nodes)
        options = dict(fit["model"].get("options") or (fit.get("config") or {}).get("model", {}).get("options") or {})
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"fit.json lacks or mangles a required entry ({exc})", path=fit_dir / "fit.json") from None
    model = build_model(kind, parse_wv(weave_path), (q.get("rule", "trapezoid"), int(q.get("nodes", 11))), **options)
    return model, params, coefficients, channels
