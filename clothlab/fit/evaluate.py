"""``clothlab eval``: a fitted or configured model at the directions of a CSV (the bridge to other tools).

Input CSV: columns theta_i, phi_i, theta_o, phi_o in degrees, clothlab convention (phi counter-clockwise from
the weft, :mod:`clothlab.frames`), and optionally u, v (texture coordinates in weave tiles: u along the weft,
v along the warp): then the model's *texture* model (:meth:`clothlab.models.base.Model.texture`; for IM the
texture model of Irawan & Marschner 2012, sec. 7.2) is evaluated at those points instead of the reflectance
model.  With u, v an optional column ``footprint`` (a box footprint's side in tiles, > 0) gives the texture
model's components averaged over the footprint centred at (u, v) instead (Chen, Wang & Wang 2024, eqs. 3-5;
:func:`clothlab.models.footprint.footprint_components`: periodic summed-area tables of the noise-free texture
by default, or stratified Monte Carlo); a model that answers box-footprint queries itself
(``footprint_queries``: ``kind: neural``, the network's footprint input, Chen, Wang & Wang 2024, sec. 4.2)
is asked directly and the footprint method options do not apply.  Other columns are ignored.
Output CSV: the four angles (and u, v, footprint), then the BRDF
(1/sr) per channel for a fit directory, and with ``components`` one column ``<component>_<channel>`` per
component and channel (the component times its fitted coefficient).  A fabric.yaml has no fitted
coefficients: its output holds the components with unit coefficients (``<component>`` columns: diffuse
= 1/pi, specular_* normalised to unit albedo).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from clothlab.errors import InputError
from clothlab.frames import spherical_to_vector
from clothlab.io.table import ANGLE_COLUMNS as ANGLES

TEXTURE = ("u", "v")
FOOTPRINT = "footprint"


def read_directions(path) -> dict[str, np.ndarray]:
    """The four angle columns of a CSV (degrees) and, when present, u and v (tiles) and footprint (tiles, > 0,
    only with u and v); file/line/column errors."""
    path = Path(path)
    if not path.is_file():
        raise InputError("directions file not found", path=path)
    with path.open(newline="") as fh:
        rows = [(i, r) for i, r in enumerate(csv.reader(fh), start=1) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputError("empty directions file", path=path)
    header = [h.strip() for h in rows[0][1]]
    missing = [c for c in ANGLES if c not in header]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)}; expected {', '.join(ANGLES)} in degrees",
                         path=path, line=rows[0][0])
    names = ANGLES + tuple(c for c in TEXTURE if c in header)
    if len(names) == len(ANGLES) + 1:
        raise InputError("texture coordinates need both columns u and v", path=path, line=rows[0][0])
    if FOOTPRINT in header:
        if len(names) == len(ANGLES):
            raise InputError("a footprint column needs the footprint centres: columns u and v (tiles)", path=path,
                             line=rows[0][0], field=FOOTPRINT)
        names += (FOOTPRINT,)
    idx = [header.index(c) for c in names]
    out = np.empty((len(rows) - 1, len(names)))
    for k, (line, row) in enumerate(rows[1:]):
        for j, (col, i) in enumerate(zip(names, idx, strict=True)):
            try:
                value = float(row[i])
            except (IndexError, ValueError):
                raise InputError(f"expected a number, found {row[i] if i < len(row) else '(nothing)'!r}",
                                 path=path, line=line, field=col) from None
            limit = 90.0 if col.startswith("theta") else None
            if not np.isfinite(value) or (limit is not None and not 0.0 <= value <= limit):
                raise InputError(f"{col} = {value!r} deg is outside [0, 90]" if limit else f"{col} is not finite",
                                 path=path, line=line, field=col)
            if col == FOOTPRINT and not value > 0.0:
                raise InputError(f"footprint = {value!r}: expected a footprint size > 0 (tiles)", path=path,
                                 line=line, field=col)
            out[k, j] = value
    return dict(zip(names, out.T, strict=True))


def _model_source(source, rule, nodes):
    source = Path(source)
    if source.is_dir():
        from clothlab.fit.store import load_fitted

        model, params, coefficients, channels = load_fitted(source)
    else:
        from clothlab.config import load_config
        from clothlab.models.registry import build_model
        from clothlab.weave.presets import resolve_weave

        cfg = load_config(source)
        q = cfg.model.quadrature
        model = build_model(cfg.model.kind, resolve_weave(cfg.model.weave, cfg.base_dir), (q.rule, q.nodes),
                            **cfg.model.options)
        params, coefficients, channels = dict(cfg.model.params), None, ()
    if rule is not None or nodes is not None:  # a model that integrates nothing ignores them
        model = model.with_quadrature(rule, nodes)
    return model, params, coefficients, channels


def evaluate_directions_file(source, directions, *, components: bool = False, rule=None, nodes=None,
                             footprint_method: str = "sat", samples: int = 256, resolution: int = 128,
                             seed: int = 0) -> str:
    """CSV text of the model of ``source`` (fit directory or fabric.yaml) at the directions of a CSV.

    With a footprint column: ``footprint_method`` ``"sat"`` (tables of ``resolution`` texels per tile side)
    or ``"mc"`` (``samples`` stratified samples per row, ``seed``)."""
    from clothlab.models.components import coefficient_name

    for name, value in (("--footprint-samples", samples), ("--footprint-resolution", resolution)):
        if int(value) < 1:
            from clothlab.errors import ConfigError

            raise ConfigError(f"expected a positive integer, got {value!r}", field=name)
    angles = read_directions(directions)
    model, params, coefficients, channels = _model_source(source, rule, nodes)
    wi = spherical_to_vector(angles["theta_i"], angles["phi_i"])
    wo = spherical_to_vector(angles["theta_o"], angles["phi_o"])
    # a segment violating sec. 5.3 raises a GeometryWarning naming it (the CLI prints it once)
    if "u" in angles:
        if not model.has_texture:
            from clothlab.models.registry import MODEL_KINDS, model_class

            with_texture = [kind for kind in MODEL_KINDS if model_class(kind).has_texture]
            raise InputError(f"u, v columns need a model with a texture model ({', '.join(with_texture)}); model "
                             f"kind {model.kind!r} has none", path=directions, field="u")
        if FOOTPRINT in angles and getattr(model, "footprint_queries", False):  # kind neural: the network's own
            comps = model.texture().components(angles["u"], angles["v"], wi, wo, params, footprint=angles[FOOTPRINT])
        elif FOOTPRINT in angles:
            from clothlab.models.footprint import footprint_components

            comps = footprint_components(model.texture(), params, wi, wo, np.column_stack([angles["u"], angles["v"]]),
                                         angles[FOOTPRINT], method=footprint_method, samples=samples, seed=seed,
                                         resolution=resolution)
        else:
            comps = model.texture().components(angles["u"], angles["v"], wi, wo, params)
    else:
        comps = model.components(wi, wo, params)
    columns = dict(angles)
    if coefficients is not None:
        total = 0.0
        parts = {}
        for name, comp in comps.items():
            coef = coefficients.get(coefficient_name(name), np.zeros(len(channels)))
            parts[name] = comp[:, None] * coef[None, :]
            total = total + parts[name]
        for c, ch in enumerate(channels):
            columns[ch] = total[:, c]
        if components:
            for name, part in parts.items():
                for c, ch in enumerate(channels):
                    columns[f"{name}_{ch}"] = part[:, c]
    else:
        columns.update(comps)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(list(columns))
    for row in zip(*columns.values(), strict=True):
        writer.writerow([repr(float(v)) for v in row])
    return buf.getvalue()
