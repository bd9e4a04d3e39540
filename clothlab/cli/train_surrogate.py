"""``clothlab train-surrogate``: label footprint queries of one fabric and train the numpy surrogate of
Chen, Wang & Wang 2024 (sec. 4-5) within a CPU budget; writes the surrogate (``.npz`` + JSON), the loss
curve and held-out errors by footprint size (JSON + PNG) into ``-o DIR``."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import add_force, add_output

TARGETS = {"im": "irawan", "surface": "surface"}
LABELS = ("mc", "sat", "model")


def add_parser(sub):
    p = sub.add_parser("train-surrogate", help="train the neural footprint surrogate of one fabric",
                       description="Label footprint queries (Table 2 sampling of Chen, Wang & Wang 2024) and "
                                   "train the numpy encoder/decoder surrogate within a CPU budget.")
    p.add_argument("source", help="preset:<name>, a .wv file or a fabric.yaml")
    add_output(p, "output directory (data, checkpoint, surrogate.npz/json, training.json, PNGs)", metavar="DIR")
    p.add_argument("--target", choices=tuple(TARGETS), default="im",
                   help="the model whose footprint averages are learnt (default im: Irawan-Marschner texture)")
    p.add_argument("--budget", type=float, default=5.0, help="CPU-minutes for labelling and training (default 5)")
    p.add_argument("--resume", action="store_true", help="continue a run in DIR (its data and checkpoint)")
    p.add_argument("--labels", choices=LABELS, default="mc",
                   help="label source: mc (default: stratified MC of the texture model over the part of the "
                        "footprint that is not whole tiles, the rest exact), sat (summed-area tables of "
                        "clothlab.models.footprint: one table per direction pair, and each query here has its "
                        "own, so slow), model (the reflectance model, footprint-independent)")
    p.add_argument("--samples", type=int, default=64, help="MC samples per query for mc labels (default 64)")
    p.add_argument("--pairs", type=int, default=64, help="direction pairs per footprint (default 64)")
    p.add_argument("--width", type=int, default=64, help="decoder width (default 64)")
    p.add_argument("--spatial", type=int, default=32, help="spatial feature width (default 32)")
    p.add_argument("--seed", type=int, default=0, help="data and initialisation seed (default 0)")
    add_force(p, "output directory")
    return p


def _model(source: str, target: str):
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    kind, params = TARGETS[target], {}
    if source.endswith((".yaml", ".yml")):
        from clothlab.config import load_config

        cfg = load_config(source)
        weave = resolve_weave(cfg.model.weave, cfg.base_dir)
        if cfg.model.kind == kind:
            params = dict(cfg.model.params)
    else:
        weave = resolve_weave(source, Path.cwd())
    return weave, build_model(kind, weave), params


def _labels(choice: str, model, params: dict, samples: int, seed: int):
    from clothlab.errors import ConfigError
    from clothlab.neural.labels import FootprintLabels, ModelLabels, TextureMonteCarloLabels

    if choice == "model":
        return ModelLabels(model, params)
    if not model.has_texture:
        raise ConfigError(f"model kind {model.kind!r} has no texture model to average over footprints; "
                          "use --labels model", field="--labels")
    texture = model.texture(seed=seed)
    if choice == "sat":
        try:
            from clothlab.models.footprint import footprint_components
        except ImportError:
            raise ConfigError("the footprint estimator (clothlab.models.footprint) is not available; "
                              "use --labels mc", field="--labels") from None
        return FootprintLabels(footprint_components, texture, params, method="sat")
    return TextureMonteCarloLabels(texture, params, samples=max(2, samples), seed=seed,
                                   tile_average=ModelLabels(model, params))


def run(args) -> int:
    import shutil

    from clothlab.errors import ConfigError, ResultExistsError
    from clothlab.neural.data import DataSpec
    from clothlab.neural.encodings import PATTERN_ORDER, material_vector
    from clothlab.neural.run import run_training
    from clothlab.neural.training import TrainSpec

    if args.output is None:
        raise ConfigError("give the output directory with -o DIR", field="-o")
    for name, value, lo in (("--budget", args.budget, 0.01), ("--samples", args.samples, 1),
                            ("--pairs", args.pairs, 1), ("--width", args.width, 4), ("--spatial", args.spatial, 4)):
        if not value >= lo:
            raise ConfigError(f"expected a number >= {lo}, got {value}", field=name)
    out = Path(args.output)
    if out.exists() and any(out.iterdir()) and not args.resume:
        if not args.force:
            raise ResultExistsError(f"{out} exists; give --resume to continue it or --force to replace it",
                                    path=out)
        shutil.rmtree(out)
    weave, model, params = _model(args.source, args.target)
    labels = _labels(args.labels, model, params, args.samples, args.seed)
    p = model.resolve(params)
    names = model.params.names()
    materials = material_vector(weave, p, model.params, names)[None]
    encoding = {"parameters": names, "pattern_order": PATTERN_ORDER, "kind": model.kind, "weave": weave.name,
                "labels": type(labels).__name__, "params": p}
    result = run_training(out, [labels], materials, DataSpec(pairs=args.pairs, seed=args.seed),
                          TrainSpec(width=args.width, spatial=args.spatial, seed=args.seed),
                          budget_s=60.0 * args.budget, encoding=encoding, resume=args.resume)
    m = result.metrics
    print(f"{out / 'surrogate.npz'}: {m['steps']} steps, {m['queries']:,} queries, "
          f"{m['label_cpu_s'] + m['cpu_s']:.0f} CPU-s")
    for b in m.get("heldout_pairs", []):
        print(f"  footprint {b['size_lo']:g}-{b['size_hi']:g} tiles: held-out relative RMSE {b['relative_rmse']:.3f}"
              f" ({b['rows']} queries)")
    return 0
