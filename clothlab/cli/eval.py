"""``clothlab eval SOURCE directions.csv``: a fitted or configured model at the directions of a CSV
(CSV out, optionally one column per component and channel)."""

from __future__ import annotations

import sys
from pathlib import Path

from clothlab.cli.options import add_force, add_output, add_quadrature_overrides, count_type


def add_parser(sub):
    p = sub.add_parser("eval", help="evaluate a fitted or configured model at the directions of a CSV",
                       description="Evaluate the model of a fit directory or a fabric.yaml at the directions of a "
                                   "CSV (with u, v columns: the model's texture model at those points; with a "
                                   "footprint column too: the texture averaged over a box footprint of that side "
                                   "in tiles centred at (u, v), Chen, Wang & Wang 2024, eqs. 3-5; kind neural "
                                   "answers it with the network's footprint input).")
    p.add_argument("source", type=Path, help="a fit directory (fits/<name>) or a fabric.yaml")
    p.add_argument("directions", type=Path, help="CSV with theta_i, phi_i, theta_o, phi_o in degrees")
    add_output(p, "output CSV (default: stdout)", metavar="CSV")
    p.add_argument("--components", action="store_true", help="add one column per component and channel")
    add_force(p, "output file")
    add_quadrature_overrides(p)
    p.add_argument("--footprint-method", choices=("sat", "mc"), default="sat",
                   help="footprint estimator: periodic summed-area tables (exact for box footprints; default) "
                        "or stratified Monte Carlo")
    p.add_argument("--footprint-resolution", type=count_type(2, 8192), default=128, metavar="R",
                   help="texels per tile side of the summed-area tables (default 128)")
    p.add_argument("--footprint-samples", type=count_type(1, 1_000_000), default=256, metavar="N",
                   help="Monte Carlo samples per footprint (default 256)")
    p.add_argument("--footprint-seed", type=count_type(0, 2**32 - 1), default=0, metavar="SEED",
                   help="Monte Carlo seed (default 0)")
    return p


def run(args) -> int:
    from clothlab.fit.eval_csv import evaluate_directions_file

    text = evaluate_directions_file(args.source, args.directions, components=args.components, rule=args.rule,
                                    nodes=args.nodes, footprint_method=args.footprint_method,
                                    samples=args.footprint_samples, resolution=args.footprint_resolution,
                                    seed=args.footprint_seed)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    from clothlab.atomic import atomic_write_text
    from clothlab.errors import ResultExistsError

    if args.output.exists() and not args.force:
        raise ResultExistsError(f"{args.output} exists; pass --force to overwrite it", path=args.output)
    atomic_write_text(args.output, text)
    return 0
