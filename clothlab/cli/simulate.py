"""``clothlab simulate``: a virtual gonioreflectometer (model + the paper's sampling + a noise model ->
a measurement table), the six paper-fabric example sets, or a simulated BTF stack."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import add_force, add_output, add_quadrature_overrides, count_type, number_type

MAX_NOISE_MULT = 10.0
"""Largest --noise-mult (a log-normal sigma of 10 already spreads values over e^+-20)."""
MAX_NOISE_ADD = 1e3
"""Largest --noise-add in 1/sr."""
MAX_SEED = 2**64 - 1


def add_parser(sub):
    p = sub.add_parser("simulate", help="virtual gonioreflectometer: model + paper sampling + noise -> table",
                       description="Simulate a measurement table (-o), the paper-fabric example sets "
                                   "(--paper-examples DIR) or a BTF stack (--btf DIR) from a weave and a model.")
    p.add_argument("source", nargs="?", help="preset:<name>, a .wv file or a fabric.yaml "
                                             "(with --btf also a fit directory)")
    add_output(p, "output table (clothlab CSV)", metavar="TABLE")
    p.add_argument("--paper-examples", type=Path, metavar="DIR",
                   help="write the six simulated paper-fabric example sets into DIR")
    p.add_argument("--btf", type=Path, metavar="DIR",
                   help="write a simulated BTF stack (texture model, EXR + manifest) of the source into DIR "
                        "(source: preset:<name>, a fabric.yaml or a fit directory)")
    p.add_argument("--btf-directions", type=count_type(1, 4096), default=16,
                   help="(light, view) pairs of the BTF stack (default 16)")
    p.add_argument("--btf-size", type=count_type(1, 16384), default=64,
                   help="BTF image size in pixels (default 64)")
    p.add_argument("--btf-tiles", type=number_type(1e-3, 1e4), default=4.0,
                   help="weave tiles across a BTF image (default 4)")
    p.add_argument("--btf-offset", default="0.25,0.4", help="BTF tile offset u0,v0 in tiles (default 0.25,0.4)")
    p.add_argument("--kd", help="diffuse albedo per channel, e.g. 0.2,0.1,0.1 (default 0.1 each)")
    p.add_argument("--ks-warp", help="warp specular albedo per channel (default 0.1 each)")
    p.add_argument("--ks-weft", help="weft specular albedo per channel (default 0.1 each)")
    p.add_argument("--channels", default="R,G,B",
                   help="channel names (default R,G,B; with --btf the source's own when it has coefficients)")
    p.add_argument("--noise-mult", type=number_type(0.0, MAX_NOISE_MULT), default=0.0,
                   help="multiplicative log-normal sigma (0.05 = 5 %%; at most 10)")
    p.add_argument("--noise-add", type=number_type(0.0, MAX_NOISE_ADD), default=0.0,
                   help="additive Gaussian sigma in 1/sr")
    p.add_argument("--seed", type=count_type(0, MAX_SEED), default=0, help="noise seed (default 0)")
    p.add_argument("--sampling", metavar="SPEC", default=None,
                   help="direction pairs of the table: paper (default: the paper's 225 x 7 grid), random:N "
                        "(N pairs, each direction uniform over the hemisphere in solid angle), random:N:cosine "
                        "(cosine-weighted), or a CSV file with columns theta_i,phi_i,theta_o,phi_o in degrees "
                        "(clothlab's azimuths)")
    p.add_argument("--sampling-seed", type=count_type(0, MAX_SEED), default=0, help="seed of random:N (default 0)")
    p.add_argument("--orientation", type=number_type(), metavar="DEG", default=None,
                   help="rotate the generating weave by DEG about the normal (counter-clockwise from above; the "
                        "model parameter orientation)")
    add_force(p, "output (table, example sets or BTF stack)")
    add_quadrature_overrides(p)
    return p


def channel_values(text: str, field: str, n: int):
    """(n,) values of 0 or in [1e-30, 1000] from ``"0.2,0.1,0.1"`` (one value: the same in every channel), each in plain
    decimal notation."""
    import numpy as np

    from clothlab.errors import ConfigError
    from clothlab.untrusted import parse_number

    values = np.array([parse_number(x, error=ConfigError, field=field) for x in text.split(",")])
    if values.size == 1:
        values = np.repeat(values, n)
    if values.size != n or np.any(values < 0) or np.any(values > 1e3) or np.any((values > 0) & (values < 1e-30)):
        raise ConfigError(f"expected {n} values of 0 or in [1e-30, 1000] (one per channel), got {text!r}",
                          field=field)
    return values


def channel_names(text: str) -> tuple[str, ...]:
    """Distinct channel names from ``"R,G,B"``, each one a table can hold (no spaces, commas or quotes, not an
    angle column, not ``sigma_*``); ConfigError naming ``--channels``."""
    from clothlab.errors import ConfigError
    from clothlab.io.table import _CHANNEL_NAME, ANGLE_COLUMNS, SIGMA_PREFIX

    names = tuple(c.strip() for c in text.split(","))
    bad = [c for c in names if not _CHANNEL_NAME.match(c) or c in ANGLE_COLUMNS or c.startswith(SIGMA_PREFIX)]
    if not names or bad or len(set(names)) != len(names):
        raise ConfigError(f"expected distinct comma-separated channel names (no spaces or quotes, not an angle "
                          f"column or sigma_*), got {text!r}", field="--channels")
    return names


def run(args) -> int:
    from clothlab.errors import ConfigError

    if args.btf is not None:
        return _run_btf(args)
    if args.paper_examples is not None:
        from clothlab.simulate.examples import write_paper_examples

        for path in write_paper_examples(args.paper_examples, force=args.force):
            print(path)
        return 0
    if not args.source or args.output is None:
        raise ConfigError("give a source (preset:<name>, a .wv file or a fabric.yaml) and -o OUTPUT, "
                          "or --paper-examples DIR", field="-o" if args.source else "source")
    from clothlab.config import apply_overrides, override_quadrature
    from clothlab.config.build import model_from_config, model_from_weave
    from clothlab.io.table import write_table
    from clothlab.simulate.gonio import NoiseModel, simulate
    from clothlab.weave.presets import resolve_weave

    source = args.source
    params = {}
    if source.endswith((".yaml", ".yml")):
        from clothlab.config import load_config

        cfg = apply_overrides(load_config(source), rule=args.rule, nodes=args.nodes)
        model = model_from_config(cfg)
        params = dict(cfg.model.params)
    else:
        try:
            weave = resolve_weave(source, Path.cwd())
        except ConfigError as exc:  # the weave named on the command line is the source argument
            if exc.path is not None:
                raise
            raise ConfigError(exc.detail, field="source") from None
        model = model_from_weave(weave, quadrature=override_quadrature(rule=args.rule, nodes=args.nodes))
    weave = model.weave
    channels = channel_names(args.channels)
    n = len(channels)
    coefficients = {"kd": channel_values("0.1" if args.kd is None else args.kd, "--kd", n),
                    "ks_warp": channel_values("0.1" if args.ks_warp is None else args.ks_warp, "--ks-warp", n),
                    "ks_weft": channel_values("0.1" if args.ks_weft is None else args.ks_weft, "--ks-weft", n)}
    dark = [c for j, c in enumerate(channels) if not any(v[j] for v in coefficients.values())]
    if dark:
        raise ConfigError(f"channel {dark[0]} has --kd, --ks-warp and --ks-weft all 0: it would reflect no light",
                          field="--kd")
    for name in model.component_names:  # per-yarn diffuse components (kind surface) take --kd
        if name.startswith("diffuse_"):
            coefficients.setdefault("kd_" + name.split("_", 1)[1], coefficients["kd"])
    from clothlab.simulate.sampling import parse_sampling

    if args.orientation is not None:
        params["orientation"] = model.params["orientation"].check(args.orientation, "--orientation")
    sampling, described = parse_sampling(args.sampling, args.sampling_seed)
    noise = NoiseModel(args.noise_mult, args.noise_add, args.seed)
    m = simulate(model, params, coefficients, channels=channels, noise=noise, sampling=sampling,
                 provenance={"sample_name": f"{weave.name} (SIMULATED)", "sampling": described})
    print(write_table(m, args.output, overwrite=args.force))
    return 0


def _run_btf(args) -> int:
    from clothlab.errors import ConfigError
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

    from clothlab.untrusted import parse_number

    offset = tuple(parse_number(x, error=ConfigError, field="--btf-offset") for x in args.btf_offset.split(","))
    if len(offset) != 2:
        raise ConfigError(f"expected u0,v0 numbers, got {args.btf_offset!r}", field="--btf-offset")
    return simulate_btf_command(args.source, args.btf, n_directions=args.btf_directions, size=args.btf_size,
                                tile_repeats=args.btf_tiles, offset=offset, seed=args.seed, kd=args.kd,
                                ks_warp=args.ks_warp, ks_weft=args.ks_weft,
                                channels=None if args.channels == "R,G,B" else args.channels,
                                rule=args.rule, nodes=args.nodes, force=args.force)
