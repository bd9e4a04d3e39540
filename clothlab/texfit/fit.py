"""Fit the texture parameters the BRDF cannot see to a BTF stack (Irawan & Marschner 2012, sec. 4.2, 7.2).

Free (any subset of :data:`TEXTURE_FREE`): the tile offset (u0, v0) in tiles, a small rotation rho (deg),
the segment length/width ratio scale s and hWidth (eq. 12), with the layout conventions of
:mod:`clothlab.simulate.btf`.  The BRDF parameters come from a reflectance fit (or fabric.yaml) and
are **held fixed**; ``refine`` names BRDF parameters (e.g. ``warp.umax``) that are refined as well, within
their declared fit bounds, in a second stage that starts from the held optimum and keeps the better of the
two (so refining never ends worse than holding).  At every objective evaluation the linear coefficients
(kd, ks_warp, ks_weft) are solved by exact NNLS per channel (:func:`clothlab.fit.nnls.nnls_small`).

Data: the **raw images**, not the unit-tile averages.  Reasons: (1) a rotated weave is smeared by averaging
tiles along the image axes, so the rotation is only observable in the raw images; (2) the intensity noise
(sec. 7.2.1) lives in the raw images only (tile averaging removes it), and its statistics are reported from
the residuals; (3) the offset is kept exactly (the model is evaluated at the very pixel centres).  The model
is noise-free in the objective (the noise realisation of real cloth is unknown; the noise has mean 1, so
the least-squares fit is unbiased).  Objective: sum of squared pixel residuals / sum of squared pixel values.

The image scale (tiles across the image) is read from the manifest of a clothlab-simulated stack, else
estimated from the images (:meth:`BtfStack.estimate_period`), or given.

Global stage: the offset objective is periodic and multimodal (every shift that lines the bands up with the
wrong yarns is a local minimum), so the offset is first searched on a grid over one whole tile (step
``grid_step`` cells, images subsampled by ``grid_stride`` px) with the other parameters at their starts;
then nlopt's LN_SBPLX (robust on the piecewise-constant steps that band edges crossing pixel centres cause)
polishes all free parameters from the best ``starts`` grid points, the offset boxed to +- one grid step.

Noise statistics: the ratio (measured - kd/pi) / (model specular) over pixels whose model specular part is
bright; its coefficient of variation is the fitted noise ``amplitude`` (1 for the paper's exponential noise,
0 without noise).  The offset is identifiable only up to the weave's own translations
(:func:`pattern_translations`); the result lists them.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from clothlab.config.schema import DEFAULT_PERCENTILES
from clothlab.errors import GeometryWarning, InputError
from clothlab.simulate.btf import (
    TextureSource,
    fabric_coordinates,
    image_centre,
    load_source,
    rotate_z,
    texture_params,
)

TEXTURE_FREE = ("offset", "rotation", "ratio", "hwidth")
ROTATION_BOUNDS = (-5.0, 5.0)  # deg
RATIO_BOUNDS = (0.8, 1.25)
HWIDTH_BOUNDS = (0.05, 1.0)
NOISE_PRESENT = 0.2  # amplitude (coefficient of variation) above which noise is reported present
MAX_PIXEL_BYTES = 2**30


def pattern_translations(weave, samples: int = 4, atol: float = 1e-3) -> np.ndarray:
    """(K, 2) shifts (du, dv) in tiles, whole cells within one tile, that leave the noise-free texture
    unchanged (same yarn kind and local (x, y) to ``atol`` cells at every point; the published segment
    centres carry 4 digits, e.g. 0.0833); (0, 0) first."""
    from clothlab.weave.lookup import locate_segments

    w, h = weave.tile_width, weave.tile_height
    grid = (np.arange(samples) + 0.5) / samples
    u = ((np.arange(w)[:, None] + grid[None, :]).ravel() / w)[None, :]
    v = ((np.arange(h)[:, None] + grid[None, :]).ravel() / h)[:, None]
    u, v = np.broadcast_arrays(u, v)
    kinds = np.array([s.kind == "weft" for s in weave.segments])
    seg, x, y = locate_segments(weave, u, v)
    shifts = []
    for b in range(h):
        for a in range(w):
            seg2, x2, y2 = locate_segments(weave, u + a / w, v + b / h)
            if (np.array_equal(kinds[seg], kinds[seg2]) and np.allclose(x, x2, atol=atol)
                    and np.allclose(y, y2, atol=atol)):
                shifts.append((a / w, b / h))
    return np.asarray(shifts, dtype=np.float64)


def offset_error_cells(found, truth, weave) -> float:
    """Distance (cells) between two offsets modulo whole tiles and the weave's own translations."""
    w, h = weave.tile_width, weave.tile_height
    d = np.asarray(found, float)[None, :] - np.asarray(truth, float)[None, :] - pattern_translations(weave)
    d -= np.round(d)
    return float(np.min(np.hypot(d[:, 0] * w, d[:, 1] * h)))


def _same_offset(a, b, shifts, tol: float = 1e-9) -> bool:
    d = np.asarray(a, float)[None, :] - np.asarray(b, float)[None, :] - shifts
    d -= np.round(d)
    return bool(np.any(np.all(np.abs(d) < tol, axis=1)))


@dataclass
class TextureFit:
    """Result of :func:`fit_texture`.  offset in tiles wrapped to [0, 1); rotation deg; ratio and hwidth
    unitless; coefficients {name: (C,)}; errors: per-image relative-error percentiles (see :func:`image_errors`)."""

    offset: tuple[float, float]
    rotation: float
    ratio: float
    hwidth: float
    refined: dict
    coefficients: dict
    channels: tuple
    objective: float
    noise: dict
    errors: dict
    translations: list
    repeats: tuple[float, float]
    angles: np.ndarray
    files: list
    free: tuple
    nevals: int
    seconds: float
    grid: dict
    message: str
    source: str
    truth: dict | None = None
    refine_stage: dict | None = None
    crop: dict | None = None
    measured_tiles: np.ndarray | None = field(default=None, repr=False)
    model_tiles: np.ndarray | None = field(default=None, repr=False)

    def to_dict(self) -> dict:
        return {
            "offset_tiles": list(self.offset), "rotation_deg": self.rotation, "ratio_scale": self.ratio,
            "hwidth": self.hwidth, "refined": self.refined,
            "coefficients": {k: dict(zip(self.channels, np.asarray(v).tolist(), strict=True))
                             for k, v in self.coefficients.items()},
            "channels": list(self.channels), "objective": self.objective, "noise": self.noise,
            "equivalent_offset_shifts_tiles": self.translations, "tile_repeats": list(self.repeats),
            "free": list(self.free), "evaluations": self.nevals, "wall_time_s": self.seconds,
            "grid": self.grid, "optimizer": self.message, "source": self.source, "truth": self.truth,
            "held_fixed": "BRDF parameters of the source (reflectance fit), except 'refined'",
            "refine_stage": self.refine_stage, "crop": self.crop,
            "data": "raw images (pixel values), noise-free model at pixel centres",
            "errors": self.errors,
        }


class _Problem:
    """Raw stack pixels and the texture model, evaluated for a vector of free parameters."""

    def __init__(self, stack, src: TextureSource, repeats, free, refine):
        from clothlab.btf.write import texture_coordinates

        self.src, self.free, self.refine = src, tuple(free), tuple(refine)
        self.texture = src.model.texture()
        self.repeats = repeats
        size = (stack.width, stack.height)
        need = len(stack) * stack.width * stack.height * stack.channels * 4
        if need > MAX_PIXEL_BYTES:
            raise InputError(f"the stack's raw pixels need {need / 2**20:.0f} MB; crop the stack", path=stack.source)
        self.pixels = np.stack([stack.image(i) for i in range(len(stack))])  # (N, H, W, C) float32
        self.a, self.b = texture_coordinates(size, repeats)  # image coordinates without offset
        self.wi, self.wo = stack.wi, stack.wo
        self.start = {"u0": 0.0, "v0": 0.0, "rotation": 0.0, "ratio": 1.0, "hwidth": float(src.params["hwidth"]),
                      **{k: float(src.params[k]) for k in refine}}

    def names(self, refine: bool = True) -> list[str]:
        """Optimiser coordinates: the free texture parameters, then (``refine``) the refined BRDF ones."""
        out = []
        for name in self.free:
            out += ["u0", "v0"] if name == "offset" else [name]
        return out + (list(self.refine) if refine else [])


    def components(self, values: dict, stride: int = 1) -> np.ndarray:
        """(N, P, 3) diffuse, specular_warp, specular_weft at the (subsampled) pixels."""
        params = {**self.src.params, **{k: values[k] for k in self.refine}}
        params = texture_params(params, ratio=values["ratio"], hwidth=values["hwidth"])
        offset = (values["u0"], values["v0"])
        u, v = self.a[::stride, ::stride] + offset[0], self.b[::stride, ::stride] + offset[1]
        fu, fv = fabric_coordinates(u, v, values["rotation"], image_centre(offset, self.repeats), self.src.weave)
        out = np.empty((len(self.wi), fu.size, 3))
        wi, wo = rotate_z(self.wi, -values["rotation"]), rotate_z(self.wo, -values["rotation"])
        for n in range(len(self.wi)):
            comps = self.texture.components(fu, fv, wi[n], wo[n], params, noise=False, warn=False)
            for k, name in enumerate(("diffuse", "specular_warp", "specular_weft")):
                out[n, :, k] = comps[name].reshape(-1)
        return out

    def data(self, stride: int = 1) -> np.ndarray:
        p = self.pixels[:, ::stride, ::stride]
        return p.reshape(p.shape[0], -1, p.shape[-1]).astype(np.float64)

    def solve(self, values: dict, stride: int = 1):
        """(objective, coef (3, C), design (N, P, 3), data (N, P, C))."""
        from clothlab.fit.nnls import nnls_small

        design, y = self.components(values, stride), self.data(stride)
        coef, residual = nnls_small(design.reshape(-1, 3), y.reshape(-1, y.shape[-1]))
        return float(np.sum(residual**2) / np.sum(y**2)), coef, design, y


def _scale_from(stack, tile_repeats, weave) -> tuple[float, float]:
    """Tiles across the (cropped) images' (width, height): given (for the whole image), from a clothlab
    manifest (whole image), or from the images' period."""
    crop_fraction = (stack.width / stack.info.width, stack.height / stack.info.height)
    if tile_repeats is not None:
        r = np.atleast_1d(np.asarray(tile_repeats, float))
        return (float(r[0]) * crop_fraction[0], float(r[-1]) * crop_fraction[1])
    if stack.source is not None and stack.source.suffix.lower() in (".yaml", ".yml"):
        import yaml

        doc = yaml.safe_load(stack.source.read_text(encoding="utf-8")) or {}
        repeats = (doc.get("simulated") or {}).get("tile_repeats")
        if repeats:
            return (float(repeats[0]) * crop_fraction[0], float(repeats[1]) * crop_fraction[1])
    period = stack.estimate_period()
    return (stack.width / period.px, stack.height / period.py)


def crop_corner_tiles(stack, repeats) -> tuple[float, float]:
    """Texture coordinate (tiles, offset excluded) of the crop's lower-left corner in the whole image
    (pixel mapping of :mod:`clothlab.btf.write`: u from the left edge, v from the bottom edge); (0, 0)
    without a crop.  ``repeats``: tiles across the cropped image."""
    if stack.crop is None:
        return (0.0, 0.0)
    x0, y0, w, h = stack.crop
    return (x0 * repeats[0] / w, (stack.info.height - y0 - h) * repeats[1] / h)


def parse_names(text, allowed, flag: str) -> tuple[str, ...]:
    """Comma-separated names (``--free``, ``--refine``), each one of ``allowed``; ConfigError naming a bad one."""
    from clothlab.errors import ConfigError

    names = tuple(n.strip() for n in str(text).split(","))
    for name in names:
        if name not in allowed:
            raise ConfigError(f"unknown name {name!r}; choose from {', '.join(allowed)} (comma-separated)",
                              field=flag)
    if len(set(names)) != len(names):
        raise ConfigError(f"a name is given twice in {text!r}", field=flag)
    return names


def parse_crop(text, flag: str = "--crop") -> tuple[int, int, int, int]:
    """``x0,y0,width,height`` in pixels (x = column, y = row from the top), as :class:`BtfStack` takes it; each
    an integer in plain ASCII digits (no ``1_0``, ``+1``, non-ASCII digits; at most 9 digits)."""
    import re

    from clothlab.errors import ConfigError

    cells = str(text).split(",")
    values = [int(v) for v in cells] if all(re.fullmatch(r"\s*-?[0-9]{1,9}\s*", v) for v in cells) else []
    if len(values) != 4:
        raise ConfigError(f"expected x0,y0,width,height (four integers, pixels), got {text!r}", field=flag)
    x0, y0, w, h = values
    if x0 < 0 or y0 < 0 or w < 1 or h < 1:
        raise ConfigError(f"expected x0, y0 >= 0 and width, height >= 1 pixels, got {text!r}", field=flag)
    return x0, y0, w, h


#: BRDF parameters a texture fit may refine (``refine``): the reflectance model's, but hWidth (a texture
#: parameter here) and the segment w, l (set by ``ratio``)
REFINABLE = ("alpha", "beta", "delta", "warp.psi", "warp.umax", "warp.kappa", "weft.psi", "weft.umax", "weft.kappa")


def _manifest_truth(stack) -> dict | None:
    if stack.source is None or stack.source.suffix.lower() not in (".yaml", ".yml"):
        return None
    import yaml

    doc = yaml.safe_load(stack.source.read_text(encoding="utf-8")) or {}
    texture = (doc.get("provenance") or {}).get("texture")
    if not texture:
        return None
    keys = ("offset", "rotation", "ratio", "hwidth", "noise", "seed", "fineness", "source")
    return {k: texture.get(k) for k in keys}


def fit_texture(stack, source, *, free=TEXTURE_FREE, refine=(), crop=None, tile_repeats=None,
                grid_step: float = 0.25, grid_stride: int = 2, starts: int = 3, max_evals: int = 600,
                seed: int = 1) -> TextureFit:
    """Fit the texture parameters to ``stack`` (a :class:`~clothlab.btf.BtfStack` or a path) with the BRDF of
    ``source`` (fit directory, fabric.yaml or preset) held fixed; see the module docstring for the method.

    ``free``: texture parameters fitted (:data:`TEXTURE_FREE`); the others stay at their starts (offset 0,
    rotation 0, ratio 1, the source's hWidth).  ``refine``: BRDF parameters (:data:`REFINABLE`) refined in a
    second stage that starts from the held optimum (all free parameters and the refined ones together,
    LN_SBPLX, up to ``max_evals`` evaluations); the better of the held and the refined optimum is kept, so
    refining never ends worse than holding (``refine_stage`` in the result says which was kept).  ``crop``:
    (x0, y0, width, height) pixels of every image; the reported offset is that of the whole image's corner.
    ``tile_repeats``: tiles across the whole image (default: the manifest's, else from the period).  With a
    crop a rotation turns about the crop's centre (not the whole image's), which shifts the offset found by
    (I - R) (c_image - c_crop) - a small shift for the few degrees a rotation may take.
    """
    from clothlab.btf import BtfStack
    from clothlab.errors import ConfigError

    start_time = time.perf_counter()
    free, refine = tuple(free), tuple(refine)
    for names, allowed, what in ((free, TEXTURE_FREE, "free"), (refine, REFINABLE, "refine")):
        for name in names:
            if name not in allowed:
                raise ConfigError(f"unknown {what} parameter {name!r}; choose from {', '.join(allowed)}", field=what)
    if isinstance(stack, BtfStack):
        if crop is not None:
            stack = BtfStack(stack.entries, crop=crop, warp_axis=stack.warp_axis, encoding=stack.encoding,
                             source=stack.source, check=False)
    else:
        stack = BtfStack.open(stack, crop=crop)
    src = source if isinstance(source, TextureSource) else load_source(source)
    weave = src.weave
    repeats = _scale_from(stack, tile_repeats, weave)
    problem = _Problem(stack, src, repeats, free, refine)
    w, h = weave.tile_width, weave.tile_height
    nevals = 0
    messages: list[str] = []

    def polish(base, names, x0, bounds, budget):
        lo, hi = [b[0] for b in bounds], [b[1] for b in bounds]
        x0 = [float(np.clip(x, a, b)) for x, a, b in zip(x0, lo, hi, strict=True)]

        def objective(x):
            return problem.solve({**base, **dict(zip(names, x.tolist(), strict=True))})[0]

        result = minimize(objective, x0, lo, hi, global_algorithm=None, local_algorithm="LN_SBPLX",
                          max_evals=max(20, budget), seed=seed, xtol_rel=1e-5)
        messages.append(result.message)
        return result.nevals, {**base, **dict(zip(names, result.x.tolist(), strict=True))}

    def bounds_of(name, values):
        if name == "u0":
            return (values["u0"] - grid_step / w, values["u0"] + grid_step / w)
        if name == "v0":
            return (values["v0"] - grid_step / h, values["v0"] + grid_step / h)
        return {"rotation": ROTATION_BOUNDS, "ratio": RATIO_BOUNDS, "hwidth": HWIDTH_BOUNDS}.get(name) or \
            src.model.params[name].bounds

    from clothlab.fit.optimize import minimize

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        # global stage: the offset on a grid over one tile
        grid_u = np.arange(0.0, 1.0, grid_step / w)
        grid_v = np.arange(0.0, 1.0, grid_step / h)
        scores = []
        offset_free = "offset" in free
        shifts = pattern_translations(weave)
        seen: list[tuple[float, float]] = []
        for u0 in (grid_u if offset_free else [0.0]):
            for v0 in (grid_v if offset_free else [0.0]):
                if any(_same_offset((u0, v0), s, shifts) for s in seen):
                    continue  # equivalent under the weave's own translations: same objective
                seen.append((u0, v0))
                value = problem.solve({**problem.start, "u0": u0, "v0": v0}, grid_stride)[0]
                scores.append((value, u0, v0))
                nevals += 1
        scores.sort()
        # stage 1: the texture parameters with the BRDF held, polished from the best grid points
        held_names = problem.names(refine=False)
        best = None
        for _value, u0, v0 in scores[: max(1, starts)]:
            base = {**problem.start, "u0": u0, "v0": v0}
            n, values = polish(base, held_names, [base[k] for k in held_names],
                               [bounds_of(k, base) for k in held_names], max_evals // max(1, starts))
            nevals += n
            objective_value = problem.solve(values)[0]
            if best is None or objective_value < best[0]:
                best = (objective_value, values)
        held_objective, values = best
        refine_stage = None
        # stage 2: refine the BRDF parameters too, from the held optimum; keep the better
        if refine:
            names = problem.names(refine=True)
            n, refined = polish(values, names, [values[k] for k in names], [bounds_of(k, values) for k in names],
                                max_evals)
            nevals += n
            refined_objective = problem.solve(refined)[0]
            kept = "refined" if refined_objective < held_objective else "held"
            refine_stage = {"held_objective": held_objective, "refined_objective": refined_objective, "kept": kept,
                            "start": {k: float(problem.start[k]) for k in refine},
                            "refined_values": {k: float(refined[k]) for k in refine}}
            if kept == "refined":
                values = refined
        objective_value, coef, design, y = problem.solve(values)
        noise = noise_statistics(design, y, coef)
        model = np.einsum("npk,kc->npc", design, coef)

    channels = tuple(src.channels) if src.channels and len(src.channels) == y.shape[-1] else tuple(
        f"c{i}" for i in range(y.shape[-1]))
    shape = problem.pixels.shape
    errors, measured_tiles, model_tiles = image_errors(
        problem.pixels, model.reshape(shape), repeats, channels, stack)
    corner = crop_corner_tiles(stack, repeats)
    offset = (float(np.mod(values["u0"] - corner[0], 1.0)), float(np.mod(values["v0"] - corner[1], 1.0)))
    return TextureFit(
        offset=offset, rotation=float(values["rotation"]), ratio=float(values["ratio"]),
        hwidth=float(values["hwidth"]), refined={k: float(values[k]) for k in refine},
        coefficients={k: coef[i] for i, k in enumerate(("kd", "ks_warp", "ks_weft"))}, channels=channels,
        objective=objective_value, noise=noise, errors=errors,
        translations=pattern_translations(weave).tolist(), repeats=repeats, angles=stack.angles,
        files=[str(e.path.name) for e in stack.entries], free=free, nevals=nevals,
        seconds=time.perf_counter() - start_time,
        grid={"step_cells": grid_step, "stride_px": grid_stride, "points": len(scores),
              "best": [{"objective": s, "u0": a, "v0": b} for s, a, b in scores[: max(1, starts)]]},
        message="; ".join(messages), source=src.origin, truth=_manifest_truth(stack), refine_stage=refine_stage,
        crop=None if stack.crop is None else {
            "x0": stack.crop[0], "y0": stack.crop[1], "width": stack.crop[2], "height": stack.crop[3],
            "corner_tiles": list(corner), "offset_of_crop_tiles": [float(values["u0"]), float(values["v0"])]},
        measured_tiles=measured_tiles, model_tiles=model_tiles)


def noise_statistics(design, data, coef, *, bright: float = 0.25) -> dict:
    """Intensity-noise statistics from the residuals (sec. 7.2.1): r = (measured - kd diffuse) / specular model
    over pixel-channels whose model specular part exceeds ``bright`` x its 99th percentile in that image."""
    diffuse = design[..., :1] * coef[0][None, None, :]
    specular = np.einsum("npk,kc->npc", design[..., 1:], coef[1:])
    ratios = []
    for n in range(specular.shape[0]):
        s = specular[n]
        top = np.percentile(s, 99)
        if top <= 0:
            continue
        mask = s > bright * top
        ratios.append((data[n] - diffuse[n])[mask] / s[mask])
    if not ratios or sum(r.size for r in ratios) < 10:
        return {"amplitude": float("nan"), "present": None, "n": 0,
                "note": "too few bright specular pixels to measure the noise"}
    r = np.concatenate(ratios)
    amplitude = float(np.std(r) / np.mean(r)) if np.mean(r) > 0 else float("nan")
    return {"amplitude": amplitude, "present": bool(amplitude > NOISE_PRESENT), "ratio_mean": float(np.mean(r)),
            "ratio_p5": float(np.percentile(r, 5)), "ratio_p50": float(np.percentile(r, 50)),
            "ratio_p95": float(np.percentile(r, 95)), "n": int(r.size),
            "meaning": "coefficient of variation of measured/model specular intensity on bright specular "
                       "pixels; ~1 for the paper's exponential noise, ~0 without noise"}


def image_errors(measured, model, repeats, channels, stack=None, percentiles=DEFAULT_PERCENTILES):
    """Per-image relative-error percentiles: of the unit-tile averages (``tile``; the noise averaged out, the
    figure a reader compares with the paper's Fig. 3/4 tiles) and of the raw pixel values (``pixel``).
    Returns (errors dict, measured tiles, model tiles), tiles (N, ny, nx, C) averaged with the period
    (W / repeats_u, H / repeats_v) px from the image's corner."""
    from clothlab.btf.period import average_tiles
    from clothlab.fit.metrics import error_percentiles

    n, height, width, c = measured.shape
    period = (width / repeats[0], height / repeats[1])
    tiles_measured, tiles_model, rows = [], [], []
    for i in range(n):
        tm = average_tiles(measured[i], period)
        tf = average_tiles(model[i], period)
        tiles_measured.append(tm)
        tiles_model.append(tf)
        row = {"index": i}
        if stack is not None:
            e = stack.entries[i]
            row.update(file=e.path.name, theta_i=e.theta_i, phi_i=e.phi_i, theta_o=e.theta_o, phi_o=e.phi_o)
        row["tile"] = error_percentiles(tm.reshape(-1, c), tf.reshape(-1, c), percentiles, channels)["overall"]
        row["pixel"] = error_percentiles(measured[i].reshape(-1, c), model[i].reshape(-1, c), percentiles,
                                         channels)["overall"]
        rows.append(row)
    tiles_measured, tiles_model = np.stack(tiles_measured), np.stack(tiles_model)
    overall = {
        "tile": error_percentiles(tiles_measured.reshape(-1, c), tiles_model.reshape(-1, c), percentiles,
                                  channels)["overall"],
        "pixel": error_percentiles(measured.reshape(-1, c), model.reshape(-1, c), percentiles, channels)["overall"],
    }
    errors = {"meaning": "relative error |model - measured| / measured (fractions) of unit-tile averages "
                         "('tile') and of raw pixel values ('pixel'), per image",
              "period_px": list(period), "overall": overall, "images": rows}
    return errors, tiles_measured, tiles_model


def fit_btf(stack_dir, fit_dir_or_yaml, out_dir, force: bool = False, *, free=TEXTURE_FREE, refine=(),
            crop=None) -> TextureFit:
    """Fit a BTF stack and save the result directory (what ``clothlab fit-btf`` does): fit (``free``,
    ``refine``, ``crop`` as :func:`fit_texture`; comma-separated strings are parsed by :func:`parse_names` /
    :func:`parse_crop`), write ``texfit.json``, ``errors.json`` and ``tiles.png`` into ``out_dir`` atomically
    (ResultExistsError if it exists, unless ``force``); returns the fit."""
    import json

    from clothlab.atomic import atomic_directory, atomic_write_bytes
    from clothlab.errors import ResultExistsError
    from clothlab.fit.store import _json_safe
    from clothlab.texfit.plots import tile_comparison_figure

    out_dir = Path(out_dir)
    if out_dir.exists() and any(out_dir.iterdir()) and not force:
        raise ResultExistsError(f"{out_dir} already exists; pass --force to replace it", path=out_dir)
    if isinstance(free, str):
        free = parse_names(free, TEXTURE_FREE, "--free")
    if isinstance(refine, str):
        refine = parse_names(refine, REFINABLE, "--refine") if refine.strip() else ()
    if isinstance(crop, str):
        crop = parse_crop(crop)
    result = fit_texture(stack_dir, fit_dir_or_yaml, free=free, refine=refine, crop=crop)
    with atomic_directory(out_dir, force=out_dir.exists()) as tmp:
        document = _json_safe(result.to_dict())
        atomic_write_bytes(tmp / "texfit.json", (json.dumps(document, indent=2) + "\n").encode())
        atomic_write_bytes(tmp / "errors.json", (json.dumps(document["errors"], indent=2) + "\n").encode())
        figure = tile_comparison_figure(result)
        figure.savefig(tmp / "tiles.png", dpi=110)
    return result
