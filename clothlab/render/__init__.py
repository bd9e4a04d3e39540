"""Rendering a cloth patch with the Irawan-Marschner shaders (texture, reflectance, level of detail) and the
Kang shader (eq. 5 LoD, Algorithm 1) in the same scene: :func:`render`, :func:`save_render`,
:func:`compare_lod`, :func:`render_to_files` (scene YAML -> EXR and PNG, as ``clothlab render`` does).

Only numpy is imported here; OpenImageIO and YAML are imported by the functions that use them.
"""

from __future__ import annotations

from pathlib import Path

from clothlab.render.render import RenderResult, compare_lod, render, save_render  # noqa: E402
from clothlab.render.scene import Scene, load_scene, scene_from_dict  # noqa: E402

__all__ = ["RenderResult", "Scene", "compare_lod", "load_scene", "render", "render_to_files", "save_render",
           "scene_from_dict"]


def output_stem_checked(output_stem, force: bool = False) -> Path:
    """The stem of a render's ``.exr`` / ``.png`` pair (a given suffix dropped); ResultExistsError when either
    exists and ``force`` is not set, before anything is rendered."""
    from clothlab.errors import ResultExistsError

    stem = Path(output_stem)
    if stem.suffix.lower() in (".exr", ".png"):
        stem = stem.with_suffix("")
    existing = [p for p in (stem.parent / f"{stem.name}.exr", stem.parent / f"{stem.name}.png") if p.exists()]
    if existing and not force:
        raise ResultExistsError(f"{existing[0]} already exists; use --force to replace it", path=existing[0])
    return stem


def render_to_files(scene_path, output_stem, shader: str = "im-lod", spp: int | None = None,
                    force: bool = False) -> tuple[RenderResult, Path, Path]:
    """Render the scene YAML ``scene_path`` to ``<output_stem>.exr`` (linear) and ``.png`` (sRGB).

    ``spp`` None: the scene's render.spp.  Refuses existing outputs unless ``force`` (checked before
    rendering).  User mistakes raise :class:`~clothlab.errors.ClothlabError`.  Returns (the render with its
    statistics and timings, EXR path, PNG path).
    """
    stem = output_stem_checked(output_stem, force)
    result = render(load_scene(scene_path), shader=shader, spp=spp)
    exr, png = save_render(result, stem, force=force)
    return result, exr, png
