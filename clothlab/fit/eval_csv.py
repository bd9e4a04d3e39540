"""``clothlab eval``: a fitted or configured model at the directions of a CSV (the bridge to other tools).

Input CSV: columns theta_i, phi_i, theta_o, phi_o in degrees, clothlab convention (phi counter-clockwise from
the weft, :mod:`clothlab.frames`), and optionally u, v (texture coordinates in weave tiles: u along the weft,
v along the warp): then the model's *texture* model (:meth:`clothlab.models.base.Model.texture`; for IM the
texture model of Irawan & Marschner 2012, sec. 7.2) is evaluated at those points instead of the reflectance
model.  With u, v an optional column ``footprint`` (a box footprint's side in tiles, > 0) gives the texture
model's components averaged over the footprint centred at (u, v) instead (Chen, Wang & Wang 2024, eqs. 3-5;
:func:`clothlab.footprint.footprint_components`: periodic summed-area tables of the noise-free texture
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
MAX_AZIMUTH = 360.0
"""Largest |phi_i|, |phi_o| (deg) read: one turn, as the measurement tables (:mod:`clothlab.io.table`)."""
MAX_TEXTURE_COORDINATE = 1e6
"""Largest |u|, |v| (tiles) read: float64 still resolves 1e-10 tile there."""
MAX_FOOTPRINT = 1e6
"""Largest footprint side (tiles) read; any footprint of a whole number of tiles averages the whole tile
(beyond ~1e11 tiles the summed-area differences lose every digit and a footprint of 1e30 gave 0)."""
MAX_FOOTPRINT_SAMPLES = 1_000_000
"""Most ``--footprint-samples`` (Monte Carlo samples per row; the paper's ground truth uses 2,048), as the CLI."""
MAX_FOOTPRINT_RESOLUTION = 8192
"""Most ``--footprint-resolution`` (summed-area table texels per tile side; default 128), as the CLI."""


def read_directions(path) -> dict[str, np.ndarray]:
    """The four angle columns of a CSV (degrees) and, when present, u and v (tiles) and footprint (tiles, > 0,
    only with u and v); every number through :func:`clothlab.untrusted.parse_number` (plain decimal notation),
    theta in [0, 90], |phi| <= :data:`MAX_AZIMUTH`, |u|, |v| <= :data:`MAX_TEXTURE_COORDINATE`, footprint in
    (0, :data:`MAX_FOOTPRINT`]; errors name the file, line and column."""
    from clothlab.untrusted import MAX_TABLE_BYTES, parse_number, read_text

    path = Path(path)
    text = read_text(path, limit=MAX_TABLE_BYTES, what="directions file")
    reader = csv.reader(io.StringIO(text, newline=""))
    rows = []
    try:
        for r in reader:  # line_num: the physical line a record ends on (a quoted field may span lines)
            if r and not r[0].lstrip().startswith("#"):
                rows.append((reader.line_num, r))
    except csv.Error as exc:
        raise InputError(f"not a CSV file: {exc}", path=path, line=reader.line_num) from None
    if not rows:
        raise InputError("empty directions file", path=path)
    if len(rows) == 1:
        raise InputError("no directions after the header; expected rows theta_i, phi_i, theta_o, phi_o (deg)",
                         path=path, line=rows[0][0])
    header = [h.strip() for h in rows[0][1]]
    missing = [c for c in ANGLES if c not in header]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)}; expected {', '.join(ANGLES)} in degrees",
                         path=path, line=rows[0][0])
    twice = sorted({c for c in header if c and header.count(c) > 1} & set(ANGLES + TEXTURE + (FOOTPRINT,)))
    if twice:
        raise InputError(f"column {twice[0]!r} appears twice in the header", path=path, line=rows[0][0],
                         field=twice[0])
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
            if i >= len(row):
                raise InputError(f"row has {len(row)} fields; column {col!r} is field {i + 1}", path=path,
                                 line=line, field=col)
            value = parse_number(row[i], path=path, line=line, field=col)
            if col.startswith("theta") and not 0.0 <= value <= 90.0:
                raise InputError(f"{col} = {value!r} deg is outside [0, 90]", path=path, line=line, field=col)
            if col.startswith("phi") and not abs(value) <= MAX_AZIMUTH:
                raise InputError(f"{col} = {value!r} deg is outside [-{MAX_AZIMUTH:g}, {MAX_AZIMUTH:g}]", path=path,
                                 line=line, field=col)
            if col in TEXTURE and not abs(value) <= MAX_TEXTURE_COORDINATE:
                raise InputError(f"{col} = {value!r} tiles is outside [-{MAX_TEXTURE_COORDINATE:g}, "
                                 f"{MAX_TEXTURE_COORDINATE:g}]", path=path, line=line, field=col)
            if col == FOOTPRINT and not 0.0 < value <= MAX_FOOTPRINT:
                raise InputError(f"footprint = {value!r}: expected a footprint size > 0 and <= {MAX_FOOTPRINT:g} "
                                 "(tiles)", path=path, line=line, field=col)
            out[k, j] = value
    return dict(zip(names, out.T, strict=True))


def _model_source(source, rule, nodes):
    source = Path(source)
    if source.is_dir():
        from clothlab.fit.store import load_fitted

        model, params, coefficients, channels = load_fitted(source)
    else:
        from clothlab.config import load_config
        from clothlab.config.build import model_from_config

        cfg = load_config(source)
        model = model_from_config(cfg)
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

    for name, value, most in (("--footprint-samples", samples, MAX_FOOTPRINT_SAMPLES),
                              ("--footprint-resolution", resolution, MAX_FOOTPRINT_RESOLUTION)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 1 <= value <= most:
            from clothlab.errors import ConfigError

            raise ConfigError(f"expected an integer from 1 to {most}, got {value!r}", field=name)
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
        if FOOTPRINT in angles and model.footprint_queries:  # kind neural: the network's own
            comps = model.texture().components(angles["u"], angles["v"], wi, wo, params, footprint=angles[FOOTPRINT])
        elif FOOTPRINT in angles:
            from clothlab.footprint import footprint_components

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
