"""Render benchmark: the receding plane (issue 4 "must show") and the IM and Kang shaders timed in one scene.

:func:`render_benchmark` renders a flat cotton-denim patch seen at 45 deg elevation from a sequence of
distances.  Per distance: time and relative L1 error (against the supersampled texture-level shader of the
same family, 64 stratified samples) of im-lod, im-texture (the always-texture shader), kang-lod and
kang-texture at 4 samples per pixel, the fraction of pixels that ran the texture model, the footprint range.
The stated bound: the LoD image's error stays at or below ERROR_BOUND at every distance.
"""

from __future__ import annotations

from clothlab.render.render import compare_lod
from clothlab.render.scene import scene_from_dict

#: bound on the relative L1 error of im-lod against the supersampled reference, at every distance
ERROR_BOUND = 0.15
SHADERS = ("im-lod", "im-texture", "kang-lod", "kang-texture")

RECEDING_PLANE = {
    "patch": {"shape": "flat", "size_mm": [4000, 4000], "tile_mm": [1.0, 2.0], "warp_angle_deg": 0},
    "camera": {"position": [0, -40, 40], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 30,
               "resolution": [96, 72]},
    "light": {"type": "directional", "direction": [0.3, -0.2, 1.0], "intensity": 1.0},
    "fabric": {"weave": "preset:cotton-denim", "seed": 0},
    "render": {"spp": 4, "seed": 1},
}


def receding_plane_scene(resolution=(96, 72)):
    """The benchmark scene (the same as measurements/scenes/receding_plane.yaml) at ``resolution``."""
    data = {**RECEDING_PLANE, "camera": {**RECEDING_PLANE["camera"], "resolution": list(resolution)}}
    return scene_from_dict(data, source=None)


def render_benchmark(quick: bool = False) -> dict:
    """Receding-plane table (printed) and figures: {'rows': [...], 'error_bound', 'within_bound',
    'lod_time_falls', 'settings'}; ``quick``: a smaller image and fewer distances (a few seconds)."""
    resolution = (32, 24) if quick else (96, 72)
    distances = (10.0, 80.0, 640.0) if quick else (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0)
    spp, reference_spp = 4, (16 if quick else 64)
    scene = receding_plane_scene(resolution)
    rows = compare_lod(scene, distances, shaders=SHADERS, spp=spp, reference_spp=reference_spp,
                       repeats=1 if quick else 3)
    lod_times = [row["im-lod"]["shading_seconds"] for row in rows]
    result = {
        "settings": {"scene": "receding plane, cotton denim, tile 1 x 2 mm, 45 deg elevation",
                     "resolution": list(resolution), "spp": spp, "reference_spp": reference_spp,
                     "lod_f0_tiles": scene.lod.f0, "lod_f1_tiles": scene.lod.f1},
        "rows": rows,
        "error_bound": ERROR_BOUND,
        "within_bound": all(row["im-lod"]["relative_error"] <= ERROR_BOUND for row in rows),
        "lod_time_falls": lod_times[-1] < lod_times[0],
    }
    print_render_benchmark(result)
    return result


def print_render_benchmark(result: dict) -> None:
    s = result["settings"]
    print(f"\nRender LoD: {s['scene']}; {s['resolution'][0]} x {s['resolution'][1]} px, {s['spp']} spp; "
          f"reference: texture level at {s['reference_spp']} spp; f0 = {s['lod_f0_tiles']:g}, "
          f"f1 = {s['lod_f1_tiles']:g} tiles")
    print("times: shading seconds (total render seconds in parentheses); err: relative L1 vs the reference; "
          f"'ref' = the always-texture image antialiased to the reference ({s['reference_spp']} spp)")
    print(f"{'dist mm':>8} {'footprint':>13} | {'t LoD':>14} {'t texture':>14} {'t ref':>6} {'err LoD':>7} "
          f"{'err tex':>7} {'tex px':>6} | {'t KangLoD':>9} {'t KangTex':>9} {'err KLoD':>8} {'err KTex':>8}")
    for row in result["rows"]:
        lod, tex, klod, ktex = (row[k] for k in SHADERS)
        print(f"{row['distance_mm']:8.0f} {row['footprint_min_tiles']:6.3f}-{row['footprint_max_tiles']:<6.3g} | "
              f"{lod['shading_seconds']:6.3f} ({lod['seconds']:5.3f}) {tex['shading_seconds']:6.3f} "
              f"({tex['seconds']:5.3f}) {row['im_reference_seconds']:6.2f} {lod['relative_error']:7.3f} "
              f"{tex['relative_error']:7.3f} {100 * lod['texture_pixel_fraction']:5.1f}% | "
              f"{klod['shading_seconds']:9.3f} {ktex['shading_seconds']:9.3f} "
              f"{klod['relative_error']:8.3f} {ktex['relative_error']:8.3f}")
    print(f"LoD error <= {result['error_bound']:g} at every distance: {result['within_bound']}; "
          f"LoD shading time falls with distance: {result['lod_time_falls']}")
