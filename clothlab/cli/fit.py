"""``clothlab fit fabric.yaml ...``: fit the configured model to its measurement, save ``fits/<name>/``,
print a summary (:func:`present_fit`); optionally the report too.

Progress of the optimiser and the posterior is shown by the fit package itself (``clothlab.progress``);
``--quiet`` here is the global ``-q``.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from clothlab.cli.options import add_force, add_output, add_parallel, add_quadrature_overrides, count_type


def add_parser(sub):
    p = sub.add_parser("fit", help="fit a model to a measurement as configured in fabric.yaml -> fits/<name>/",
                       description="Fit the model of each fabric.yaml to its measurement and save fits/<name>/ "
                                   "atomically (parameters, coefficients, error percentiles, trace).")
    p.add_argument("configs", nargs="+", type=Path, metavar="fabric.yaml|DIR",
                   help="one or more fabric.yaml files, or directories (every fabric.yaml below them); several "
                        "are a batch: one task per fit, fits already done with the same configuration skipped "
                        "(docs/parallel.md)")
    add_force(p, "fits/<name>/")
    p.add_argument("--max-evals", type=count_type(1, 2**31 - 1),
                   help="optimiser evaluation budget (overrides the yaml)")
    p.add_argument("--seed", type=count_type(0, 2**32 - 1), help="optimiser seed (overrides the yaml)")
    add_output(p, "write the fit directories <name>/ under DIR (default: the yaml's output.fits)", metavar="DIR",
               deprecated=("--fits-dir",))
    p.add_argument("--report", action="store_true", help="also build reports/<name>/ afterwards (output.reports)")
    p.add_argument("--posterior", action="store_true",
                   help="also sample the posterior with emcee (fit.posterior settings, else the defaults); an "
                        "interrupted run continues from its checkpoint when the same command is run again")
    p.add_argument("--no-posterior", action="store_true", help="skip the posterior even if fabric.yaml asks for it")
    p.add_argument("--cv", type=count_type(0, 100_000), metavar="K",
                   help="k-fold cross-validated error percentiles (K >= 2)")
    p.add_argument("--select", action="store_true",
                   help="model selection instead of one fit: the same as `clothlab select` (docs/select.md)")
    from clothlab.cli.select import add_selection_options

    add_selection_options(p)
    add_quadrature_overrides(p)
    add_parallel(p, "the fits (one task per fit; one fabric.yaml: one task per cross-validation fold and chunks "
                    "of its posterior's walkers)")
    return p


def run(args) -> int:
    if args.select:
        from clothlab.cli import select

        return select.run(args)
    with contextlib.ExitStack() as held:  # each result's lock, held from the checks to the save
        return _run(args, held)


def _run(args, held) -> int:
    from dataclasses import replace

    from clothlab.atomic import prepare_result
    from clothlab.cli.options import parallel_requested, runner_of
    from clothlab.config import PosteriorConfig, apply_overrides, load_config
    from clothlab.errors import ConfigError
    from clothlab.fit.batch import expand_config_paths
    from clothlab.fit.runner import run_fit, save_fit

    if args.cv is not None and args.cv < 2:
        raise ConfigError(f"--cv needs at least 2 folds, got {args.cv}", field="--cv")
    parallel = parallel_requested(args)  # checked first: without the extra, one line and nothing done
    paths = expand_config_paths(args.configs)
    batch = len(paths) > 1 or any(p.is_dir() for p in args.configs)
    configs = []
    for path in paths:  # every yaml is checked (and no result overwritten) before the first fit starts
        cfg = apply_overrides(load_config(path), rule=args.rule, nodes=args.nodes, max_evals=args.max_evals,
                              seed=args.seed)
        if args.cv is not None:
            cfg = replace(cfg, fit=replace(cfg.fit, cv_folds=args.cv))
        if args.no_posterior:
            cfg = replace(cfg, fit=replace(cfg.fit, posterior=None))
        elif args.posterior and cfg.fit.posterior is None:
            walkers = max(32, 2 * len(cfg.fit.free) + 2)
            cfg = replace(cfg, fit=replace(cfg.fit, posterior=PosteriorConfig(walkers=walkers)))
        if batch:
            configs.append(cfg)
            continue
        dest = (args.output or cfg.output.fits) / cfg.name
        # writable, not being written by another fit (locked until saved), no result overwritten without --force
        held.enter_context(prepare_result(dest, force=args.force))
        configs.append(cfg)
    if batch:
        return _run_batch(args, configs)
    # the pool of the CV folds (one task each) and the posterior's walkers; no cluster when there is neither
    pooled = any(cfg.fit.posterior is not None or cfg.fit.cv_folds >= 2 for cfg in configs)
    runner = held.enter_context(runner_of(args)) if parallel and pooled else None
    for cfg in configs:
        result = run_fit(cfg, fits_dir=args.output, runner=runner)
        out = save_fit(result, force=args.force, fits_dir=args.output)
        print(present_fit(result, saved_to=out))
        if args.report:
            from clothlab.report.build import build_report

            report = build_report(out, cfg.output.reports, force=args.force, percentiles=cfg.report.percentiles)
            print(f"  report: {report / 'index.html'}")
    return 0


def _run_batch(args, configs) -> int:
    """Several fits as one batch (:mod:`clothlab.fit.batch`) on the runner of ``--workers``/``--scheduler``:
    each fit's summary as it lands, then the table; exit 1 when a fit failed."""
    from clothlab.cli.options import runner_of
    from clothlab.fit.batch import batch_lines, plan_batch, run_batch

    items, skipped = plan_batch(configs, fits_dir=args.output, force=args.force)

    def show(row):
        if row["status"] == "fitted":
            print(f"{row['report']}\n  saved to {row['path']}", flush=True)

    with runner_of(args) if items else contextlib.nullcontext() as runner:
        rows = run_batch(items, runner, on_row=show) if items else []
    by_name = {r["name"]: r for r in skipped + rows}
    rows = [by_name[c.name] for c in configs]
    print("\n".join(batch_lines(rows)))
    if args.report:
        from clothlab.report.build import build_report

        for cfg, row in zip(configs, rows, strict=True):
            if row["status"] == "fitted":  # a fit skipped as done keeps its report
                report = build_report(Path(row["path"]), cfg.output.reports, force=True,
                                      percentiles=cfg.report.percentiles)
                print(f"  report: {report / 'index.html'}")
    return 1 if any(r["status"] == "failed" for r in rows) else 0


def present_fit(result, saved_to=None) -> str:
    """The summary printed after a fit: :meth:`clothlab.fit.runner.FitResult.fit_report` (parameters with
    uncertainty, coefficients per channel, error percentiles, time by stage, notes); ``saved_to``: the fit
    directory, named at the end."""
    text = result.fit_report()
    return text if saved_to is None else f"{text}\n  saved to {saved_to}"
