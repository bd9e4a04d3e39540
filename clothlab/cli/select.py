"""``clothlab select fabric.yaml`` (= ``clothlab fit --select fabric.yaml``): fit candidate weaves, model kinds
and orientation starts, rank them by cross-validated error and AIC/BIC, refit the winner and save it as
``fits/<name>/`` with the comparison table (``selection.csv``, ``selection.md``); :mod:`clothlab.fit.select`,
docs/select.md."""

from __future__ import annotations

import contextlib
from pathlib import Path

from clothlab.cli.options import add_force, add_output, add_parallel, count_type


def add_parser(sub):
    p = sub.add_parser("select", help="model selection: weaves x kinds x orientations, ranked -> fits/<name>/",
                       description="Fit every candidate (weave presets or select.weaves, model kinds with their "
                                   "diffuse term, orientation starts) with a reduced budget, rank them by "
                                   "cross-validated error (and list AIC / BIC), refit the winner with the "
                                   "fabric.yaml budget and save it with the comparison table (docs/select.md).")
    p.add_argument("configs", nargs="+", type=Path, metavar="fabric.yaml", help="one or more fabric.yaml files")
    add_selection_options(p)
    add_force(p, "fits/<name>/")
    add_output(p, "write the fit directories <name>/ under DIR (default: the yaml's output.fits)", metavar="DIR")
    p.add_argument("--no-posterior", action="store_true", help="skip the posterior of the winner's refit")
    add_parallel(p, "the candidate fits (one task per candidate)")
    return p


def add_selection_options(p) -> None:
    """The options shared by ``select`` and ``fit --select``."""
    p.add_argument("--weaves", metavar="LIST", help="comma-separated candidate weaves (preset names, preset:<name> "
                                                    "or .wv files); default select.weaves, else every preset")
    p.add_argument("--kinds", metavar="LIST", help="comma-separated candidate model kinds, e.g. "
                                                   "irawan,irawan+oren-nayar (default select.kinds)")
    p.add_argument("--orientation-starts", type=count_type(1, 8), metavar="N",
                   help="orientation starts per weave and kind, 1-8 (default select.orientation_starts, 2)")
    p.add_argument("--candidate-evals", type=count_type(1, 2**31 - 1), metavar="N",
                   help="evaluations per candidate fit (default select.max_evals, 600)")
    p.add_argument("--candidate-cv", type=count_type(0, 2**31 - 1), metavar="K",
                   help="cross-validation folds per candidate (default select.cv_folds, 5; 0: rank by BIC)")
    p.add_argument("--losses", metavar="LIST",
                   help="comma-separated candidate losses (squared, l1, huber, cauchy; default: select.losses, "
                        "else huber at 0.1); huber and cauchy are tried at each --loss-scales value, the CV "
                        "ranking chooses")
    p.add_argument("--loss-scales", metavar="LIST",
                   help="comma-separated scales of the huber / cauchy candidates, in the metric's units (0.1 = 10 %%; "
                        "default select.loss_scales, else 0.1)")
    p.add_argument("--stability", type=count_type(0, 1000), metavar="B",
                   help="selection stability: the selection repeated on B seeded subsamples of 80 %% of the rows; "
                        "how often each weave, kind, loss and orientation range wins (about B more selections)")
    p.add_argument("--nested", type=count_type(0, 100), metavar="K",
                   help="nested cross-validation with K outer folds (K >= 2; 0: none, the default): the whole "
                        "selection repeated inside each outer fold; its outer held-out error is the figure of the "
                        "selected model, the winner's inner CV the selection score (about K+1 times the cost)")


def _settings(cfg, args):
    from clothlab.config.checks import Location, as_choice
    from clothlab.errors import ConfigError
    from clothlab.fit.select import check_settings, settings_from_config
    from clothlab.models.registry import MODEL_KINDS
    from clothlab.weave.presets import PRESET_PREFIX, canonical_preset_name

    weaves = kinds = None
    if args.weaves is not None:
        weaves = []
        for item in (w.strip() for w in args.weaves.split(",")):
            if item.endswith(".wv"):
                if not Path(item).is_file():
                    raise ConfigError(f"weave file not found: {item!r}", field="--weaves")
                weaves.append(str(Path(item).absolute()))
            elif item.lower().startswith("pattern:"):
                from clothlab.weave.patterns import PATTERN_PREFIX, get_pattern

                try:
                    weaves.append(PATTERN_PREFIX + get_pattern(item[len(PATTERN_PREFIX):].strip()).name)
                except ConfigError as exc:
                    raise ConfigError(exc.detail, field="--weaves") from None
            else:
                try:
                    weaves.append(PRESET_PREFIX + canonical_preset_name(item.removeprefix(PRESET_PREFIX)))
                except ConfigError as exc:  # an unknown preset, or an empty entry
                    raise ConfigError(exc.detail, field="--weaves") from None
    losses = scales = None
    if getattr(args, "losses", None) is not None:
        from clothlab.config.choices import LOSSES

        losses = [as_choice(k.strip(), Location(None, "--losses"), LOSSES) for k in args.losses.split(",")]
    if getattr(args, "loss_scales", None) is not None:
        from clothlab.untrusted import parse_number

        scales = []
        for item in args.loss_scales.split(","):
            value = parse_number(item, error=ConfigError, field="--loss-scales")
            if not value > 0:
                raise ConfigError(f"expected positive numbers (the metric's units), got {item.strip()!r}",
                                  field="--loss-scales")
            scales.append(value)
    if args.kinds is not None:
        kinds = [as_choice(k.strip(), Location(None, "--kinds"), MODEL_KINDS) for k in args.kinds.split(",")]
    for flag, items in (("--weaves", weaves), ("--kinds", kinds), ("--losses", losses), ("--loss-scales", scales)):
        if items is not None and len(set(items)) != len(items):
            twice = next(item for i, item in enumerate(items) if item in items[:i])
            raise ConfigError(f"{twice!r} is listed twice", field=flag)
    for flag, value, low in (("--orientation-starts", args.orientation_starts, 1),
                             ("--candidate-evals", args.candidate_evals, 1), ("--candidate-cv", args.candidate_cv, 0),
                             ("--nested", getattr(args, "nested", None), 0)):
        if value is not None and (value < low or (flag in ("--candidate-cv", "--nested") and value == 1)):
            raise ConfigError(f"{flag} must be at least {low}{' and not 1' if low == 0 else ''}, got {value}",
                              field=flag)
    settings = settings_from_config(cfg, weaves=weaves, kinds=kinds, orientation_starts=args.orientation_starts,
                                    max_evals=args.candidate_evals, cv_folds=args.candidate_cv,
                                    nested=getattr(args, "nested", None), losses=losses, loss_scales=scales,
                                    stability=getattr(args, "stability", None))
    check_settings(settings, cfg.base_dir)  # every weave reads, before any candidate is fitted
    return settings


def run(args) -> int:
    from dataclasses import replace

    from clothlab.atomic import prepare_result
    from clothlab.cli.options import parallel_requested, runner_of
    from clothlab.config import apply_overrides, load_config
    from clothlab.fit.select import save_selection, select

    parallel = parallel_requested(args)  # Dask missing: the one-line error before anything is made
    with contextlib.ExitStack() as held:
        jobs = []
        for path in args.configs:  # every yaml checked, no result overwritten, before the first selection runs
            cfg = apply_overrides(load_config(path), rule=getattr(args, "rule", None),
                                  nodes=getattr(args, "nodes", None), max_evals=getattr(args, "max_evals", None),
                                  seed=getattr(args, "seed", None))  # fit --select passes fit's options
            if getattr(args, "cv", None) is not None:
                cfg = replace(cfg, fit=replace(cfg.fit, cv_folds=args.cv))
            if getattr(args, "no_posterior", False):
                cfg = replace(cfg, fit=replace(cfg.fit, posterior=None))
            settings = _settings(cfg, args)
            held.enter_context(prepare_result((args.output or cfg.output.fits) / cfg.name, force=args.force))
            jobs.append((cfg, settings))
        runner = held.enter_context(runner_of(args)) if parallel else None
        for cfg, settings in jobs:
            selection = select(cfg, settings, fits_dir=args.output, runner=runner)
            out = save_selection(selection, force=args.force, fits_dir=args.output)
            print(present_selection(selection, out))
    return 0


def present_selection(selection, saved_to) -> str:
    """The ranked table (as saved in selection.md, with the nested CV when run), the winner's refit summary as a
    plain fit prints it (``fit_report()``, as :func:`clothlab.cli.fit.present_fit`) and where it went."""
    from clothlab.fit.noise_floor import floor_sentence, measurement_noise_floor
    from clothlab.fit.select import table_markdown

    winner = selection.winner
    if selection.nested:
        error, label = selection.nested["held_out"], "outer held-out, nested CV"
    else:
        error, label = (winner.cross_validation or {}).get("held_out") or winner.errors["overall"], "held out"
    floor = floor_sentence(measurement_noise_floor(winner.problem.measurement), error, label)
    return (f"{table_markdown(selection)}\n  noise floor: {floor}\n\n"
            f"  winner: {selection.ranked[0].row['candidate']}; its refit:\n\n"
            f"{winner.fit_report()}\n  saved to {saved_to}")
