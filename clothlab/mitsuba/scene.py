"""A clothlab scene (:mod:`clothlab.render.scene`) rendered by Mitsuba 3 with the clothlab plugin:
:func:`scene_dict` (the Mitsuba scene description) and :func:`render_scene` (``clothlab render --renderer mitsuba``).

The translation, element by element (the same geometry, camera, light and fabric as ``clothlab render``):

- flat patch -> ``rectangle`` scaled to ``size_mm`` and moved to ``center`` (its uv spans the patch, s = +x,
  t = +y as in :class:`clothlab.render.geometry.FlatPatch`); the plugin gets ``uv_size_mm``, ``tile_mm`` and
  ``warp_angle_deg`` so (u, v) and the fabric frame are the renderer's.  A cylinder has no Mitsuba form here
  (ConfigError).
- pinhole camera -> ``perspective`` (``fov_axis: y``, look-at), ``hdrfilm`` with a box filter of one pixel
  (every sample counts for its own pixel only, as in clothlab); square ``spp`` -> ``stratified`` sampler
  (jittered), other -> ``independent``.  The plugin also gets the camera, so its LoD footprint is the one-pixel
  ray differential of :mod:`clothlab.render.geometry` (not Mitsuba's per-sample one).
- directional light -> ``directional`` (direction reversed: Mitsuba's points away from the light, irradiance
  = intensity); point light -> ``point`` with intensity 1e6 I (clothlab's d is in metres, the scene's in mm).
- integrator ``direct`` with one emitter sample and no BSDF sample (a delta light cannot be hit by BSDF
  sampling): radiance f_r E cos theta_i per sample, no shadows on the patch, as in :mod:`clothlab.render.render`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from clothlab.errors import ConfigError


def _vec(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def scene_dict(scene, material_key: str, *, spp: int, seed: int = 0) -> dict:
    """The Mitsuba scene dict of ``scene`` with the plugin material ``material_key``
    (:func:`clothlab.mitsuba.plugin.add_material`)."""
    import mitsuba as mi

    patch, camera, light = scene.patch, scene.camera, scene.light
    if patch.shape != "flat":
        raise ConfigError(f"the Mitsuba bridge renders a flat patch, not {patch.shape!r}", path=scene.source,
                          field="patch.shape")
    width, height = camera.resolution
    root = int(round(math.sqrt(spp)))
    sampler = ({"type": "stratified", "sample_count": int(spp), "jitter": True, "seed": int(seed)}
               if root * root == spp else {"type": "independent", "sample_count": int(spp), "seed": int(seed)})
    sx, sy = patch.size_mm
    bsdf = {"type": "clothlab", "material": material_key, "uv_size_mm": _vec((sx, sy)),
            "tile_mm": _vec(patch.tile_mm), "warp_angle_deg": float(patch.warp_angle_deg),
            "camera_origin": _vec(camera.position), "camera_target": _vec(camera.look_at),
            "camera_up": _vec(camera.up), "camera_fov": float(camera.fov_deg), "camera_height": int(height)}
    if light.type == "directional":
        d = -np.asarray(light.direction, dtype=np.float64)
        emitter = {"type": "directional", "direction": (d / np.linalg.norm(d)).tolist(),
                   "irradiance": {"type": "rgb", "value": float(light.intensity)}}
    else:
        emitter = {"type": "point", "position": [float(c) for c in light.position],
                   "intensity": {"type": "rgb", "value": 1e6 * float(light.intensity)}}
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {"type": "perspective", "fov": float(camera.fov_deg), "fov_axis": "y",
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.position),
                                                              target=list(camera.look_at), up=list(camera.up)),
                   "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "pixel_format": "rgb",
                            "component_format": "float32", "rfilter": {"type": "box"}},
                   "sampler": sampler},
        "patch": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().translate(list(patch.center)) @ mi.ScalarTransform4f().scale(
                      [0.5 * sx, 0.5 * sy, 1.0]),
                  "bsdf": bsdf},
        "light": emitter,
    }


def _coverage(scene, spp: int, seed: int) -> np.ndarray:
    """The fraction of each pixel's samples on the patch (clothlab's geometry at clothlab's sample positions)."""
    from clothlab.render.camera import PinholeCamera
    from clothlab.render.geometry import make_surface

    camera = PinholeCamera(scene.camera)
    px, py = camera.pixel_samples(spp, np.random.default_rng(seed))
    hits = make_surface(scene.patch).intersect(camera.eye, camera.directions(px.reshape(-1), py.reshape(-1)))
    return hits.hit.reshape(px.shape).mean(axis=-1)


def _render_wavefront(mscene, scene, spp: int, seed: int, bsdf) -> np.ndarray:
    """Direct lighting of ``mscene`` (a scalar variant) as one wavefront: Mitsuba generates the camera rays at
    clothlab's pixel sample positions (:meth:`clothlab.render.camera.PinholeCamera.pixel_samples`, the same
    seed), intersects them and samples the emitter with its shadow test, one sample at a time (~9 us each);
    the plugin then shades every sample in one model call (:meth:`eval_arrays`) and the samples are averaged
    per pixel (a one-pixel box filter).  The direct integrator's estimate for a delta light, batched."""
    import mitsuba as mi

    from clothlab.mitsuba.plugin import SurfacePoints
    from clothlab.render.camera import PinholeCamera

    camera = PinholeCamera(scene.camera)
    width, height = camera.width, camera.height
    px, py = camera.pixel_samples(spp, np.random.default_rng(seed))
    pixel = np.broadcast_to(np.arange(height * width).reshape(height, width, 1), px.shape).reshape(-1)
    px, py = px.reshape(-1) / width, py.reshape(-1) / height
    emitter = np.random.default_rng(seed + 1).random((px.size, 2))
    sensor = mscene.sensors()[0]
    keep, rows = [], {k: [] for k in ("view", "light", "uv", "p", "s", "t", "n", "weight")}
    for k in range(px.size):
        ray, ray_weight = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(px[k]), float(py[k])), mi.Point2f(0.5, 0.5))
        si = mscene.ray_intersect(ray)
        if not si.is_valid():
            continue
        ds, em = mscene.sample_emitter_direction(si, mi.Point2f(float(emitter[k, 0]), float(emitter[k, 1])), True)
        if ds.pdf == 0.0 or not any(float(c) != 0.0 for c in em):
            continue
        keep.append(k)
        frame = si.sh_frame
        for name, value in (("view", si.wi), ("light", si.to_local(ds.d)), ("uv", si.uv), ("p", si.p),
                            ("s", frame.s), ("t", frame.t), ("n", frame.n), ("weight", ray_weight * em)):
            rows[name].append(tuple(value))
    channels = 3
    image = np.zeros((height * width, channels))
    if keep:
        a = {k: np.asarray(v, dtype=np.float64) for k, v in rows.items()}
        points = SurfacePoints(len(keep), uv=a["uv"], p=a["p"], s=a["s"], t=a["t"], n=a["n"])
        f = bsdf.eval_arrays(points, a["view"], a["light"])
        if f.shape[1] == 1:
            f = np.repeat(f, 3, axis=1)
        radiance = f * a["weight"]
        index = pixel[np.asarray(keep)]
        image = np.stack([np.bincount(index, radiance[:, c], minlength=height * width) for c in range(channels)],
                         axis=-1)
    return (image / spp).reshape(height, width, channels)


def render_scene(scene, *, shader: str = "im-lod", spp: int | None = None, seed: int | None = None,
                 variant: str | None = None, material=None, wavefront: bool | None = None):
    """Render ``scene`` in Mitsuba 3 with the fabric ``clothlab render --shader shader`` would use
    (:func:`clothlab.mitsuba.material.material_from_scene`, or ``material``); returns a
    :class:`clothlab.render.RenderResult` (image (H, W, 3) linear; timings: ``setup`` (material and scene
    load), ``render``, ``total``; stats: the variant, plugin model calls and lanes per call).

    ``wavefront`` (scalar variants; default there): :func:`_render_wavefront` - Mitsuba's scalar ray queries
    per sample, the plugin's shading in one call - instead of ``mi.render`` (one plugin call per sample,
    ~1.5 ms each); ``False`` uses ``mi.render``.  JIT variants always use ``mi.render`` (already batched)."""
    from clothlab.mitsuba import use_variant
    from clothlab.mitsuba.material import material_from_scene
    from clothlab.mitsuba.plugin import add_material, forget_material
    from clothlab.render.render import RenderResult, _check
    from clothlab.render.scene import check_render_memory

    spp = scene.spp if spp is None else spp
    _check("im-lod", spp)
    if spp != scene.spp:
        check_render_memory(scene.camera.resolution, spp, 3, source=scene.source)
    seed = scene.seed if seed is None else seed
    start = time.perf_counter()
    variant = use_variant(variant)
    import drjit as dr
    import mitsuba as mi

    material = material if material is not None else material_from_scene(scene, shader)
    if len(material.channels) not in (1, 3):
        raise ConfigError(f"the Mitsuba bridge renders 1 or 3 channels, the fabric has {list(material.channels)}",
                          path=scene.source, field="fabric.channels")
    key = add_material(material)
    try:
        mscene = mi.load_dict(scene_dict(scene, key, spp=spp, seed=seed))
        bsdf = mscene.shapes()[0].bsdf()
        t_setup = time.perf_counter()
        batched = variant.startswith("scalar") and wavefront is not False
        if batched:
            pixels = _render_wavefront(mscene, scene, spp, seed, bsdf)
        else:
            image = mi.render(mscene, spp=spp, seed=seed)
            dr.eval(image)
            pixels = np.array(image, dtype=np.float64)
        t_render = time.perf_counter()
    finally:
        forget_material(key)
    if len(material.channels) == 1:
        pixels = pixels[..., :1]
    calls, lanes = getattr(bsdf, "calls", 0), getattr(bsdf, "lanes", 0)
    timings = {"setup": t_setup - start, "render": t_render - t_setup, "shading": t_render - t_setup,
               "total": t_render - start}
    stats = {"variant": variant, "wavefront": bool(batched), "plugin_calls": int(calls), "plugin_lanes": int(lanes),
             "lanes_per_call": lanes / calls if calls else 0.0, "policy": material.policy, "kind": material.kind}
    return RenderResult(image=pixels, coverage=_coverage(scene, spp, seed), channels=tuple(material.channels),
                        shader=f"mitsuba:{shader}", spp=int(spp), timings=timings, stats=stats,
                        exposure=scene.exposure,
                        metadata={"scene": scene.source or "", "renderer": "mitsuba", "variant": variant,
                                  "shader": shader, "spp": int(spp), "lod_f0": scene.lod.f0, "lod_f1": scene.lod.f1})


def render_to_files(scene_path, output_stem, *, shader: str = "im-lod", spp: int | None = None,
                    variant: str | None = None, force: bool = False):
    """:func:`clothlab.render.render_to_files` with Mitsuba 3 as the renderer: ``<stem>.exr`` and ``.png``;
    refuses existing outputs unless ``force`` (checked before rendering).  Returns (result, EXR, PNG)."""

    from clothlab.render import load_scene, output_stem_checked, save_render

    stem = output_stem_checked(output_stem, force)
    result = render_scene(load_scene(scene_path), shader=shader, spp=spp, variant=variant)
    exr, png = save_render(result, stem, force=force)
    return result, exr, png
