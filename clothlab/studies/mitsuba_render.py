"""Bench section ``mitsuba``: the same scene rendered by ``clothlab render`` and by Mitsuba 3 through the clothlab
plugin, side by side in one run (wall time, parity: mean and p99 of the per-pixel relative difference), and
Mitsuba's chi-square test of the plugin's sampler per model kind and incident angle (docs/mitsuba.md).  Skipped
(with a line saying so) when Mitsuba is not installed."""

from __future__ import annotations

import time

import numpy as np

ANGLES = (0.0, 30.0, 60.0, 80.0, 87.0)


def _scene(position, resolution, spp, fov=30.0, light=None):
    from clothlab.render import scene_from_dict

    return scene_from_dict({
        "patch": {"shape": "flat", "size_mm": [2000, 2000], "tile_mm": [1.0, 2.0], "warp_angle_deg": 20},
        "camera": {"position": list(position), "look_at": [0, 0, 0], "fov_deg": fov, "resolution": list(resolution)},
        "light": light or {"type": "directional", "direction": [0.3, -0.2, 1], "intensity": 1.0},
        "fabric": {"weave": "preset:cotton-denim"}, "render": {"spp": spp}}, base_dir=".")


def _parity(scene, shader, variant, repeats: int = 3, wavefront=None):
    """Both renderers on ``scene``: the least wall time of ``repeats`` renders each (after a 1-spp warm-up, so
    compilation is not timed), and the per-pixel relative difference over fully covered pixels."""
    from clothlab.mitsuba.scene import render_scene
    from clothlab.render import render

    render(scene, shader=shader, spp=1)
    render_scene(scene, shader=shader, spp=1, variant=variant, wavefront=wavefront)
    t_clothlab, t_mitsuba = float("inf"), float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        a = render(scene, shader=shader)
        t_clothlab = min(t_clothlab, time.perf_counter() - t)
        b = render_scene(scene, shader=shader, variant=variant, wavefront=wavefront)
        if b.timings["total"] < t_mitsuba:
            t_mitsuba, t_render = b.timings["total"], b.timings["render"]
    mask = a.coverage >= 1.0
    rel = np.abs(b.image[mask] - a.image[mask]) / np.maximum(np.abs(a.image[mask]), 1e-30)
    width, height = scene.camera.resolution
    return {"shader": shader, "variant": variant, "spp": scene.spp, "size": f"{width}x{height}",
            "light": scene.light.type, "wavefront": bool(b.stats.get("wavefront")),
            "clothlab_seconds": t_clothlab, "mitsuba_seconds": t_mitsuba, "mitsuba_render_seconds": t_render,
            "plugin_calls": b.stats["plugin_calls"], "repeats": repeats,
            "mean_relative": float(rel.mean()), "p99_relative": float(np.percentile(rel, 99))}


def mitsuba_study(quick: bool) -> dict:
    from clothlab.mitsuba import available, use_variant

    if not available():
        return {"skipped": 'mitsuba is not installed (pip install "clothlab[mitsuba]")'}
    from clothlab.errors import ConfigError

    try:
        variant = use_variant("llvm_ad_rgb")
    except ConfigError as exc:
        variant, note = "scalar_rgb", str(exc)
    else:
        note = ""
    big = not quick and variant != "scalar_rgb"
    cases = [(_scene([0, -300, 300], (48, 36) if big else (16, 12), 4), "im-reflectance"),
             (_scene([0, -6, 6], (48, 36) if big else (16, 12), 256 if big else 64, fov=30.0 if big else 10.0),
              "im-texture"),
             (_scene([0, -60, 60], (48, 36) if big else (16, 12), 16), "im-lod"),
             (_scene([0, -8, 5], (48, 36) if big else (16, 12), 256 if big else 64, fov=30.0 if big else 10.0),
              "im-lod"),  # footprint 0.1-0.5 tile: texture, blend and reflectance pixels
             (_scene([0, -60, 60], (48, 36) if big else (16, 12), 16,
                     light={"type": "point", "position": [10, -20, 50], "intensity": 0.002}), "im-lod")]
    rows = [_parity(scene, shader, variant, repeats=3 if big else 1) for scene, shader in cases]
    # the scalar variant: mi.render (one plugin call per sample) on a small scene, and the scalar wavefront
    rows.append(_parity(_scene([0, -60, 60], (16, 12), 4), "im-lod", "scalar_rgb", repeats=1, wavefront=False))
    rows.append(_parity(cases[1][0], "im-texture", "scalar_rgb", repeats=3 if big else 1))
    chi2 = []
    if variant != "scalar_rgb":
        from clothlab.mitsuba.checks import chi2_check, plugin_dict
        from clothlab.models.registry import MODEL_KINDS

        use_variant(variant)  # back from the scalar row

        angles = ANGLES if big else (0.0, 87.0)
        for kind in MODEL_KINDS:
            for theta in angles:
                r = chi2_check(plugin_dict(preset="cotton-denim", kind=kind), theta,
                               sample_count=200_000 if big else 20_000, test_count=len(MODEL_KINDS) * len(angles))
                chi2.append({"kind": kind, "theta_deg": theta, "passed": r["passed"], "p_value": r["p_value"],
                             "sample_count": r["sample_count"]})
    return {"variant": variant, "variant_note": note, "parity": rows, "chi2": chi2}


def run(context) -> dict:
    return mitsuba_study(context.quick)


def lines(result: dict) -> list[str]:
    out = ["== mitsuba =="]
    if "skipped" in result:
        return out + [f"  skipped: {result['skipped']}"]
    out.append(f"  variant {result['variant']}" + (f" ({result['variant_note']})" if result["variant_note"] else ""))
    for r in result["parity"]:
        variant = r["variant"] + (" wavefront" if r.get("wavefront") else "")
        out.append(f"  {r['shader']:<15} {variant:<22} {r.get('light', 'directional'):<11} {r['size']} px "
                   f"{r['spp']:>4} spp: "
                   f"clothlab render {r['clothlab_seconds']:.2f} s, "
                   f"Mitsuba {r['mitsuba_seconds']:.2f} s (render {r['mitsuba_render_seconds']:.2f} s, "
                   f"{r['plugin_calls']} plugin calls); per pixel mean {100 * r['mean_relative']:.2f} %, "
                   f"p99 {100 * r['p99_relative']:.2f} %")
    if result["chi2"]:
        kinds = dict.fromkeys(r["kind"] for r in result["chi2"])
        for kind in kinds:
            cells = [f"{r['theta_deg']:g} deg {'pass' if r['passed'] else 'FAIL'} (p {r['p_value']:.3f})"
                     for r in result["chi2"] if r["kind"] == kind]
            out.append(f"  chi2 {kind:<18} " + ", ".join(cells))
    return out
