"""Render a cloth patch with the IM or Kang shaders; EXR + PNG output; LoD vs texture comparisons.

Radiance per sample (no global illumination, no shadows but back-facing):

    L = f_r(wi, wo) E cos(theta_i),   E = light intensity (directional) or I / d^2 (point, d in metres)

with wi, wo in the fabric frame of the hit (z normal, y warp, x weft); samples with wi_z <= 0 or wo_z <= 0
are black.  A pixel is the mean over its ``spp`` samples (the pixel centre for spp = 1, stratified jitter
for square spp, seeded by scene.seed); background pixels are 0.  Everything is vectorised over samples.
For the shaders that shade a pixel's footprint as one box (``shade.CENTRE_POLICIES``: neural-lod) the
pixel centres are traced too at spp > 1 (``Samples.centre``), so that the box does not move with the jitter.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from clothlab.errors import ConfigError, ResultExistsError
from clothlab.render.camera import PinholeCamera
from clothlab.render.geometry import footprint_of, make_surface
from clothlab.render.scene import Scene, check_render_memory
from clothlab.render.shade import (
    CENTRE_POLICIES,
    COUNTERS,
    FOOTPRINT_POLICIES,
    SAMPLE_COUNTERS,
    SHADERS,
    TEXTURE_POLICIES,
    Counter,
    FabricModels,
    PixelCentres,
    Samples,
    lod_weight,
    network_samples,
    reference_shader,
    shade,
    shader_kind,
)


@dataclass
class RenderResult:
    """image (H, W, C) linear radiance; coverage (H, W) fraction of samples on the patch; timings (s: wall
    clock per stage, ``shading_cpu`` / ``total_cpu`` this process's CPU time, ``<model>_seconds`` per model);
    stats: sample and model-evaluation counts, the fraction of covered pixels that ran the texture model
    (``texture_pixel_fraction``), that used only the reflectance model, footprint range (tiles)."""

    image: np.ndarray
    coverage: np.ndarray
    channels: tuple
    shader: str
    spp: int
    timings: dict
    stats: dict
    exposure: float = 0.0
    metadata: dict = field(default_factory=dict)


def _check(shader, spp):
    if shader not in SHADERS:
        raise ConfigError(f"unknown shader {shader!r}; choose one of {', '.join(SHADERS)}", field="shader")
    if isinstance(spp, bool) or not isinstance(spp, int | np.integer) or spp < 1:
        raise ConfigError(f"spp must be an integer >= 1, got {spp!r}", field="spp")


def render(scene: Scene, *, shader: str = "im-lod", spp: int | None = None, seed: int | None = None,
           fabric: FabricModels | None = None) -> RenderResult:
    """Render ``scene`` with ``shader`` (one of SHADERS) at ``spp`` samples per pixel (default scene.spp).

    ``fabric``: prebuilt models (:meth:`FabricModels.build`) to reuse between renders of one scene.
    """
    spp = scene.spp if spp is None else spp
    _check(shader, spp)
    if spp != scene.spp:  # the scene checked its own render.spp; an override is checked here, before any work
        check_render_memory(scene.camera.resolution, spp, len(scene.fabric.channels), source=scene.source)
    start, cpu_start = time.perf_counter(), time.process_time()
    fabric = fabric or FabricModels.build(scene.fabric)
    t_build = time.perf_counter()
    camera = PinholeCamera(scene.camera)
    surface = make_surface(scene.patch)
    rng = np.random.default_rng(scene.seed if seed is None else seed)
    px, py = camera.pixel_samples(spp, rng)
    h, w = camera.height, camera.width
    pixel = np.broadcast_to(np.arange(h * w).reshape(h, w, 1), px.shape).reshape(-1)
    idx, front, hits, steps, wi, wo, irradiance = _trace(camera, surface, scene.light, px.reshape(-1),
                                                         py.reshape(-1))
    footprint = footprint_of(steps)
    centre = None
    if shader_kind(shader)[1] in CENTRE_POLICIES:  # at 1 spp the samples are the centres
        centre = _pixel_centres(camera, surface, scene.light, (idx, front, hits, steps, wi, wo) if spp == 1 else None)
    samples = Samples(hits.u[front], hits.v[front], wi[front], wo[front], footprint[front], pixel[idx][front],
                      hits.distance[front], centre)
    t_geometry, cpu_geometry = time.perf_counter(), time.process_time()

    counter = Counter()
    f_r = shade(shader, fabric, samples, scene.lod, counter)
    radiance = f_r * (irradiance[front] * wi[front, 2])[:, None]
    t_shade, cpu_shade = time.perf_counter(), time.process_time()

    channels = len(fabric.channels)
    image = np.stack([np.bincount(samples.pixel, radiance[:, c], minlength=h * w) for c in range(channels)],
                     axis=-1) / spp
    coverage = np.bincount(pixel[idx], minlength=h * w) / spp
    t_end, cpu_end = time.perf_counter(), time.process_time()

    timings = {"setup": t_build - start, "geometry": t_geometry - t_build, "shading": t_shade - t_geometry,
               "accumulate": t_end - t_shade, "total": t_end - start,
               "shading_cpu": cpu_shade - cpu_geometry, "total_cpu": cpu_end - cpu_start}
    timings.update({k: v for k, v in counter.items() if k.endswith("_seconds")})
    stats = _stats(shader, scene, samples, counter, h * w, idx.size, pixel[idx])
    return RenderResult(image=image.reshape(h, w, channels), coverage=coverage.reshape(h, w),
                        channels=fabric.channels, shader=shader, spp=int(spp), timings=timings, stats=stats,
                        exposure=scene.exposure,
                        metadata={"scene": scene.source or "", "shader": shader, "spp": int(spp),
                                  "lod_f0": scene.lod.f0, "lod_f1": scene.lod.f1,
                                  "camera_distance_mm": scene.camera.distance})


def _trace(camera, surface, light, px, py):
    """Rays through pixel positions px, py (M,): (idx: the rays that hit the patch; front: those of the hits
    lit and seen from the front; per hit: the hits, the (du, dv) tile steps of a one-pixel step in x and in y
    (2, hits, 2; :meth:`~clothlab.render.geometry.Hits.differentials`), fabric-frame wi, wo, irradiance)."""
    directions = camera.directions(px, py)
    hits = surface.intersect(camera.eye, directions)
    idx = np.flatnonzero(hits.hit)
    hits = type(hits)(**{k: getattr(hits, k)[idx] for k in hits.__dataclass_fields__})
    steps = hits.differentials(camera.eye, camera.directions(px[idx] + 1.0, py[idx]),
                               camera.directions(px[idx], py[idx] + 1.0), surface.tile_mm)
    to_light, irradiance = _light(light, hits.position)
    wi, wo = hits.to_fabric(to_light), hits.to_fabric(-directions[idx])
    front = np.flatnonzero((wi[:, 2] > 0.0) & (wo[:, 2] > 0.0))
    return idx, front, hits, steps, wi, wo, irradiance


def _pixel_centres(camera, surface, light, traced=None) -> PixelCentres:
    """The surface point through each pixel's centre (the 1-spp sample of :meth:`PinholeCamera.pixel_samples`),
    by pixel index; ``traced``: the :func:`_trace` of the centres (at 1 spp the samples), else traced here."""
    if traced is None:
        cx, cy = camera.pixel_samples(1, None)
        traced = _trace(camera, surface, light, cx.reshape(-1), cy.reshape(-1))[:6]
    idx, front, hits, steps, wi, wo = traced
    n = camera.height * camera.width
    out = PixelCentres(np.zeros(n), np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n),
                       np.full((n, 2, 2), np.inf), np.zeros(n, dtype=bool))
    at = idx[front]
    out.u[at], out.v[at], out.wi[at], out.wo[at] = hits.u[front], hits.v[front], wi[front], wo[front]
    out.steps[at] = steps[:, front].transpose(1, 0, 2)
    out.footprint[at], out.valid[at] = footprint_of(steps[:, front]), True
    return out


def _light(light, position):
    """Unit directions towards the light (M, 3) and the irradiance at normal incidence (M,)."""
    if light.type == "directional":
        d = np.asarray(light.direction, dtype=np.float64)
        return np.broadcast_to(d / np.linalg.norm(d), position.shape), np.full(len(position), light.intensity)
    offset = np.asarray(light.position, dtype=np.float64) - position
    dist = np.linalg.norm(offset, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return offset / dist[:, None], np.where(dist > 0.0, light.intensity / (1e-3 * dist) ** 2, 0.0)


def _stats(shader, scene, samples, counter, pixels, hit_samples, hit_pixel) -> dict:
    shaded_pixels = np.unique(samples.pixel)
    n = max(shaded_pixels.size, 1)
    policy = shader_kind(shader)[1]
    if policy in FOOTPRINT_POLICIES:
        b = lod_weight(samples.footprint, scene.lod.f0, scene.lod.f1)
        if policy == "network-lod":  # network pixels run no texture sample
            b = np.where(network_samples(samples), 1.0, b)
        texture_pixels = np.unique(samples.pixel[b < 1.0]).size
        reflectance_only = n - np.unique(samples.pixel[b < 1.0]).size if shaded_pixels.size else 0
        blend_pixels = np.unique(samples.pixel[(b > 0.0) & (b < 1.0)]).size
    else:
        uses_texture = policy in TEXTURE_POLICIES
        texture_pixels = shaded_pixels.size if uses_texture else 0
        reflectance_only = shaded_pixels.size - texture_pixels
        blend_pixels = 0
    finite = samples.footprint[np.isfinite(samples.footprint)]
    stats = {
        "pixels": int(pixels),
        "covered_pixels": int(np.unique(hit_pixel).size),
        "shaded_pixels": int(shaded_pixels.size),
        "samples": int(hit_samples),
        "shaded_samples": int(samples.u.size),
        "texture_pixel_fraction": texture_pixels / n,
        "blend_pixel_fraction": blend_pixels / n,
        "reflectance_only_pixel_fraction": reflectance_only / n,
        "footprint_min_tiles": float(finite.min()) if finite.size else float("nan"),
        "footprint_median_tiles": float(np.median(finite)) if finite.size else float("nan"),
        "footprint_max_tiles": float(finite.max()) if finite.size else float("nan"),
    }
    for name in COUNTERS:
        stats[f"{name}_evaluations"] = int(counter.get(f"{name}_points", 0))
    return stats


# ---------------------------------------------------------------------------------------------- output


def to_srgb8(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """8-bit sRGB codes (H, W, C) of linear ``image`` scaled by 2^exposure, clipped to [0, 1]."""
    from clothlab.btf.images import linear_to_srgb

    scaled = np.clip(np.asarray(image, dtype=np.float64) * 2.0 ** exposure, 0.0, 1.0)
    return np.rint(linear_to_srgb(scaled) * 255.0).astype(np.uint8)


def save_render(result: RenderResult, path_stem, *, exposure: float | None = None, force: bool = False,
                pixel_type: str = "half") -> tuple[Path, Path]:
    """Write ``<stem>.exr`` (linear, 'half' or 'float', with scene metadata) and ``<stem>.png`` (sRGB, 8 bit,
    exposure in stops; default the scene's), each atomically (temporary file + rename).  Refuses to replace
    an existing file unless ``force``.  Returns (exr path, png path)."""
    import os
    import tempfile

    from clothlab.btf.images import write_image

    if pixel_type not in ("half", "float"):
        raise ConfigError(f"EXR pixel type must be 'half' or 'float', got {pixel_type!r}", field="pixel_type")
    stem = Path(path_stem)
    if stem.suffix.lower() in (".exr", ".png"):
        stem = stem.with_suffix("")
    exr, png = stem.parent / f"{stem.name}.exr", stem.parent / f"{stem.name}.png"
    existing = [p for p in (exr, png) if p.exists()]
    if existing and not force:
        raise ResultExistsError(f"{', '.join(map(str, existing))} already exist(s); use --force (force=True) "
                                "to replace", path=existing[0])
    exr.parent.mkdir(parents=True, exist_ok=True)
    exposure = result.exposure if exposure is None else exposure
    names = result.channels if len(result.channels) == result.image.shape[-1] else None
    attributes = {f"clothlab:{k}": v for k, v in result.metadata.items()}
    jobs = ((exr, result.image, pixel_type, names),
            (png, to_srgb8(result.image, exposure).astype(np.float32) / 255.0, "uint8", None))
    for path, pixels, ptype, channel_names in jobs:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
        os.close(fd)
        try:
            write_image(tmp, pixels, pixel_type=ptype, channel_names=channel_names,
                        attributes=attributes if path is exr else None)
            os.chmod(tmp, 0o644)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return exr, png


# ---------------------------------------------------------------------------------------------- comparison


def relative_error(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """sum |image - reference| / sum |reference| over the masked pixels and all channels (relative L1)."""
    if mask is not None:
        image, reference = image[mask], reference[mask]
    denominator = np.abs(reference).sum()
    return float(np.abs(image - reference).sum() / denominator) if denominator > 0 else float("nan")


def timed_render(scene: Scene, shader: str, spp: int, fabric: FabricModels, repeats: int = 1,
                 budget_s: float = float("inf"), seed: int | None = None) -> tuple[RenderResult, int]:
    """(the render with the least shading CPU time of up to ``repeats``, the number run): each render cold
    (the models' direction memos dropped first: a repeat must not reuse its predecessor's reflectance work
    at the same directions); no further repeat once ``budget_s`` wall seconds are spent."""
    best, spent, runs = None, 0.0, 0
    while runs < max(1, repeats) and (runs == 0 or spent < budget_s):
        fabric.forget_directions()
        result = render(scene, shader=shader, spp=spp, fabric=fabric, seed=seed)
        spent, runs = spent + result.timings["total"], runs + 1
        if best is None or result.timings["shading_cpu"] < best.timings["shading_cpu"]:
            best = result
    return best, runs


def render_figures(result: RenderResult, reference: np.ndarray, mask: np.ndarray, runs: int = 1) -> dict:
    """A render's figures against ``reference`` (an image) over ``mask``: total and shading seconds (wall),
    shading CPU seconds, runs, relative L1 error, texture / blend pixel fractions, model evaluations per
    model and in all, seconds per sample-evaluated model."""
    st, t = result.stats, result.timings
    return {"seconds": t["total"], "shading_seconds": t["shading"], "shading_cpu_seconds": t["shading_cpu"],
            "runs": runs, "relative_error": relative_error(result.image, reference, mask),
            "texture_pixel_fraction": st["texture_pixel_fraction"], "blend_pixel_fraction": st["blend_pixel_fraction"],
            **{f"{m}_evaluations": st[f"{m}_evaluations"] for m in COUNTERS},
            "model_evaluations": sum(st[f"{m}_evaluations"] for m in COUNTERS),
            **{f"{m}_{k}": t.get(f"{m}_{k}", 0.0) for m in SAMPLE_COUNTERS for k in ("seconds", "cpu_seconds")}}


def compare_lod(scene: Scene, distances, *, shaders=("im-lod", "im-texture"), spp: int = 4,
                reference_spp: int = 64, repeats: int = 1, repeat_budget_s: float = float("inf"),
                warmup: bool = True, fabric: FabricModels | None = None, reference_check: bool = False) -> list[dict]:
    """Render ``scene`` with the camera moved to each distance (mm from its look-at point, same direction):
    per shader family the supersampled texture-level shader (im-texture or kang-texture at ``reference_spp``
    stratified samples) as the antialiasing reference, and each shader at ``spp``.  Per distance and shader:
    the render with the least shading CPU time of up to ``repeats`` (fewer once a shader has spent
    ``repeat_budget_s`` at that distance) - total and shading seconds (wall), shading CPU seconds (this
    process; less disturbed by other load), seconds per model - the relative L1
    error vs its family's reference over fully covered pixels, the model evaluations (deterministic: the
    same scene gives the same counts), texture / blend pixel fractions; and the footprint range of the view
    (tiles).  ``warmup``: one small render per shader first, so compilation is not timed; the models'
    direction memos are dropped before every timed render (a repeat would otherwise reuse its predecessor's
    reflectance work at the same directions).
    ``reference_check``: also ``<family>_reference_error``, the relative L1 difference between the reference
    and a second one from another seed (about sqrt 2 times the reference's own error: errors of that size
    are below what the comparison resolves)."""
    for shader in shaders:
        _check(shader, spp)
    fabric = fabric or FabricModels.build(scene.fabric)
    if warmup:
        small = replace(scene, camera=replace(scene.camera, resolution=(4, 3)))
        for shader in {*shaders, *(reference_shader(s) for s in shaders)}:
            render(small, shader=shader, spp=1, fabric=fabric)
    rows = []
    for distance in distances:
        s = replace(scene, camera=scene.camera.at_distance(distance))
        references = {}
        row = {"distance_mm": float(distance)}
        for shader in shaders:
            family = shader.split("-")[0]
            name = reference_shader(shader)  # its kind's texture-level shader (neural-lod: im-lod's)
            if name not in references:
                references[name] = render(s, shader=name, spp=reference_spp, fabric=fabric)
            reference = references[name]
            row[f"{family}_reference_seconds"] = reference.timings["total"]
            mask = reference.coverage >= 1.0
            if reference_check and f"{family}_reference_error" not in row:
                second = render(s, shader=name, spp=reference_spp, fabric=fabric, seed=s.seed + 1)
                row[f"{family}_reference_error"] = relative_error(second.image, reference.image, mask)
            best, runs = timed_render(s, shader, spp, fabric, repeats, repeat_budget_s)
            st = best.stats
            row[shader] = render_figures(best, reference.image, mask, runs)
            row.setdefault("pixels", int(mask.sum()))
            row.setdefault("footprint_min_tiles", st["footprint_min_tiles"])
            row.setdefault("footprint_median_tiles", st["footprint_median_tiles"])
            row.setdefault("footprint_max_tiles", st["footprint_max_tiles"])
        rows.append(row)
    return rows
