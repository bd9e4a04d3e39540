"""``clothlab fit-btf STACK SOURCE -o DIR``: fit the texture parameters (tile offset, rotation, w/l ratio,
hWidth, noise) to a BTF stack, the BRDF parameters of a reflectance fit held (Irawan & Marschner sec. 4.2,
7.2)."""

from __future__ import annotations

import math
from pathlib import Path

from clothlab.cli.options import LazyText, add_force, add_output, names_of

TEXTURE_FREE = names_of("clothlab.texfit.fit", "TEXTURE_FREE")
REFINABLE = names_of("clothlab.texfit.fit", "REFINABLE")


def add_parser(sub):
    p = sub.add_parser("fit-btf", help="fit the texture parameters (tile offset, rotation, w/l ratio, hWidth, "
                                       "noise) to a BTF stack, the BRDF parameters from a reflectance fit held",
                       description="Fit the texture parameters to a BTF stack; writes texfit.json, errors.json "
                                   "and tiles.png into the output directory.")
    p.add_argument("stack", type=Path, help="BTF stack directory (names with angles, or a manifest)")
    p.add_argument("source", type=Path, help="the reflectance fit directory (fits/<name>) or a fabric.yaml")
    add_output(p, "output directory (texfit.json, errors.json, tiles.png)", metavar="DIR", required=True)
    p.add_argument("--free", help=LazyText(lambda: (
        f"texture parameters to fit, comma-separated from {', '.join(TEXTURE_FREE())} (default: all); the others "
        "stay at offset 0, rotation 0, ratio 1, the source's hWidth")))
    p.add_argument("--refine", default="", help=LazyText(lambda: (
        f"BRDF parameters to refine too, comma-separated from {', '.join(REFINABLE())} (e.g. warp.umax,weft.umax);"
        " starts from the held optimum and keeps the better (default: none, all held)")))
    p.add_argument("--crop", metavar="X0,Y0,W,H",
                   help="fit a crop of every image: x0,y0,width,height in pixels (x = column, y = row from the top)")
    add_force(p, "output directory")
    return p


def run(args) -> int:
    from clothlab.texfit.fit import fit_btf

    kwargs = {} if args.free is None else {"free": args.free}
    result = fit_btf(args.stack, args.source, args.output, force=args.force, refine=args.refine, crop=args.crop,
                     **kwargs)
    print(present_texture_fit(result, args.stack, args.output))
    return 0 if math.isfinite(result.objective) else 1


def present_texture_fit(result, stack_dir, out_dir) -> str:
    """One line per stage of a texture fit: the fitted texture parameters, noise amplitude, tile-average
    error percentiles, evaluations and time; the refined BRDF parameters when there was a refine stage."""
    overall = result.errors["overall"]["tile"]
    lines = [f"texture fit of {stack_dir} ({len(result.files)} images) with the BRDF of {result.source}: offset "
             f"({result.offset[0]:.4f}, {result.offset[1]:.4f}) tiles, rotation {result.rotation:.3f} deg, "
             f"ratio {result.ratio:.3f}, hWidth {result.hwidth:.3f}; noise amplitude "
             f"{result.noise['amplitude']:.2f}; tile-average relative error p50 {overall['p50']:.3g}, p80 "
             f"{overall['p80']:.3g}; {result.nevals} evaluations, {result.seconds:.1f} s -> {out_dir}"]
    if result.refine_stage is not None:
        r = result.refine_stage
        changes = ", ".join(f"{k} {r['start'][k]:g} -> {v:.4g}" for k, v in r["refined_values"].items())
        lines.append(f"  refined {changes}: objective {r['refined_objective']:.4g} vs {r['held_objective']:.4g} "
                     f"held; kept the {r['kept']} optimum")
    return "\n".join(lines)
