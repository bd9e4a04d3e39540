"""Simulated BTF stacks of a texture model (Irawan & Marschner 2012, sec. 4.2, Fig. 4, sec. 7.2).

The source's model must have a texture model (:meth:`clothlab.models.base.Model.texture`) and declare the
parameters the layout acts on (:data:`LAYOUT_PARAMETERS`: the Irawan-Marschner model does).

Directions (:func:`fig4_directions`): the light on four half circles of illumination *elevation* 30, 45, 60
and 75 deg (the arrangement of the paper's Fig. 4), i.e. theta_i = 90 deg - elevation, at azimuths evenly
spread over [0, 180] deg; the view near the normal (one or a few views).

Texture layout (the parameters the BRDF cannot see, :class:`TextureLayout`):

- ``offset`` (u0, v0) in weave tiles: the texture coordinate of the image's lower-left corner
  (:mod:`clothlab.btf.write` pixel mapping);
- ``rotation`` rho in degrees: the fabric is turned counter-clockwise by rho in the image (seen from above)
  about the image centre.  A pixel at image texture coordinate p (tiles, as write.py, offset included) shows
  the fabric point f = c + R(-rho) (p - c) (rotation in *cells*, which are square; c = image centre), and an
  image-frame direction d is d_fab = R(-rho) d in the fabric frame;
- ``ratio``: scale s of the segment length/width ratio: l' = l sqrt(s), w' = w / sqrt(s) for both yarn types
  (segment area kept; s = 1 keeps the weave's w, l);
- ``hwidth``: eq. 12 band width (None: the weave's / fit's value);
- ``noise`` and ``seed``: the texture model's noise (IM: sec. 7.2.1) and its realisation.

Pixels are square: the image height covers ``tile_repeats * W_cells / H_cells * height / width`` tiles.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError, InputError
from clothlab.progress import get_logger

ELEVATIONS = (30.0, 45.0, 60.0, 75.0)  # deg, paper Fig. 4


@dataclass(frozen=True)
class TextureLayout:
    """How the weave lies in the images and the texture-only parameters (see the module docstring)."""

    offset: tuple[float, float] = (0.0, 0.0)  # tiles
    rotation: float = 0.0  # deg, counter-clockwise
    ratio: float = 1.0  # scale of l / w
    hwidth: float | None = None  # eq. 12; None = the source's
    noise: bool = True
    seed: int = 0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["offset"] = [float(x) for x in self.offset]
        return d


#: the parameters a :class:`TextureLayout` acts on (``ratio`` scales w and l, ``hwidth`` replaces eq. 12's)
LAYOUT_PARAMETERS = ("warp.w", "warp.l", "weft.w", "weft.l", "hwidth")


@dataclass
class TextureSource:
    """A texture model's origin: the model (one with a texture model, :meth:`clothlab.models.base.Model.texture`),
    parameters (declared units), coefficients {name: (C,)} or None, channel names or None, and a description
    for provenance."""

    model: object
    params: dict
    coefficients: dict | None
    channels: tuple | None
    origin: str

    @property
    def weave(self):
        return self.model.weave


def _texture_source(model, params, coefficients, channels, origin, *, path=None, field="source") -> TextureSource:
    """A TextureSource, after checking that the model has a texture model and the layout's parameters."""
    if not model.has_texture:
        raise InputError(f"{origin}: model kind {model.kind!r} has no texture model", path=path, field=field)
    missing = [name for name in LAYOUT_PARAMETERS if name not in model.params]
    # a point texture model declaring none of them (kind surface: segment sizes from the weave) takes the
    # layout without ratio and hwidth (texture_params)
    layout_free = len(missing) == len(LAYOUT_PARAMETERS) and not model.texture_filters
    if missing and not layout_free:
        raise InputError(f"{origin}: the texture layout (segment ratio, hwidth of eq. 12) needs the parameters "
                         f"{', '.join(LAYOUT_PARAMETERS)}; model kind {model.kind!r} declares no "
                         f"{', '.join(missing)}", path=path, field=field)
    return TextureSource(model, params, coefficients, channels, origin)


def load_source(source) -> TextureSource:
    """A fit directory (fit.json + weave.wv), a fabric.yaml, or ``preset:<name>`` / a preset name (the registry's
    default model kind); its model must have a texture model with the layout's parameters."""
    from clothlab.config.build import model_from_config, model_from_weave
    from clothlab.weave.presets import PRESET_NAMES

    text = str(source)
    path = Path(text)
    if path.is_dir():
        from clothlab.fit.store import load_fitted

        model, params, coefficients, channels = load_fitted(path)
        return _texture_source(model, params, coefficients, channels, f"fit:{path}", path=path / "fit.json",
                               field="model.kind")
    if path.suffix.lower() in (".yaml", ".yml") and path.is_file():
        from clothlab.config import load_config

        config = load_config(path)
        model = model_from_config(config)
        return _texture_source(model, model.resolve(config.model.params), None, None, f"config:{path}", path=path,
                               field="model.kind")
    name = text[len("preset:"):] if text.lower().startswith("preset:") else text
    if name.strip().lower().replace("_", "-") not in PRESET_NAMES:
        raise InputError(f"texture source '{text}' is neither a fit directory, a fabric.yaml nor a preset "
                         f"({', '.join(PRESET_NAMES)})", field="source")
    from clothlab.simulate.examples import YARN_COLOURS

    model = model_from_weave(f"preset:{name}")
    colours = YARN_COLOURS.get(model.weave.name)
    coefficients = None if colours is None else {k: np.asarray(v, dtype=np.float64) for k, v in colours.items()}
    return _texture_source(model, model.default_parameters(), coefficients, ("R", "G", "B") if colours else None,
                           f"preset:{model.weave.name}")


def fig4_directions(n_directions: int = 16, *, elevations=ELEVATIONS, views=((0.0, 0.0),)) -> np.ndarray:
    """(N, 4) theta_i, phi_i, theta_o, phi_o (deg): lights on half circles of the given elevations (Fig. 4),
    ``n_directions`` in all, spread evenly over elevations and views; azimuths evenly over [0, 180] deg."""
    elevations = [float(e) for e in elevations]
    views = [tuple(float(a) for a in v) for v in views]
    groups = len(elevations) * len(views)
    if int(n_directions) < groups:
        raise InputError(f"n_directions = {n_directions} is fewer than the {groups} (elevation, view) groups",
                         field="n_directions")
    if any(not 0.0 < e <= 90.0 for e in elevations):
        raise InputError(f"elevations must lie in (0, 90] deg, got {elevations}", field="elevations")
    per_group = np.full(groups, int(n_directions) // groups)
    per_group[: int(n_directions) % groups] += 1
    rows = []
    for g, count in enumerate(per_group):
        view = views[g // len(elevations)]
        elevation = elevations[g % len(elevations)]
        azimuths = [90.0] if count == 1 else np.linspace(0.0, 180.0, count)
        rows += [(90.0 - elevation, float(phi), view[0], view[1]) for phi in azimuths]
    return np.asarray(rows, dtype=np.float64)


def square_pixel_repeats(weave, size, tile_repeats: float) -> tuple[float, float]:
    """(repeats across the width, across the height) in tiles so that pixels are square in cells."""
    width, height = size
    cells_per_px = float(tile_repeats) * weave.tile_width / width
    return float(tile_repeats), cells_per_px * height / weave.tile_height


def rotate_z(vectors: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate (..., 3) vectors counter-clockwise about z by ``angle_deg``."""
    c, s = np.cos(np.deg2rad(angle_deg)), np.sin(np.deg2rad(angle_deg))
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([c * x - s * y, s * x + c * y, vectors[..., 2]], axis=-1)


def fabric_coordinates(u, v, rotation: float, centre, weave) -> tuple[np.ndarray, np.ndarray]:
    """Fabric texture coordinates f = c + R(-rho)(p - c) of image texture coordinates p = (u, v) (tiles);
    the rotation acts in cells (square), ``centre`` c in tiles."""
    if rotation == 0.0:
        return np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    w, h = weave.tile_width, weave.tile_height
    du, dv = (np.asarray(u) - centre[0]) * w, (np.asarray(v) - centre[1]) * h
    c, s = np.cos(np.deg2rad(rotation)), np.sin(np.deg2rad(rotation))
    return centre[0] + (c * du + s * dv) / w, centre[1] + (-s * du + c * dv) / h


def texture_params(params: dict, *, ratio: float = 1.0, hwidth: float | None = None) -> dict:
    """``params`` with the segment ratio scale and hwidth of a :class:`TextureLayout` applied."""
    out = dict(params)
    if "warp.l" not in params:  # a model whose segment sizes are the weave's (kind surface)
        if ratio != 1.0 or hwidth is not None:
            raise InputError("the texture layout's ratio and hwidth need a model with the parameters "
                             f"{', '.join(LAYOUT_PARAMETERS)}", field="ratio" if ratio != 1.0 else "hwidth")
        return out
    root = float(np.sqrt(ratio))
    for kind in ("warp", "weft"):
        out[f"{kind}.l"] = params[f"{kind}.l"] * root
        out[f"{kind}.w"] = params[f"{kind}.w"] / root
    if hwidth is not None:
        out["hwidth"] = float(hwidth)
    return out


def image_centre(offset, repeats) -> tuple[float, float]:
    """Texture coordinate (tiles) of the image centre for a stack written with ``offset`` and ``repeats``."""
    return offset[0] + 0.5 * repeats[0], offset[1] + 0.5 * repeats[1]


def texture_evaluator(texture, params: dict, coefficients: dict, layout: TextureLayout, centre):
    """``evaluate(u, v, wi, wo) -> (H, W, C)`` for :func:`clothlab.btf.write.write_btf_stack` (image-frame
    directions and texture coordinates, mapped to the fabric by ``layout``)."""
    p = texture_params(params, ratio=layout.ratio, hwidth=layout.hwidth)

    def evaluate(u, v, wi, wo):
        fu, fv = fabric_coordinates(u, v, layout.rotation, centre, texture.weave)
        values = texture.evaluate(fu, fv, rotate_z(wi, -layout.rotation), rotate_z(wo, -layout.rotation),
                                  coefficients, p, noise=layout.noise)
        return values.reshape(*np.shape(u), -1)

    return evaluate


def simulate_btf(source, out_dir, *, directions=None, n_directions: int = 16, size=64, tile_repeats: float = 4.0,
                 layout: TextureLayout | None = None, views=((0.0, 0.0),), naming: str = "utia",
                 force: bool = False) -> Path:
    """Write a simulated BTF stack (half-float EXR + manifest.yaml) of the texture model of ``source``
    (:func:`load_source`) and return its directory.  The generating layout, parameters and coefficients
    are recorded under ``provenance.texture`` in the manifest."""
    import warnings

    from clothlab.btf.write import write_btf_stack
    from clothlab.errors import GeometryWarning

    layout = layout or TextureLayout()
    src = source if isinstance(source, TextureSource) else load_source(source)
    if src.coefficients is None:
        raise InputError(f"{src.origin} carries no coefficients (kd, ks_warp, ks_weft); give them "
                         "(with_coefficients; clothlab simulate --btf: --kd, --ks-warp, --ks-weft)", field="source")
    texture = src.model.texture(seed=int(layout.seed))
    size = (int(size), int(size)) if np.ndim(size) == 0 else tuple(int(s) for s in size)
    repeats = square_pixel_repeats(src.weave, size, tile_repeats)
    table = fig4_directions(n_directions, views=views) if directions is None else np.asarray(directions, float)
    centre = image_centre(layout.offset, repeats)
    p = texture_params(src.params, ratio=layout.ratio, hwidth=layout.hwidth)
    provenance = {"texture": {
        "source": src.origin, "weave": src.weave.name, **layout.to_dict(), "hwidth": p.get("hwidth"),
        "rotation_centre_tiles": list(centre), "fineness": float(src.weave.fineness),
        "model": src.model.kind, **src.model.settings(),
        "params": src.params, "coefficients": {k: np.asarray(v).tolist() for k, v in src.coefficients.items()},
        "channels": list(src.channels or []),
        "directions": "light on half circles of elevation 30/45/60/75 deg (theta_i = 90 - elevation), "
                      "azimuth 0..180 deg; paper Fig. 4"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)  # reported by the reflectance fit already
        return write_btf_stack(out_dir, texture_evaluator(texture, src.params, src.coefficients, layout, centre),
                               directions=table, size=size, tile_repeats=repeats, naming=naming, exr=True,
                               manifest=True, overwrite=force, half=True, offset=layout.offset,
                               channel_names=list(src.channels) if src.channels else None, provenance=provenance)


#: coefficient -> CLI flag; the defaults where neither the flags nor the source give a coefficient are those of
#: the table simulation (``clothlab simulate``): 0.1 per channel
COEFFICIENT_FLAGS = {"kd": "--kd", "ks_warp": "--ks-warp", "ks_weft": "--ks-weft"}
DEFAULT_COEFFICIENT = 0.1
DEFAULT_CHANNELS = ("R", "G", "B")


def _values(text, flag: str, names: tuple) -> np.ndarray:
    n = len(names)
    if isinstance(text, str):
        try:
            values = np.array([float(x) for x in text.split(",")])
        except ValueError:
            raise ConfigError(f"expected comma-separated numbers, got {text!r}", field=flag) from None
    else:
        values = np.atleast_1d(np.asarray(text, dtype=np.float64))
    if values.size == 1:
        values = np.repeat(values, n)
    if values.size != n or not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ConfigError(f"expected {n} non-negative value(s), one per channel ({', '.join(names)}), or one for "
                         f"all; got {text!r}", field=flag)
    return values


def with_coefficients(src: TextureSource, *, kd=None, ks_warp=None, ks_weft=None, channels=None) -> tuple[
        TextureSource, dict]:
    """``src`` with its coefficients resolved: a flag value (comma-separated per channel, or one number for
    all) overrides the source's own (a fit's or a preset's example colours); a coefficient neither gives is
    0.1 per channel, as in the table simulation.  ``channels`` (names, comma-separated or a sequence; None:
    the source's, else R,G,B).  Returns (source, {coefficient: 'flag' | 'source' | 'default'})."""
    from dataclasses import replace

    if channels is None:
        names = tuple(src.channels) if src.channels else DEFAULT_CHANNELS
    else:
        names = tuple(c.strip() for c in (channels.split(",") if isinstance(channels, str) else channels))
        if not names or not all(names) or len(set(names)) != len(names):
            raise ConfigError(f"expected distinct comma-separated channel names, got {channels!r}", field="--channels")
    n = len(names)
    given = {"kd": kd, "ks_warp": ks_warp, "ks_weft": ks_weft}
    own = src.coefficients or {}
    coefficients, origin = {}, {}
    for name, flag in COEFFICIENT_FLAGS.items():
        if given[name] is not None:
            coefficients[name], origin[name] = _values(given[name], flag, names), "flag"
        elif name in own:
            value = np.atleast_1d(np.asarray(own[name], dtype=np.float64))
            if value.size not in (1, n):
                raise ConfigError(f"{src.origin} gives {name} for {value.size} channel(s) "
                                 f"({', '.join(src.channels or [])}) but the stack is to have {n} "
                                 f"({', '.join(names)}); give {flag} for the {n} channel(s)", field=flag)
            coefficients[name], origin[name] = np.broadcast_to(value, (n,)).copy(), "source"
        else:
            coefficients[name], origin[name] = np.full(n, DEFAULT_COEFFICIENT), "default"
    for component in src.model.component_names:  # per-yarn diffuse (kind surface): the source's, else kd
        name = "kd_" + component.split("_", 1)[1] if component.startswith("diffuse_") else None
        if name is not None:
            if kd is None and name in own:
                value = np.atleast_1d(np.asarray(own[name], dtype=np.float64))
                coefficients[name] = np.broadcast_to(value, (n,)).copy()
                origin[name] = "source"
            else:
                coefficients[name], origin[name] = coefficients["kd"], origin["kd"]
    return replace(src, coefficients=coefficients, channels=names), origin


def simulate_btf_command(source, out_dir, *, n_directions: int = 16, size: int = 64, tile_repeats: float = 4.0,
                         offset=(0.25, 0.4), seed: int = 0, kd=None, ks_warp=None, ks_weft=None, channels=None,
                         rule: str | None = None, nodes: int | None = None, force: bool = False) -> int:
    """CLI body of ``clothlab simulate --btf``: write the stack, log one line (logger ``clothlab.simulate.btf``,
    level INFO) saying what was written; 0 on success.

    ``kd``, ``ks_warp``, ``ks_weft``, ``channels``: see :func:`with_coefficients`; ``rule`` / ``nodes``
    override the source's quadrature of the texture model."""
    from dataclasses import replace

    offset = tuple(float(x) for x in (np.repeat(offset, 2) if np.ndim(offset) == 0 else offset))
    src = load_source(source)
    if rule is not None or nodes is not None:
        src = replace(src, model=src.model.with_quadrature(rule, None if nodes is None else int(nodes)))
    src, origin = with_coefficients(src, kd=kd, ks_warp=ks_warp, ks_weft=ks_weft, channels=channels)
    path = simulate_btf(src, out_dir, n_directions=n_directions, size=size, tile_repeats=tile_repeats,
                        layout=TextureLayout(offset=offset, seed=int(seed)), force=force)
    coefs = "; ".join(f"{k} = {', '.join(f'{c:g}' for c in v)} ({origin[k]})" for k, v in src.coefficients.items())
    get_logger(__name__).info(
        f"wrote simulated BTF stack {path} ({n_directions} images, {size} px, {tile_repeats:g} tiles across, "
        f"offset {offset[0]:g}, {offset[1]:g} tiles, noise seed {seed}; channels {', '.join(src.channels)}: {coefs})")
    return 0
