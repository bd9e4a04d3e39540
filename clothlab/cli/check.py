"""``clothlab check``: the numerical stability study - extreme inputs, reciprocity, continuity, stiff fits
(:func:`clothlab.studies.stability.run_check_command`).  Exit code 1 when the sweep finds a non-finite or
negative value or a reciprocity violation."""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import add_output, add_parallel, count_type


def add_parser(sub):
    p = sub.add_parser("check", help="numerical stability study: extreme inputs, reciprocity, continuity, stiff fits",
                       description="Evaluate the model at extreme inputs and along parameter sweeps; exit code 1 "
                                   "on a non-finite or negative value or a reciprocity violation.")
    p.add_argument("--full", action="store_true", help=">= 10^6 configurations and the stiff-fit study (minutes)")
    p.add_argument("--seed", type=count_type(0, 2**32 - 1), default=0,
                   help="seed of the random parameter sets (default 0)")
    p.add_argument("--data", type=Path, metavar="DIR",
                   help="directory with the example measurements and fits (default: the shipped examples)")
    add_output(p, "report directory: an HTML page of the findings and the plots (PNG)", metavar="DIR",
               deprecated=("--report", "--figures"))
    p.add_argument("--json", type=Path, metavar="PATH", help="also write the findings as JSON")
    add_parallel(p, "the sweep's chunks (the findings do not depend on it)")
    return p


def run(args) -> int:
    import contextlib

    from clothlab.cli.options import parallel_requested, runner_of
    from clothlab.studies.stability import run_check_command

    kwargs = dict(full=args.full, seed=args.seed, data_dir=args.data, output=args.output, json_path=args.json,
                  emit=print)
    if not parallel_requested(args):
        return run_check_command(**kwargs)
    with contextlib.closing(runner_of(args)) as runner:
        return run_check_command(**kwargs, runner=runner)
