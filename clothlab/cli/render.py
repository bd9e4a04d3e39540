"""``clothlab render scene.yaml [-o STEM]``: a flat or cylindrical cloth patch to EXR and PNG, the texture model
only where the pixel footprint resolves yarns.  Without ``-o`` the files are ``renders/<scene file stem>.exr``
and ``.png`` (:data:`DEFAULT_DIR`)."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import LazyText, add_force, add_output, count_type, names_of, one_of

SHADERS = names_of("clothlab.render.shade", "SHADERS")
#: Directory of the default output stem (``renders/<scene stem>``), relative to the working directory.
DEFAULT_DIR = Path("renders")


def add_parser(sub):
    p = sub.add_parser("render", help="render a scene (flat or cylindrical cloth patch) to EXR and PNG, with the "
                                      "texture model only where the pixel footprint resolves yarns",
                       description="Render a scene YAML to STEM.exr (linear) and STEM.png (sRGB).")
    p.add_argument("scene", type=Path,
                   help="scene YAML: patch, camera, light, fabric and render sections (format: clothlab.render.scene)")
    add_output(p, "output path stem (writes STEM.exr, STEM.png; default renders/<scene file stem>)", metavar="STEM")
    p.add_argument("--shader", default="im-lod", type=one_of(SHADERS, "shader"),
                   help=LazyText(lambda: f"one of {', '.join(SHADERS())} (default im-lod)"))
    p.add_argument("--spp", type=count_type(1, 1_000_000), help="samples per pixel (default: the scene's render.spp)")
    p.add_argument("--renderer", default="clothlab", choices=("clothlab", "mitsuba"),
                   help="clothlab (default) or mitsuba: Mitsuba 3 with the clothlab plugin (docs/mitsuba.md)")
    p.add_argument("--variant", help="Mitsuba variant (default: llvm_ad_rgb if it runs here, else scalar_rgb)")
    add_force(p, "STEM.exr and STEM.png")
    return p


def run(args) -> int:
    output = args.output if args.output is not None else DEFAULT_DIR / Path(args.scene).stem
    if getattr(args, "renderer", "clothlab") == "mitsuba":
        from clothlab.mitsuba.scene import render_to_files as mitsuba_render_to_files

        result, exr, png = mitsuba_render_to_files(args.scene, output, shader=args.shader, spp=args.spp,
                                                   variant=args.variant, force=args.force)
        t, s = result.timings, result.stats
        print(f"rendered {args.scene} in Mitsuba 3 ({s['variant']}, plugin policy {s['policy']}, kind {s['kind']}) "
              f"with {args.shader}, {result.spp} spp in {t['total']:.2f} s (render {t['render']:.2f} s, "
              f"{s['plugin_calls']} plugin calls)\n  wrote {exr} and {png}")
        return 0
    from clothlab.render import render_to_files

    result, exr, png = render_to_files(args.scene, output, shader=args.shader, spp=args.spp, force=args.force)
    print(present_render(args.scene, result, exr, png))
    return 0


def present_render(scene, result, exr, png) -> str:
    """What a render did: shader, samples, size, time, the share of pixels that ran the texture model, the
    footprint range in weave tiles, the files written."""
    s, t = result.stats, result.timings
    height, width = result.image.shape[:2]
    return "\n".join([
        f"rendered {scene} with {result.shader}, {result.spp} spp, {width} x {height} px in {t['total']:.2f} s "
        f"(shading {t['shading']:.2f} s)",
        f"  covered pixels {s['covered_pixels']}/{s['pixels']}; texture model in "
        f"{100 * s['texture_pixel_fraction']:.1f} % of them; footprint {s['footprint_min_tiles']:.3g}.."
        f"{s['footprint_max_tiles']:.3g} tiles",
        f"  wrote {exr} and {png}"])
