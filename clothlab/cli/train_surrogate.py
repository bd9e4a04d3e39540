"""``clothlab train-surrogate``: label footprint queries of one fabric and train the numpy surrogate of
Chen, Wang & Wang 2024 (sec. 4-5) within a CPU budget; writes the surrogate (``.npz`` + JSON), the loss
curve and held-out errors by footprint size (JSON + PNG) into ``-o DIR``."""

from __future__ import annotations

import contextlib
from pathlib import Path

from clothlab.cli.options import add_force, add_output, add_parallel, count_type, number_type
from clothlab.models.registry import PAPER_KIND  # light: the registry imports no model
from clothlab.surrogate.materials import LABEL_CHOICES

TARGET_ALIASES = {"im": PAPER_KIND}
"""Short names of ``--target`` (the kind names themselves are accepted too)."""


def target_choices() -> tuple[str, ...]:
    """``--target`` values: the aliases and the kinds that kind neural takes as targets, as registered
    (:data:`clothlab.models.neural.model.TARGET_KINDS`, each a kind of :mod:`clothlab.models.registry`)."""
    from clothlab.models.neural.model import TARGET_KINDS
    from clothlab.models.registry import MODEL_KINDS

    return tuple(TARGET_ALIASES) + tuple(k for k in TARGET_KINDS if k in MODEL_KINDS)


def target_kind(target: str) -> str:
    """The model kind of a ``--target`` value."""
    return TARGET_ALIASES.get(target, target)


def add_parser(sub):
    p = sub.add_parser("train-surrogate", help="train the neural footprint surrogate of one fabric",
                       description="Label footprint queries (Table 2 sampling of Chen, Wang & Wang 2024) and "
                                   "train the numpy encoder/decoder surrogate within a CPU budget.")
    p.add_argument("source", help="preset:<name>, pattern:<name>, a .wv file or a fabric.yaml; several weaves "
                                  "separated by commas (e.g. pattern:plain,pattern:twill-3x3): one network over the "
                                  "materials of all of them")
    add_output(p, "output directory (data, checkpoint, surrogate.npz/json, training.json, PNGs)", metavar="DIR")
    p.add_argument("--target", choices=target_choices(), default="im",
                   help="the model whose footprint averages are learnt (default im: Irawan-Marschner texture)")
    p.add_argument("--budget", type=number_type(0.01, 1e6), default=5.0,
                   help="CPU-minutes for labelling and training (default 5)")
    p.add_argument("--resume", action="store_true", help="continue a run in DIR (its data and checkpoint)")
    p.add_argument("--labels", choices=LABEL_CHOICES, default="mc",
                   help="label source: mc (default: stratified MC of the texture model over the part of the "
                        "footprint that is not whole tiles, the rest exact), sat (summed-area tables of "
                        "clothlab.footprint: one table per direction pair, and each query here has its "
                        "own, so slow), model (the reflectance model, footprint-independent)")
    p.add_argument("--samples", type=count_type(1, 1_000_000), default=64,
                   help="MC samples per query for mc labels (default 64)")
    p.add_argument("--pairs", type=count_type(1, 100_000), default=64,
                   help="direction pairs per footprint (default 64)")
    p.add_argument("--width", type=count_type(4, 4096), default=64, help="decoder width (default 64)")
    p.add_argument("--spatial", type=count_type(4, 4096), default=32, help="spatial feature width (default 32)")
    p.add_argument("--seed", type=count_type(0, 2**32 - 1), default=0, help="data and initialisation seed (default 0)")
    p.add_argument("--small-sizes", type=count_type(0, 1000), default=0, metavar="N",
                   help="extra footprint sizes per centre, log-stratified in 0.01-0.12 tile (default 0: Table 2)")
    p.add_argument("--row-centres", action="store_true",
                   help="every query its own footprint centre in its grid cell (default: one centre per cell, "
                        "Table 2)")
    p.add_argument("--yarn-bins", type=count_type(0, 256), default=0, metavar="N",
                   help="one-blob bins of the yarn-local position features (default 0: none, as the paper)")
    p.add_argument("--residual", action="store_true",
                   help="the network predicts a correction over the reflectance model in the loss space of eqs. "
                        "9-11 (g = T(R) + net): whole-tile footprints become exact (default: off, as the paper)")
    p.add_argument("--residual-input", action="store_true",
                   help="also give T(R) of the reflectance model to the angular decoder as an input")
    p.add_argument("--highlight-scale", type=number_type(1e-6, 1e6), default=None, metavar="X",
                   help="weight each specular loss term by 1 + (label / X)^2 (X in 1/sr): strong highlights count "
                        "as in linear space (default: off, the log loss of eqs. 9-11 as the paper)")
    p.add_argument("--probe-points", type=count_type(0, 8), default=0, metavar="N",
                   help="give the decoder the noise-free texture at the N x N midpoints of each footprint (N = 1: its "
                        "centre) as an input, which locates the yarn highlights in small footprints; each query then "
                        "costs N^2 texture evaluations more (default 0: none, as the paper)")
    p.add_argument("--mirror-share", type=number_type(0.0, 0.95), default=0.0, metavar="F",
                   help="draw wo near the mirror direction of wi (within 0.3 in x, y) for this share of the labelled "
                        "rows, where the yarn highlights are; evaluation pairs stay uniform (default 0: Table 2)")
    p.add_argument("--reciprocal", action="store_true",
                   help="train on each eligible row with wi and wo swapped half the time (Helmholtz reciprocity: the "
                        "same label), never on a held-out direction pair; needs a reciprocal model (checked) "
                        "(default: off, as the paper)")
    p.add_argument("--vary", action="append", default=[], metavar="NAME=LO:HI:N",
                   help="a multi-material network: N values of parameter NAME from LO to HI (geometric for "
                        "log-declared parameters), repeatable (the grid of all combinations); the midpoints "
                        "between neighbouring values are labelled too and held out (unseen materials)")
    p.add_argument("--draw", type=int, default=None, metavar="N",
                   help="a multi-material network: N parameter sets per weave drawn at random (seeded by --seed) "
                        "from Table 2 of Chen, Wang & Wang 2024 (--target surface: per yarn type psi in {-30, 0, "
                        "30} deg, umax U(15, 45) deg, alpha U(0.1, 1), beta U(0, 2)); a seeded --heldout-share of "
                        "each weave's are labelled and held out (unseen materials)")
    p.add_argument("--heldout-share", type=float, default=0.2, metavar="F",
                   help="with --draw: the share of each trained weave's materials held out (default 0.2; at least "
                        "one when N >= 2)")
    p.add_argument("--heldout-pattern", default=None, metavar="WEAVE",
                   help="a weave (e.g. pattern:twill-5x5) not in SOURCE whose materials (--draw / --vary, as the "
                        "others) are labelled and never trained on: scored apart as the unseen pattern "
                        "(metrics.heldout_pattern)")
    add_force(p, "output directory")
    add_parallel(p, "the labelling chunks (one task per chunk; identical data)")
    return p


def _model(source: str, target: str):
    from clothlab.config.build import model_from_weave
    from clothlab.surrogate.materials import tile_average_model
    from clothlab.weave.presets import resolve_weave

    kind, params = target_kind(target), {}
    if source.endswith((".yaml", ".yml")):
        from clothlab.config import load_config

        cfg = load_config(source)
        weave = resolve_weave(cfg.model.weave, cfg.base_dir)
        if cfg.model.kind == kind:
            params = dict(cfg.model.params)
    else:
        weave = resolve_weave(source, Path.cwd())
    # the network's configured model: the kind with its converged tile average (surrogate.materials)
    return weave, tile_average_model(model_from_weave(weave, kind=kind)), params


def _footprint_estimate():
    """``clothlab.footprint.footprint_components`` (the estimator of ``--labels sat``), or None without it."""
    try:
        from clothlab.footprint import footprint_components
    except ImportError:
        return None
    return footprint_components


def _weave_specs(args) -> tuple[list[str], str | None]:
    """The weave specs of SOURCE (comma-separated) and of --heldout-pattern; ConfigError naming the option
    for an empty list or a held-out weave that is also trained."""
    from clothlab.errors import ConfigError

    specs = [t.strip() for t in str(args.source).split(",")]
    if not any(specs):
        raise ConfigError("give at least one weave (preset:<name>, pattern:<name>, a .wv file or a fabric.yaml)",
                          field="source")
    if not all(specs):  # 'a,,b' or a trailing comma: an item lost, not a shorter list
        raise ConfigError(f"item {specs.index('') + 1} of the weave list {str(args.source)[:80]!r} is empty; "
                          "separate the weaves by single commas", field="source")
    held = args.heldout_pattern.strip() if args.heldout_pattern else None
    if args.heldout_pattern is not None and not held:
        raise ConfigError("give a weave, e.g. pattern:twill-5x5", field="--heldout-pattern")
    return specs, held


def _resolve(spec: str, target: str, option: str):
    """(weave, model, params) of one weave spec; a bad spec is a ConfigError naming ``option``."""
    from clothlab.errors import ConfigError

    try:
        return _model(spec, target)
    except ConfigError as exc:
        raise ConfigError(f"{spec!r}: {exc.detail}", field=option, path=exc.path) from None


def run(args) -> int:
    """Train in the run directory: a new run (or ``--force``) is built in a hidden temporary directory next to
    it and swapped into place when complete (:func:`clothlab.atomic.atomic_directory`, the fits' swap: an
    interrupted or failed run leaves the previous directory as it was); ``--resume`` continues the run in
    place under its lock (every file written atomically)."""
    lines: list[str] = []
    with contextlib.ExitStack() as held:
        code = _run(args, held, lines)
    print("\n".join(lines))  # after the swap: the files named exist
    return code


def _run_directory(held, out: Path, *, resume: bool, force: bool) -> Path:
    """The directory this run writes: ``out`` itself (locked) for ``--resume``, else the temporary directory
    of :func:`clothlab.atomic.atomic_directory` that replaces ``out`` when the ``held`` stack closes cleanly."""
    from clothlab.atomic import atomic_directory, result_lock
    from clothlab.errors import ConfigError, OutputError, ResultExistsError

    if (out.exists() or out.is_symlink()) and not out.is_dir():  # never swapped away, even with --force
        raise OutputError("exists and is not a directory; give a directory for the run", path=out)
    used = out.is_dir() and any(out.iterdir())
    if resume:
        if not (out / "materials.json").is_file():
            what = "does not exist" if not out.exists() else "holds no run (no materials.json)"
            raise ConfigError(f"nothing to resume: {out} {what}; run without --resume to start it", path=out,
                              field="--resume")
        return held.enter_context(result_lock(out))
    if used and not force:
        raise ResultExistsError(f"{out} exists; give --resume to continue it or --force to replace it", path=out)
    return held.enter_context(atomic_directory(out, force=out.exists()))


def _run(args, held, lines: list[str]) -> int:
    import json

    from clothlab.atomic import atomic_write_bytes
    from clothlab.errors import ConfigError
    from clothlab.surrogate.data import DataSpec
    from clothlab.surrogate.encodings import PATTERN_ORDER, material_vector, yarn_extent
    from clothlab.surrogate.training import TrainSpec
    from clothlab.surrogate.training_run import run_training
    from clothlab.weave.wvformat import format_wv

    if args.output is None:
        raise ConfigError("give the output directory with -o DIR", field="-o")
    specs, held_spec = _weave_specs(args)
    if args.draw is not None:
        if args.draw < 1:
            raise ConfigError(f"need N >= 1 materials per weave, got {args.draw}", field="--draw")
        if args.vary:
            raise ConfigError("give either --draw (Table 2 at random) or --vary (a grid), not both", field="--draw")
        from clothlab.models.surface.model import SurfaceModel  # Table 2 is the surface model's (Chen et al.)

        if target_kind(args.target) != SurfaceModel.kind:
            raise ConfigError(f"Table 2's ranges are the surface model's parameters; use --target "
                              f"{SurfaceModel.kind}", field="--draw")
    if not 0.0 <= args.heldout_share < 1.0:
        raise ConfigError(f"need 0 <= F < 1, got {args.heldout_share:g}", field="--heldout-share")
    resolved = [_resolve(spec, args.target, "source") for spec in specs]
    if held_spec is not None:
        resolved.append(_resolve(held_spec, args.target, "--heldout-pattern"))
    weave_names = [w.name for w, _, _ in resolved]
    if len(set(weave_names[:len(specs)])) < len(specs):
        raise ConfigError(f"a weave is named twice: {', '.join(weave_names[:len(specs)])}", field="source")
    if held_spec is not None and weave_names[-1] in weave_names[:-1]:
        raise ConfigError(f"{held_spec!r} is also a trained weave; the held-out pattern must not be trained on",
                          field="--heldout-pattern")
    several = len(resolved) > 1
    if several and args.yarn_bins:
        raise ConfigError("yarn features with several weaves are not supported yet (they need the weave of each "
                          "row); leave --yarn-bins at 0", field="--yarn-bins")
    final = Path(args.output)
    out = _run_directory(held, final, resume=args.resume, force=args.force)
    import numpy as np

    from clothlab.models.base import ORIENTATION
    from clothlab.surrogate.labels import ModelLabels, TextureProbe
    from clothlab.surrogate.materials import label_source, material_draw, material_grid, reference_quadrature

    # per weave its materials (trained weaves first, then the held-out pattern's), one list over all
    sets, heldout, held_pattern, owner = [], [], [], []
    for i, (weave, model, params) in enumerate(resolved):
        p = model.resolve(params)
        is_held = held_spec is not None and i == len(resolved) - 1
        if args.draw is not None:
            from clothlab.models.surface.parameters import draw_table2

            own, own_held = material_draw(weave.name, p, args.draw, args.heldout_share, args.seed,
                                          draw=draw_table2, heldout_all=is_held)
        else:
            own, own_held = material_grid(model.params, p, args.vary)
        offset = len(sets)
        sets += own
        owner += [i] * len(own)
        if is_held:
            held_pattern += list(range(offset, offset + len(own)))
        else:
            heldout += [offset + j for j in own_held]
    estimate = _footprint_estimate() if args.labels == "sat" else None
    labels = [label_source(args.labels, resolved[i][1], q, args.samples, args.seed, footprint_estimate=estimate)
              for i, q in zip(owner, sets, strict=True)]
    # what --residual corrects (and the R of the far view): R of each material on its own weave
    references = [ModelLabels(resolved[i][1], q) for i, q in zip(owner, sets, strict=True)]
    probes = None
    if args.probe_points:
        if not all(m.has_texture for _, m, _ in resolved):
            raise ConfigError("the texture probe needs a model with a texture", field="--probe-points")
        textures = [m.texture(seed=args.seed) for _, m, _ in resolved]
        probes = [TextureProbe(textures[i], q, args.probe_points) for i, q in zip(owner, sets, strict=True)]
    if args.reciprocal:  # before any labelling: the swap is only valid for a reciprocal model
        from clothlab.surrogate.training import check_reciprocal

        try:
            check_reciprocal(references, "reflectance model")
            check_reciprocal(probes, "texture probe")
        except ValueError as exc:
            raise ConfigError(str(exc), field="--reciprocal") from None
    weave, model, _ = resolved[0]
    p = model.resolve(resolved[0][2])
    names = [n for n in model.params.names() if n != ORIENTATION]  # a frame rotation, applied outside the network
    materials = np.stack([material_vector(resolved[i][0], q, model.params, names)
                          for i, q in zip(owner, sets, strict=True)])
    encoding = {"parameters": names, "pattern_order": PATTERN_ORDER, "kind": model.kind, "weave": weave.name,
                "labels": type(labels[0]).__name__, "params": p, "weave_wv": format_wv(weave)}
    if reference_quadrature(model) is not None:  # the R a query evaluates (clothlab.models.neural.reference_model)
        encoding["reference_quadrature"] = reference_quadrature(model)
    if args.vary or args.draw is not None or several:
        encoding["materials_params"] = [{k: q[k] for k in names} for q in sets]
        encoding["heldout_materials"] = heldout
    if several:  # additive: a sidecar without these keys has one weave, "weave_wv"
        encoding["weaves_wv"] = {w.name: format_wv(w) for w, _, _ in resolved}
        encoding["materials_weave"] = [weave_names[i] for i in owner]
        encoding["patterns"] = weave_names[:len(specs)]
    if held_spec is not None:
        encoding["heldout_pattern"] = held_pattern
        encoding["heldout_pattern_name"] = weave_names[-1]
    if args.yarn_bins:
        encoding["yarn_extent"] = yarn_extent(p)
    # the chunks of material m are labelled with sets[m] on its weave: a resume must not relabel others
    described = json.dumps({"weaves": [weave_names[i] for i in owner], "params": sets}, sort_keys=True)
    record = out / "materials.json"
    if args.resume and record.exists() and record.read_text(encoding="utf-8") != described:
        raise ConfigError(f"the data in {out} was labelled for other materials or weaves ({record}); resume with "
                          "the same SOURCE, --heldout-pattern, --draw / --vary and --seed, or start a new directory",
                          field="--resume")
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(record, described.encode())
    data_spec = DataSpec(pairs=args.pairs, seed=args.seed, small_sizes=args.small_sizes, row_centres=args.row_centres,
                         mirror_share=args.mirror_share)
    from clothlab.cli.options import parallel_requested, runner_of

    with runner_of(args) if parallel_requested(args) else contextlib.nullcontext() as runner:
        result = run_training(out, labels, materials, data_spec,
                              TrainSpec(width=args.width, spatial=args.spatial, seed=args.seed,
                                        yarn_bins=args.yarn_bins, residual=args.residual,
                                        residual_input=args.residual_input,
                                        highlight_scale=args.highlight_scale, probe_points=args.probe_points,
                                        reciprocal=args.reciprocal),
                              budget_s=60.0 * args.budget, encoding=encoding, resume=args.resume,
                              heldout_materials=heldout, runner=runner, references=references,
                              heldout_pattern=held_pattern, probes=probes)
    from clothlab.surrogate.training_run import write_report_page

    latent = None
    if args.vary and not several:  # Fig. 8: between the first and the last grid material
        from clothlab.surrogate.interpolation import latent_interpolation, plot_latent_interpolation

        last = len(sets) - len(heldout) - 1
        latent = latent_interpolation(result.surrogate, model, 0, last, sets[0], sets[last], names)
        plot_latent_interpolation(latent, out / "latent.png")
        atomic_write_bytes(out / "latent.json", (json.dumps(latent, indent=2) + "\n").encode())
    write_report_page(out, result.metrics, latent=latent)
    m = result.metrics
    lines.append(f"{final / 'surrogate.npz'}: {m['steps']} steps, {m['queries']:,} queries, "
                 f"{m['label_cpu_s'] + m['cpu_s']:.0f} CPU-s")
    for key, what in (("heldout_pairs", "held-out pairs"), ("heldout_materials", "unseen materials"),
                      ("heldout_pattern", "unseen pattern")):
        for b in m.get(key, []):
            interval = b.get("relative_rmse_interval")
            spread = f", 90 % bootstrap {interval[0]:.3f}-{interval[1]:.3f}" if interval else ""
            lines.append(f"  footprint {b['size_lo']:g}-{b['size_hi']:g} tiles: {what}: relative RMSE "
                         f"{b['relative_rmse']:.3f} ({b['rows']} queries{spread})")
    if m.get("far_view", {}).get("rows"):
        far = m["far_view"]
        lines.append(f"  far view (>= 4 tiles, held-out pairs): {far['relative_rms_vs_texture']:.3f} relative RMS from "
                     f"the texture labels (the reflectance model: {far['reflectance_vs_texture']:.3f})")
    return 0
