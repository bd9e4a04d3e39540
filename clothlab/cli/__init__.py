"""The ``clothlab`` command line: fit, report, eval, simulate, bench, check.

Heavy imports live inside the commands so that ``clothlab --help`` stays fast.  A user mistake
(:class:`clothlab.errors.ClothlabError`) prints one line ``clothlab: error: ...`` and exits with code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

from clothlab import __version__
from clothlab.errors import ClothlabError, ConfigError, ResultExistsError


def _add_quadrature_overrides(p):
    p.add_argument("--rule", choices=("trapezoid", "gauss", "support", "adaptive"),
                   help="quadrature rule (overrides fabric.yaml model.quadrature.rule)")
    p.add_argument("--nodes", type=int, help="quadrature nodes (per piece for support/adaptive)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="clothlab",
        description="Measure, fit and report the appearance of woven cloth (Irawan-Marschner, Kang).")
    parser.add_argument("--version", action="version", version=f"clothlab {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("fit", help="fit a model to a measurement as configured in fabric.yaml -> fits/<name>/")
    p.add_argument("configs", nargs="+", type=Path, metavar="fabric.yaml")
    p.add_argument("--force", action="store_true", help="replace an existing fits/<name>/")
    p.add_argument("--max-evals", type=int, help="optimiser evaluation budget (overrides the yaml)")
    p.add_argument("--seed", type=int, help="optimiser seed (overrides the yaml)")
    p.add_argument("--fits-dir", type=Path, help="write under this directory instead of output.fits")
    p.add_argument("--report", action="store_true", help="also build reports/<name>/ afterwards")
    p.add_argument("--posterior", action="store_true",
                   help="also sample the posterior with emcee (fit.posterior settings, else the defaults); an "
                        "interrupted run continues from its checkpoint when the same command is run again")
    p.add_argument("--no-posterior", action="store_true", help="skip the posterior even if fabric.yaml asks for it")
    p.add_argument("--cv", type=int, metavar="K", help="k-fold cross-validated error percentiles (K >= 2)")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    _add_quadrature_overrides(p)

    p = sub.add_parser("report", help="HTML report of fits (default: every fit under ./fits)")
    p.add_argument("fits", nargs="*", type=Path, metavar="fits/<name>")
    p.add_argument("--out", type=Path, default=Path("reports"), help="reports directory (default: reports)")
    p.add_argument("--force", action="store_true", help="replace existing reports")
    p.add_argument("--comparison-name", default="comparison", help="name of the multi-fit comparison report")

    p = sub.add_parser("eval", help="evaluate a fitted or configured model at the directions of a CSV")
    p.add_argument("source", type=Path, help="a fit directory (fits/<name>) or a fabric.yaml")
    p.add_argument("directions", type=Path, help="CSV with theta_i, phi_i, theta_o, phi_o in degrees")
    p.add_argument("-o", "--output", type=Path, help="output CSV (default: stdout)")
    p.add_argument("--components", action="store_true", help="add one column per component and channel")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    _add_quadrature_overrides(p)

    p = sub.add_parser("simulate", help="virtual gonioreflectometer: model + paper sampling + noise -> table")
    p.add_argument("source", nargs="?", help="preset:<name>, a .wv file or a fabric.yaml")
    p.add_argument("-o", "--output", type=Path, help="output table (clothlab CSV)")
    p.add_argument("--paper-examples", type=Path, metavar="DIR",
                   help="write the six simulated paper-fabric example sets into DIR")
    p.add_argument("--btf", type=Path, metavar="DIR",
                   help="write a simulated BTF stack (texture model, EXR + manifest) of the source into DIR "
                        "(source: preset:<name>, a fabric.yaml or a fit directory)")
    p.add_argument("--btf-directions", type=int, default=16, help="(light, view) pairs of the BTF stack")
    p.add_argument("--btf-size", type=int, default=64, help="image size in pixels")
    p.add_argument("--btf-tiles", type=float, default=4.0, help="weave tiles across an image")
    p.add_argument("--btf-offset", default="0.25,0.4", help="tile offset u0,v0 in tiles")
    p.add_argument("--kd", help="diffuse albedo per channel, e.g. 0.2,0.1,0.1")
    p.add_argument("--ks-warp", help="warp specular albedo per channel")
    p.add_argument("--ks-weft", help="weft specular albedo per channel")
    p.add_argument("--channels", default="R,G,B",
                   help="channel names (default R,G,B; with --btf the source's own when it has coefficients)")
    p.add_argument("--noise-mult", type=float, default=0.0, help="multiplicative log-normal sigma (0.05 = 5 %%)")
    p.add_argument("--noise-add", type=float, default=0.0, help="additive Gaussian sigma in 1/sr")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true")
    _add_quadrature_overrides(p)

    p = sub.add_parser("bench", help="speed and accuracy figures, measured side by side in one run")
    p.add_argument("--quick", action="store_true", help="a reduced run (seconds instead of minutes)")
    p.add_argument("--json", type=Path, help="also write the figures as JSON")
    p.add_argument("--figures", type=Path, help="directory for the benchmark plots and HTML page (as --report)")
    p.add_argument("--sections", help="comma-separated subset of sections to run")
    p.add_argument("--report", type=Path, metavar="DIR", help="also write an HTML page of the figures into DIR")
    p.add_argument("--data", type=Path, metavar="DIR",
                   help="directory holding measurements/<fabric>/ and fits/<fabric>/ (e.g. the repository root); "
                        "default: the example measurements regenerated into a temporary directory, no saved fits")

    p = sub.add_parser("fit-btf", help="fit the texture parameters (tile offset, rotation, w/l ratio, hWidth, "
                                       "noise) to a BTF stack, the BRDF parameters from a reflectance fit held")
    p.add_argument("stack", type=Path, help="BTF stack directory (names with angles, or a manifest)")
    p.add_argument("source", type=Path, help="the reflectance fit directory (fits/<name>) or a fabric.yaml")
    p.add_argument("-o", "--output", type=Path, required=True, help="output directory (texfit.json, tiles.png)")
    p.add_argument("--free", default="offset,rotation,ratio,hwidth",
                   help="texture parameters to fit, comma-separated from offset, rotation, ratio, hwidth "
                        "(default: all); the others stay at offset 0, rotation 0, ratio 1, the source's hWidth")
    p.add_argument("--refine", default="",
                   help="BRDF parameters to refine too, comma-separated (e.g. warp.umax,weft.umax; from alpha, "
                        "beta, delta, warp./weft. psi, umax, kappa); starts from the held optimum and keeps the "
                        "better (default: none, all held)")
    p.add_argument("--crop", metavar="X0,Y0,W,H",
                   help="fit a crop of every image: x0,y0,width,height in pixels (x = column, y = row from the top)")
    p.add_argument("--force", action="store_true")

    p = sub.add_parser("render", help="render a scene (flat or cylindrical cloth patch) to EXR and PNG, with the "
                                      "texture model only where the pixel footprint resolves yarns")
    p.add_argument("scene", type=Path, help="scene YAML (see measurements/scenes/receding_plane.yaml)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output path stem (writes STEM.exr, STEM.png)")
    p.add_argument("--shader", default="im-lod",
                   choices=("im-lod", "im-texture", "im-reflectance", "kang-lod", "kang-texture"))
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's render.spp)")
    p.add_argument("--force", action="store_true")

    p = sub.add_parser("calibrate", help="colour correction from a photographed ColorChecker (colour-science)")
    p.add_argument("chart", type=Path, help="CSV with R, G, B linear camera values per patch (24 rows)")
    p.add_argument("--method", default="Cheung 2004", choices=("Cheung 2004", "Finlayson 2015", "Vandermonde"))
    p.add_argument("--degree", type=int, help="root-polynomial / Vandermonde degree")
    p.add_argument("--apply", type=Path, metavar="TABLE", help="correct this measurement table")
    p.add_argument("-o", "--output", type=Path, help="corrected table (with --apply)")
    p.add_argument("--report", type=Path, metavar="DIR", help="write a page with delta E 2000 before / after")
    p.add_argument("--force", action="store_true")

    p = sub.add_parser("check", help="numerical stability study: extreme inputs, reciprocity, continuity, stiff fits")
    p.add_argument("--full", action="store_true", help=">= 10^6 configurations and the stiff-fit study (minutes)")
    p.add_argument("--json", type=Path, help="also write the findings as JSON")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--figures", type=Path, help="directory for plots")
    p.add_argument("--report", type=Path, metavar="DIR", help="also write an HTML page of the findings into DIR")
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        with _geometry_warnings_to_stderr():
            return COMMANDS[args.command](args)
    except ClothlabError as exc:
        print(f"clothlab: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("\nclothlab: interrupted", file=sys.stderr)
        return 130


@contextlib.contextmanager
def _geometry_warnings_to_stderr():
    """A GeometryWarning (e.g. a segment violating w sin(umax) < l, sec. 5.3) reaches the user as one
    'clothlab: warning: ...' line per distinct message, however often the model raises it."""
    import warnings

    from clothlab.errors import GeometryWarning

    seen = set()
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, GeometryWarning):
            return previous(message, category, filename, lineno, file, line)
        if str(message) not in seen:
            seen.add(str(message))
            print(f"clothlab: warning: {message}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("always", GeometryWarning)
        warnings.showwarning = show
        yield


# ---------------------------------------------------------------------------------------------- fit

class _Progress:
    def __init__(self, name: str, budget: int, quiet: bool):
        self.name, self.budget, self.quiet = name, budget, quiet
        self.last = 0.0

    def __call__(self, row):
        if self.quiet:
            return
        now = time.perf_counter()
        if now - self.last < 0.2:
            return
        self.last = now
        print(f"\r  {self.name}: [{row.stage:6s}] evaluation {row.index:5d}/{self.budget}  "
              f"best {row.best:.4e}  {row.time:6.1f} s", end="", file=sys.stderr, flush=True)

    def done(self):
        if not self.quiet:
            print(file=sys.stderr)


def cmd_fit(args) -> int:
    from dataclasses import replace

    from clothlab.config import PosteriorConfig, apply_overrides, load_config
    from clothlab.fit.runner import run_fit, save_fit

    if args.cv is not None and args.cv < 2:
        raise ConfigError(f"--cv needs at least 2 folds, got {args.cv}", field="--cv")
    configs = []
    for path in args.configs:
        cfg = apply_overrides(load_config(path), rule=args.rule, nodes=args.nodes, max_evals=args.max_evals,
                              seed=args.seed)
        if args.cv is not None:
            cfg = replace(cfg, fit=replace(cfg.fit, cv_folds=args.cv))
        if args.no_posterior:
            cfg = replace(cfg, fit=replace(cfg.fit, posterior=None))
        elif args.posterior and cfg.fit.posterior is None:
            walkers = max(32, 2 * len(cfg.fit.free) + 2)
            cfg = replace(cfg, fit=replace(cfg.fit, posterior=PosteriorConfig(walkers=walkers)))
        dest = (args.fits_dir or cfg.output.fits) / cfg.name
        if dest.exists() and not args.force:
            raise ResultExistsError(f"{dest} exists; pass --force to replace it", path=dest)
        configs.append(cfg)
    for cfg in configs:
        progress = _Progress(cfg.name, cfg.fit.optimizer.max_evals + cfg.fit.optimizer.polish_evals, args.quiet)
        result = run_fit(cfg, progress=progress, fits_dir=args.fits_dir, posterior_progress=not args.quiet)
        progress.done()
        out = save_fit(result, force=args.force, fits_dir=args.fits_dir)
        print(format_summary(result, out))
        if args.report:
            from clothlab.report.build import build_report

            report = build_report(out, cfg.output.reports, force=args.force, percentiles=cfg.report.percentiles)
            print(f"  report: {report / 'index.html'}")
    return 0


def format_summary(result, out) -> str:
    """The short summary printed after a fit: parameters, coefficients, error percentiles, time."""
    p = result.problem
    lines = [f"{result.name}: {p.model.kind} fit of {p.measurement.n} directions x {len(p.measurement.channels)} "
             f"channels -> {out}"]
    for name in p.free:
        spec = p.model.params[name]
        i = p.free.index(name)
        flag = ("  (at lower bound)" if result.optimum.at_lower[i] else
                "  (at upper bound)" if result.optimum.at_upper[i] else "")
        lines.append(f"  {name:12s} = {result.params[name]:10.4g} {spec.unit}{flag}")
    for name, coef in result.coefficients.items():
        lines.append(f"  {name:12s} = " + ", ".join(f"{c:.4g}" for c in coef))
    e = result.errors["overall"]
    lines.append("  relative error: " + ", ".join(
        f"{'median' if k == 'p50' else k[1:] + 'th'} {100 * e[k]:.2f} %" for k in e if k.startswith("p")))
    lines.append(f"  {int(result.optimum.nevals)} evaluations, {result.wall_time:.1f} s")
    for w in result.warnings:
        lines.append(f"  warning: {w}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- report

def cmd_report(args) -> int:
    from clothlab.report.build import build_comparison, build_report

    fits = list(args.fits)
    if not fits:
        root = Path("fits")
        fits = sorted(d for d in root.iterdir() if (d / "fit.json").is_file()) if root.is_dir() else []
        if not fits:
            raise ConfigError("no fit directories given and none found under ./fits (run `clothlab fit` first)")
    for fit_dir in fits:
        out = build_report(fit_dir, args.out, force=args.force)
        print(f"{fit_dir} -> {out / 'index.html'}")
    if len(fits) > 1:
        out = build_comparison(fits, args.out, name=args.comparison_name, force=args.force)
        print(f"comparison of {len(fits)} fits -> {out / 'index.html'}")
    return 0


# ---------------------------------------------------------------------------------------------- eval

def cmd_eval(args) -> int:
    from clothlab.fit.evaluate import evaluate_directions_file

    text = evaluate_directions_file(args.source, args.directions, components=args.components, rule=args.rule,
                                    nodes=args.nodes)
    if args.output is None:
        sys.stdout.write(text)
    else:
        from clothlab.atomic import atomic_write_text

        if args.output.exists() and not args.force:
            raise ResultExistsError(f"{args.output} exists; pass --force to overwrite it", path=args.output)
        atomic_write_text(args.output, text)
    return 0


# ---------------------------------------------------------------------------------------------- simulate

def _channel_values(text, field, n):
    import numpy as np

    try:
        values = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise ConfigError(f"expected comma-separated numbers, got {text!r}", field=field) from None
    if values.size == 1:
        values = np.repeat(values, n)
    if values.size != n or np.any(values < 0) or not np.all(np.isfinite(values)):
        raise ConfigError(f"expected {n} non-negative values (one per channel), got {text!r}", field=field)
    return values


def cmd_simulate(args) -> int:
    if args.btf is not None:
        from clothlab.simulate.btf import simulate_btf_command

        if not args.source:
            raise ConfigError("--btf needs a source: preset:<name>, a fabric.yaml or a fit directory")
        not_applicable = [flag for flag, value in (("-o/--output", args.output), ("--paper-examples",
                          args.paper_examples), ("--noise-mult", args.noise_mult or None),
                          ("--noise-add", args.noise_add or None)) if value is not None]
        if not_applicable:
            raise ConfigError(f"{' and '.join(not_applicable)} {'does' if len(not_applicable) == 1 else 'do'} not "
                              "apply to --btf: the stack is written into the --btf directory, and its noise is the "
                              "texture model's intensity noise (paper sec. 7.2.1, seeded by --seed), not the table "
                              "simulation's measurement noise", field=not_applicable[0].split("/")[-1])
        try:
            offset = tuple(float(x) for x in args.btf_offset.split(","))
        except ValueError:
            offset = ()
        if len(offset) != 2:
            raise ConfigError(f"expected u0,v0 numbers, got {args.btf_offset!r}", field="--btf-offset")
        return simulate_btf_command(args.source, args.btf, n_directions=args.btf_directions, size=args.btf_size,
                                    tile_repeats=args.btf_tiles, offset=offset, seed=args.seed, kd=args.kd,
                                    ks_warp=args.ks_warp, ks_weft=args.ks_weft,
                                    channels=None if args.channels == "R,G,B" else args.channels,
                                    rule=args.rule, nodes=args.nodes, force=args.force)
    if args.paper_examples is not None:
        from clothlab.simulate.examples import write_paper_examples

        for path in write_paper_examples(args.paper_examples, force=args.force):
            print(path)
        return 0
    if not args.source or args.output is None:
        raise ConfigError("give a source (preset:<name>, a .wv file or a fabric.yaml) and -o OUTPUT, "
                          "or --paper-examples DIR")
    from clothlab.io.table import write_table
    from clothlab.models.registry import build_model
    from clothlab.simulate.gonio import NoiseModel, simulate
    from clothlab.weave.presets import resolve_weave

    source = args.source
    params, rule, nodes, kind = {}, "trapezoid", 11, "irawan"
    if source.endswith((".yaml", ".yml")):
        from clothlab.config import load_config

        cfg = load_config(source)
        weave = resolve_weave(cfg.model.weave, cfg.base_dir)
        params, rule, nodes, kind = dict(cfg.model.params), cfg.model.quadrature.rule, cfg.model.quadrature.nodes, \
            cfg.model.kind
    else:
        weave = resolve_weave(source, Path.cwd())
    channels = tuple(c.strip() for c in args.channels.split(",") if c.strip())
    n = len(channels)
    coefficients = {"kd": _channel_values(args.kd or "0.1", "--kd", n),
                    "ks_warp": _channel_values(args.ks_warp or "0.1", "--ks-warp", n),
                    "ks_weft": _channel_values(args.ks_weft or "0.1", "--ks-weft", n)}
    model = build_model(kind, weave, (args.rule or rule, args.nodes or nodes))
    noise = NoiseModel(args.noise_mult, args.noise_add, args.seed)
    m = simulate(model, params, coefficients, channels=channels, noise=noise,
                 provenance={"sample_name": f"{weave.name} (SIMULATED)"})
    print(write_table(m, args.output, overwrite=args.force))
    return 0


def _emit(line: str) -> None:
    print(line, flush=True)


def cmd_bench(args) -> int:
    from clothlab.studies.bench import run_bench

    sections = tuple(s.strip() for s in args.sections.split(",") if s.strip()) if args.sections else None
    return run_bench(sections=sections, quick=args.quick, data_dir=args.data, output=args.report or args.figures,
                     json_path=args.json, emit=_emit)


def cmd_check(args) -> int:
    from clothlab.studies.stability import run_check_command

    # exit 1 when the sweep found a non-finite / negative value or a reciprocity violation
    return run_check_command(full=args.full, seed=args.seed, data_dir=None, output=args.report or args.figures,
                             json_path=args.json, emit=_emit)


def cmd_fit_btf(args) -> int:
    from clothlab.texfit.fit import fit_btf_command

    return fit_btf_command(args.stack, args.source, args.output, force=args.force, free=args.free,
                           refine=args.refine, crop=args.crop)


def cmd_render(args) -> int:
    from clothlab.render import render_command

    return render_command(args.scene, args.output, shader=args.shader, spp=args.spp, force=args.force)


def cmd_calibrate(args) -> int:
    from clothlab.colour.calibrate import calibrate_command

    return calibrate_command(args.chart, method=args.method, degree=args.degree, apply=args.apply,
                             output=args.output, report=args.report, force=args.force)


COMMANDS = {"calibrate": cmd_calibrate, "fit": cmd_fit, "fit-btf": cmd_fit_btf, "render": cmd_render,
            "report": cmd_report, "eval": cmd_eval, "simulate": cmd_simulate, "bench": cmd_bench,
            "check": cmd_check}


if __name__ == "__main__":
    sys.exit(main())
