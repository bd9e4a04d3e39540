"""Rendering a cloth patch with the Irawan-Marschner shaders (texture, reflectance, level of detail) and the
Kang shader (eq. 5 LoD, Algorithm 1) in the same scene: :func:`render`, :func:`save_render`,
:func:`compare_lod`, :func:`render_command` (the ``clothlab render`` command).

Only numpy is imported here; OpenImageIO and YAML are imported by the functions that use them.
"""

from __future__ import annotations

from pathlib import Path

from clothlab.render.render import RenderResult, compare_lod, render, save_render  # noqa: E402
from clothlab.render.scene import Scene, load_scene, scene_from_dict  # noqa: E402

__all__ = ["RenderResult", "Scene", "compare_lod", "load_scene", "render", "render_command", "save_render",
           "scene_from_dict"]


def render_command(scene_path, output_stem, shader: str = "im-lod", spp: int | None = None,
                   force: bool = False) -> int:
    """``clothlab render``: scene YAML -> ``<output_stem>.exr`` (linear) and ``.png`` (sRGB); prints a summary.

    ``spp`` None: the scene's render.spp.  Refuses existing outputs unless ``force`` (checked before
    rendering).  User mistakes raise :class:`~clothlab.errors.ClothlabError`; returns 0 on success.
    """
    from clothlab.errors import ResultExistsError

    stem = Path(output_stem)
    if stem.suffix.lower() in (".exr", ".png"):
        stem = stem.with_suffix("")
    existing = [p for p in (stem.parent / f"{stem.name}.exr", stem.parent / f"{stem.name}.png") if p.exists()]
    if existing and not force:
        raise ResultExistsError(f"{existing[0]} already exists; use --force to replace it", path=existing[0])
    scene = load_scene(scene_path)
    result = render(scene, shader=shader, spp=spp)
    exr, png = save_render(result, stem, force=force)
    s, t = result.stats, result.timings
    print(f"rendered {scene_path} with {shader}, {result.spp} spp, {result.image.shape[1]} x {result.image.shape[0]}"
          f" px in {t['total']:.2f} s (shading {t['shading']:.2f} s)")
    print(f"  covered pixels {s['covered_pixels']}/{s['pixels']}; texture model in "
          f"{100 * s['texture_pixel_fraction']:.1f} % of them; footprint {s['footprint_min_tiles']:.3g}.."
          f"{s['footprint_max_tiles']:.3g} tiles")
    print(f"  wrote {exr} and {png}")
    return 0
