"""Posterior studies: a full posterior run to its stopping rule (the benchmark, bench section ``posterior``)
and the coverage of the 95 % intervals over the simulated example sets (emcee docs, "Autocorrelation
analysis"; the bench section ``coverage`` is :mod:`clothlab.studies.coverage`).

The fabrics' fabric.yaml files come from a :class:`clothlab.studies.data.StudyData` (``data``: a data
directory, or None for the example measurements regenerated into a temporary directory).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from clothlab.fit.posterior import PosteriorResult, run_posterior
from clothlab.studies.data import StudyData, study_data


def optimisation_only(config, **optimizer):
    """``config`` with cross-validation and the posterior switched off (``fit.cv_folds`` 0, ``fit.posterior``
    None) and the given ``fit.optimizer`` fields replaced: ``run_fit`` then runs the optimisation alone and
    writes no checkpoint (the studies below run the posterior themselves, checkpointing into a temporary
    directory)."""
    from dataclasses import replace

    fit = replace(config.fit, cv_folds=0, posterior=None)
    if optimizer:
        fit = replace(fit, optimizer=replace(fit.optimizer, **optimizer))
    return replace(config, fit=fit)


def _study_posterior(fit, **kwargs) -> PosteriorResult:
    """run_posterior at a fit's optimum, checkpointing into a temporary directory (never under fits/)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="clothlab-posterior-") as tmp:
        return run_posterior(fit.problem, fit.params, checkpoint_path=Path(tmp) / "checkpoint.npz", **kwargs)


#: The sampler choices the bench runs side by side (start, moves, stop; :func:`clothlab.fit.posterior.run_posterior`):
#: the default first, then the previous default (ball start, tau rule), then one choice changed at a time.
VARIANTS = (("laplace", "de-snooker", "ess"), ("ball", "de-snooker", "tau"), ("laplace", "de-snooker", "tau"),
            ("ball", "de-snooker", "ess"), ("laplace", "stretch", "ess"), ("laplace", "gaussian", "ess"))


def variant_name(start: str, moves: str, stop: str) -> str:
    return f"{start} start, {moves}, {stop} stop"


def posterior_benchmark(fabric: str = "polyester-lining", max_minutes: float = 10.0, *, data: StudyData | None = None,
                        walkers: int = 32, seed: int = 1, progress: bool = True, optimizer: dict | None = None,
                        moves: tuple[str, ...] = ("de-snooker",), variants=None) -> dict:
    """A full posterior (the fabric's six free parameters, noisy data) run to its stopping rule with each of
    ``variants`` ((start, moves, stop) triples; default: each of ``moves`` with the default start and stop), the
    first one's figures at the top level, every one's under ``by_variant`` (and, for the default start and stop,
    ``by_moves``): steps, max tau, smallest effective sample size, wall and CPU seconds, the 95 % intervals.

    The optimum comes from the fabric's fabric.yaml optimiser settings (``optimizer`` replaces some;
    cross-validation and the configured posterior off; its wall time is reported apart); the posterior then
    runs once, with a minimum of 1,000 steps, and stops by its rule (``variants``), at 50,000 steps or after
    ``max_minutes``.  Returns the wall times, tau, steps, acceptance and whether it converged within the limit.
    """
    import os

    from clothlab.fit.posterior.sampler import DEFAULT_START, DEFAULT_STOP
    from clothlab.fit.runner import run_fit

    with study_data(data) as d:
        fit = run_fit(optimisation_only(d.load_config(fabric), **(optimizer or {})))
    variants = tuple(variants or ((DEFAULT_START, name, DEFAULT_STOP) for name in moves))
    by_moves, by_variant = {}, {}
    for start, name, stop in variants:
        c = time.process_time()
        run = _study_posterior(fit, walkers=walkers, steps=1000, max_steps=50_000, seed=seed, progress=progress,
                               max_seconds=60.0 * max_minutes, moves=name, start=start, stop=stop)
        js = run.to_json()
        row = {"start": start, "moves": name, "stop": stop, "steps": run.steps, "converged": run.converged,
               "wall_s": run.wall_time, "cpu_s": time.process_time() - c,
               "max_tau": float(max(js["convergence"]["tau"].values())),
               "min_ess": float(min(js["convergence"]["ess"].values())),
               "acceptance_mean": float(np.mean(run.acceptance)),
               "truth_in_95": {n: e.get("truth_in_95") for n, e in js["parameters"].items()}}
        by_variant[variant_name(start, name, stop)] = row
        if (start, stop) == (DEFAULT_START, DEFAULT_STOP):
            by_moves[name] = row
        if (start, name, stop) == variants[0]:
            post = run
    summary = post.to_json()
    return {"fabric": fabric, "free": list(fit.problem.free), "fit_wall_time_s": fit.timings["optimisation_s"],
            "posterior_wall_time_s": post.wall_time, "converged": post.converged, "stop_reason": post.stop_reason,
            "within_limit": post.converged and post.wall_time <= 60.0 * max_minutes, "limit_minutes": max_minutes,
            "steps": post.steps, "walkers": post.walkers, "tau": summary["convergence"]["tau"],
            "ess": summary["convergence"]["ess"], "acceptance_mean": float(np.mean(post.acceptance)),
            "not_determined": summary["not_determined"], "cpu_count": os.cpu_count(), "by_moves": by_moves,
            "by_variant": by_variant, "rule": summary["convergence"]["rule"],
            "parameters": {n: {k: e[k] for k in ("median", "p2.5", "p97.5", "truth", "truth_in_95") if k in e}
                           for n, e in summary["parameters"].items()}}


COVERAGE_FABRICS = ("cotton-denim", "silk-shantung", "silk-charmeuse", "cotton-twill", "wool-gabardine",
                    "polyester-lining")
COVERAGE_TARGET = 0.9
"""Pass criterion: the 95 % intervals contain the generating value for at least this fraction of the free
parameters, over the six noisy simulated sets."""


def coverage_study(fabrics=COVERAGE_FABRICS, *, data: StudyData | None = None, walkers: int = 32, steps: int = 1000,
                   max_steps: int = 20_000, seed: int = 1, progress: bool = False, optimizer: dict | None = None,
                   check_every: int = 100) -> dict:
    """Coverage of the 95 % intervals over the noisy simulated sets (measurements/<fabric>/fabric.yaml, six free
    parameters each): each set is fitted with its fabric.yaml optimiser settings (``optimizer`` replaces some,
    e.g. a smaller budget; cross-validation and the configured posterior off), then one posterior runs at the
    optimum (``steps`` minimum, ``max_steps`` cap, the default stopping rule: effective sample size once tau is
    stable).  The generating values ("truth") are the simulated data's recorded parameters (measurement
    provenance).  Returns per fabric the covered flags, intervals, convergence and wall times, and overall the
    covered / total counts, the fraction and the pass verdict."""
    from clothlab.fit.runner import run_fit

    rows, inside, total = {}, 0, 0
    with study_data(data) as d:
        for fabric in fabrics:
            fit = run_fit(optimisation_only(d.load_config(fabric), **(optimizer or {})))
            post = _study_posterior(fit, walkers=walkers, steps=steps, max_steps=max_steps, seed=seed,
                                    progress=progress, check_every=check_every)
            params = post.to_json()["parameters"]
            hits = {n: e["truth_in_95"] for n, e in params.items() if "truth_in_95" in e}
            inside += sum(hits.values())
            total += len(hits)
            rows[fabric] = {"covered": hits, "n_covered": int(sum(hits.values())), "n_free": len(hits),
                            "converged": post.converged, "stop_reason": post.stop_reason, "steps": post.steps,
                            "walkers": post.walkers, "max_tau": float(np.max(post.tau)),
                            "fit_wall_time_s": fit.timings["optimisation_s"], "wall_time_s": post.wall_time,
                            "intervals": {n: [e["p2.5"], e["p97.5"], e.get("truth")] for n, e in params.items()}}
    fraction = inside / total if total else math.nan
    return {"fabrics": rows, "covered": inside, "total": total, "fraction": fraction, "target": COVERAGE_TARGET,
            "passed": bool(total and fraction >= COVERAGE_TARGET),
            "settings": {"walkers": walkers, "steps": steps, "max_steps": max_steps, "seed": seed,
                         "optimizer": dict(optimizer or {})}}


def likelihood_paths(problem, unit_points: np.ndarray, *, repeats: int = 3) -> dict:
    """The batched log-probability (one call per ensemble half, as emcee's ``vectorize=True`` calls it) against
    the scalar path (walker by walker, :mod:`clothlab.studies.scalar_path`) on the same walkers, in one run:
    seconds per walker of each (best of ``repeats``, CPU time), their ratio and the largest relative difference
    of the values."""
    from clothlab.fit.posterior.likelihood import _Likelihood
    from clothlab.studies.scalar_path import scalar_log_prob

    like = _Likelihood(problem)
    X = np.atleast_2d(unit_points)
    halves = [X[i:i + 16] for i in range(0, len(X), 16)]
    batched, scalar = float("inf"), float("inf")
    for _ in range(repeats):  # alternated, so a load change hits both
        t = time.process_time()
        got = np.concatenate([like(h) for h in halves])
        batched = min(batched, time.process_time() - t)
        t = time.process_time()
        ref = np.concatenate([scalar_log_prob(like, h) for h in halves])
        scalar = min(scalar, time.process_time() - t)
    return {"walkers": len(X), "batched_s_per_walker": batched / len(X), "scalar_s_per_walker": scalar / len(X),
            "ratio": scalar / batched, "max_relative_difference": float(np.max(np.abs(got - ref) / np.abs(ref)))}


def run(context) -> dict:
    """Bench section ``posterior``: :func:`posterior_benchmark` of the noisy polyester-lining set, limit
    10 minutes (the quick run caps it at 1 minute and will usually report 'not converged'); then the scalar and
    the batched log-probability on 64 walkers of the fit's neighbourhood, side by side, with the scalar path's
    posterior time estimated from its cost per walker (steps x walkers x seconds per walker)."""
    import os

    from clothlab.fit.runner import run_fit

    with study_data(context.data) as d:
        fit = run_fit(optimisation_only(d.load_config("polyester-lining"), max_evals=300, starts=1))
    rng = np.random.default_rng(0)
    x = fit.problem.to_unit(fit.params)
    points = np.clip(x[None] + 1e-3 * rng.standard_normal((64, len(x))), 0.0, 1.0)
    paths = likelihood_paths(fit.problem, points, repeats=1 if context.quick else 3)
    t, c = time.perf_counter(), time.process_time()
    result = posterior_benchmark("polyester-lining", max_minutes=1.0 if context.quick else 10.0, data=context.data,
                                 progress=False, variants=VARIANTS)
    result["posterior_cpu_s"] = result["by_variant"][variant_name(*VARIANTS[0])]["cpu_s"]  # the default alone
    result["section_cpu_s"] = time.process_time() - c
    result["load_average_1min"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    result["paths"] = paths
    result["scalar_posterior_estimate_s"] = result["steps"] * result["walkers"] * paths["scalar_s_per_walker"]
    result["benchmark_wall_s"] = time.perf_counter() - t
    return result


def lines(p: dict) -> list[str]:
    paths = p.get("paths")
    out = [f"== posterior ({p['fabric']}, {len(p['free'])} free, {p['walkers']} walkers) ==",
           f"  {p['steps']} steps in {p['posterior_wall_time_s']:.0f} s wall"
           + (f", {p['posterior_cpu_s']:.0f} s CPU (load average {p['load_average_1min']:.1f})"
              if p.get("posterior_cpu_s") is not None and p.get("load_average_1min") is not None else "")
           + f"; converged by its rule: {p['converged']} (within {p['limit_minutes']:g} min: "
           f"{p['within_limit']}); max tau {max(p['tau'].values()):.0f}; not determined: "
           f"{p['not_determined'] or 'none'}"]
    variants = p.get("by_variant") or {}
    if len(variants) > 1:
        out.append(f"  sampler choices side by side (same target, {p['walkers']} walkers, seed 1; first = default):")
        out.append(f"    {'start, moves, stop':34s} {'steps':>6s} {'max tau':>8s} {'min ESS':>8s} {'CPU s':>6s} "
                   f"{'wall s':>7s} {'accept':>6s} {'conv.':>5s} covered")
        for name, r in variants.items():
            hits = [v for v in r["truth_in_95"].values() if v is not None]
            out.append(f"    {name:34s} {r['steps']:6d} {r['max_tau']:8.1f} {r['min_ess']:8.0f} {r['cpu_s']:6.1f} "
                       f"{r['wall_s']:7.1f} {r['acceptance_mean']:6.2f} {'yes' if r['converged'] else 'no':>5s} "
                       f"{sum(hits)}/{len(hits)}")
    runs = p.get("by_moves") or {}
    if len(runs) > 1 and len(variants) <= len(runs):
        first, *others = runs.items()
        for name, r in others:
            out.append(f"  moves {first[0]} vs {name}: {first[1]['steps']} vs {r['steps']} steps, max tau "
                       f"{first[1]['max_tau']:.0f} vs {r['max_tau']:.0f}, {first[1]['cpu_s']:.0f} vs "
                       f"{r['cpu_s']:.0f} s CPU (ratio {r['cpu_s'] / max(first[1]['cpu_s'], 1e-9):.2f}); converged "
                       f"{first[1]['converged']} / {r['converged']}")
    if paths:
        out.append(f"  log-probability per walker (CPU): scalar path {1e3 * paths['scalar_s_per_walker']:.3f} ms, "
                   f"batched {1e3 * paths['batched_s_per_walker']:.3f} ms, ratio {paths['ratio']:.1f}x "
                   f"(values agree to {paths['max_relative_difference']:.1e} relative); the scalar path would "
                   f"take ~{p['scalar_posterior_estimate_s']:.0f} s CPU for these {p['steps']} steps")
    return out
