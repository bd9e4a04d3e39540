"""Bench section ``scaleout``: the same work sequential and on a 2-worker Dask LocalCluster, side by side
(issue 13; docs/parallel.md).

1. batch: the six example IM fits (cross-validation as configured, no posterior; the quick run one start of
   :data:`QUICK_EVALS` evaluations) by :func:`clothlab.fit.batch.run_batch` in-process and on the cluster:
   wall-time ratio sequential / 2 workers, with the workers and this process warmed first (kernels loaded; the
   warm-ups are timed on their own, as is the cluster start), and whether every parameter is bit-identical;
2. cross-validation folds: one fit's :data:`CV_FOLDS` neutral fold refits
   (:func:`clothlab.fit.crossval.cross_validate`) in the in-process loop and as one task each on the cluster:
   ratio and whether every figure is identical (the quick run :data:`CV_QUICK_EVALS` evaluations per fold);
3. per-task overhead: :data:`OVERHEAD_TASKS` empty tasks through the cluster (submit, run, result) per task;
4. check: the whole extremes sweep of ``check --full`` in chunks
   (:func:`clothlab.studies.stability.sweep_chunked`; a few seconds), ratio and equal findings;
5. posterior crossover: one log-probability call of W walkers in-process and through the pool for a few
   walker counts and table sizes (the point where the pool starts to win; ``pool="auto"`` measures the same at
   run time).

Nothing is written under the data directory: fits go to a temporary directory.  Needs the Dask extra; without
it the section says so and measures nothing.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from clothlab.studies.data import StudyData, study_data

FABRICS = ("cotton-denim", "silk-shantung", "silk-charmeuse", "cotton-twill", "wool-gabardine", "polyester-lining")
QUICK_EVALS = 1500
OVERHEAD_TASKS = 60
CV_FABRIC = "polyester-lining"
CV_FOLDS = 5
CV_QUICK_EVALS = 400
WORKERS = 2


def _noop(x):
    return x


def _warm():
    """Load the compiled kernels in a worker (what its first real task would pay)."""
    import numpy as np

    from clothlab.studies.stability import _evaluate

    d = np.array([[0.0, 0.6, 0.8]])
    params = {"alpha": 0.01, "beta": 4.0, "delta": 0.3, "warp.psi": -30.0, "warp.umax": 30.0,
              "warp.kappa": 0.0, "warp.w": 1.0, "warp.l": 3.0}
    for rule in (("trapezoid", 11), ("support", 8)):
        _evaluate(d, d, params, rule)
        _evaluate(d, d, {**params, "warp.psi": 0.0}, rule)
    return True


def _items(data, fits_dir: Path, quick: bool):
    from dataclasses import replace

    from clothlab.fit.batch import plan_batch

    configs = []
    for fabric in FABRICS:
        cfg = data.load_config(fabric)
        fit = replace(cfg.fit, posterior=None)
        if quick:
            fit = replace(fit, optimizer=replace(fit.optimizer, max_evals=QUICK_EVALS, starts=1))
        configs.append(replace(cfg, fit=fit))
    items, _ = plan_batch(configs, fits_dir=fits_dir, force=True)
    return items


def _timed(fn):
    tic = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - tic


def _cv_job(data, quick: bool):
    """A function running the cross-validation of :data:`CV_FABRIC` on a runner (None: the in-process loop)."""
    from clothlab.fit.crossval import cross_validate
    from clothlab.fit.problem import build_problem

    cfg = data.load_config(CV_FABRIC)
    problem = build_problem(cfg)
    kwargs = {"k": CV_FOLDS, "seed": cfg.fit.optimizer.seed, "max_evals": CV_QUICK_EVALS if quick else None,
              "percentiles": cfg.report.percentiles, "refit": "neutral", "optimizer": cfg.fit.optimizer}
    return lambda runner: cross_validate(problem, problem.start, runner=runner, **kwargs)


def _figures(cv: dict) -> dict:
    return {key: value for key, value in cv.items() if key != "wall_time_s"}


def run(context) -> dict:
    try:
        from clothlab.parallel import require_dask

        require_dask()
    except Exception as exc:  # noqa: BLE001 - the section reports why it measured nothing
        return {"skipped": str(exc)}
    return scaleout(context.quick, data=context.data)


def scaleout(quick: bool, *, data: StudyData | None = None) -> dict:
    """The figures of the module docstring (one run, sequential and 2 workers side by side)."""
    import numpy as np

    from clothlab.fit.batch import run_batch
    from clothlab.parallel import InProcessRunner, make_runner
    from clothlab.studies import stability as check

    out: dict = {"workers": WORKERS, "quick": quick}
    with study_data(data) as d, tempfile.TemporaryDirectory(prefix="clothlab-scaleout-") as tmp:
        tmp = Path(tmp)
        _, local_warm_s = _timed(_warm)  # this process warmed like the workers: the ratio compares warm runs
        seq_rows, seq_s = _timed(lambda: run_batch(_items(d, tmp / "seq", quick), InProcessRunner()))
        cv_folds = _cv_job(d, quick)
        seq_cv, seq_cv_s = _timed(lambda: cv_folds(None))
        rng = np.random.default_rng(0)
        wi, wo = check.check_directions(200, rng)
        grid = check.grid_parameter_sets(fast=False)
        random_sets = check.random_parameter_sets(4000, rng)
        jobs = [(f"{r[0]}-{r[1]}", r, part, sets) for r in check.RULES_CHECKED
                for part, sets in (("grid", grid), ("random", random_sets))]
        seq_sweep, seq_sweep_s = _timed(lambda: check.sweep_chunked(jobs, wi, wo, InProcessRunner(), tmp / "c1"))
        local = InProcessRunner()
        _, local_overhead = _timed(lambda: local.map(_noop, range(OVERHEAD_TASKS), progress=False))
        runner, start_s = _timed(lambda: make_runner(workers=WORKERS))
        with runner:
            _, warm_s = _timed(lambda: runner.client.run(_warm))
            par_rows, par_s = _timed(lambda: run_batch(_items(d, tmp / "par", quick), runner))
            par_cv, par_cv_s = _timed(lambda: cv_folds(runner))
            _, overhead = _timed(lambda: runner.map(_noop, range(OVERHEAD_TASKS), progress=False))
            par_sweep, par_sweep_s = _timed(lambda: check.sweep_chunked(jobs, wi, wo, runner, tmp / "c2"))
            out["posterior"] = _crossover(runner, d, quick)
        n_chunks = len(list((tmp / "c1").glob("*.npz")))
    identical = all(a["status"] == b["status"] == "fitted" and a["params"] == b["params"]
                    for a, b in zip(seq_rows, par_rows, strict=True))
    out.update({
        "batch": {"fits": len(seq_rows), "evaluations_each": QUICK_EVALS if quick else "as configured",
                  "sequential_s": seq_s, "workers_s": par_s, "ratio": seq_s / par_s,
                  "cluster_start_s": start_s, "worker_warm_up_s": warm_s,
                  "in_process_warm_up_s": local_warm_s, "identical_parameters": identical},
        "cv_folds": {"fabric": CV_FABRIC, "folds": seq_cv["k"], "evaluations_each": seq_cv["budget"],
                     "sequential_s": seq_cv_s, "workers_s": par_cv_s, "ratio": seq_cv_s / par_cv_s,
                     "identical": _figures(seq_cv) == _figures(par_cv)},
        "overhead": {"tasks": OVERHEAD_TASKS, "cluster_ms_per_task": 1e3 * overhead / OVERHEAD_TASKS,
                     "in_process_ms_per_task": 1e3 * local_overhead / OVERHEAD_TASKS},
        "check": {"parameter_sets_per_rule": len(grid) + len(random_sets), "directions": len(wi),
                  "chunk_sets": check.CHUNK_SETS, "chunks": n_chunks, "sequential_s": seq_sweep_s,
                  "workers_s": par_sweep_s, "ratio": seq_sweep_s / par_sweep_s,
                  "same_findings": seq_sweep == par_sweep,
                  "configurations": sum(p["configurations"] for r in seq_sweep.values() for p in r.values())},
    })
    return out


def _crossover(runner, data, quick: bool) -> list[dict]:
    """One log-probability call of W walkers in-process and through the pool (best of 2), per table size."""
    import numpy as np

    from clothlab.fit.posterior.likelihood import _Likelihood
    from clothlab.fit.posterior.sampler import _best_time, _PooledLogProb
    from clothlab.fit.problem import FitProblem, build_problem

    problem = build_problem(data.load_config("polyester-lining"))
    rows = []
    for every in (8, 1):  # a reduced table and the whole one
        m = problem.measurement.subset(np.arange(problem.measurement.n)[::every])
        sub = FitProblem(problem.model, m, problem.free, problem.start,
                         {n: (lo, hi) for n, lo, hi in zip(problem.free, problem.lower, problem.upper, strict=True)},
                         problem.metric)
        like = _Likelihood(sub)
        pooled = _PooledLogProb(like, runner)
        rng = np.random.default_rng(0)
        for walkers in ((16, 64) if quick else (16, 64, 256)):
            X = 0.5 + 0.01 * rng.standard_normal((walkers, like.ndim))
            pooled(X)  # warm-up
            local_s, pool_s = _best_time(like, X), _best_time(pooled, X)
            rows.append({"directions": int(m.n), "walkers": walkers, "in_process_s": local_s, "pool_s": pool_s,
                         "pool_wins": pool_s < local_s})
    return rows


def lines(result: dict) -> list[str]:
    if "skipped" in result:
        return ["== scale-out (Dask) ==", f"  skipped: {result['skipped']}"]
    b, o, c, f = result["batch"], result["overhead"], result["check"], result["cv_folds"]
    out = ["== scale-out: sequential vs a 2-worker Dask LocalCluster ==",
           f"  batch of {b['fits']} example fits (no posterior, evaluations: {b['evaluations_each']}): sequential "
           f"{b['sequential_s']:.1f} s, {result['workers']} workers {b['workers_s']:.1f} s -> ratio {b['ratio']:.2f}; "
           f"parameters bit-identical: {b['identical_parameters']}",
           f"  (cluster start {b['cluster_start_s']:.1f} s and worker warm-up {b['worker_warm_up_s']:.1f} s, paid "
           f"once, not in the ratio; this process warmed the same way first, "
           f"{b.get('in_process_warm_up_s', float('nan')):.1f} s)",
           f"  cross-validation folds of one fit ({f['fabric']}, {f['folds']} neutral fold refits of "
           f"{f['evaluations_each']} evaluations + polish, one task each): sequential {f['sequential_s']:.1f} s, "
           f"{result['workers']} workers {f['workers_s']:.1f} s -> ratio {f['ratio']:.2f}; every figure identical: "
           f"{f['identical']}",
           f"  per-task overhead: {o['cluster_ms_per_task']:.1f} ms on the cluster, "
           f"{o['in_process_ms_per_task']:.3f} ms in-process ({o['tasks']} empty tasks)",
           f"  check extremes sweep ({c['parameter_sets_per_rule']} sets x {c['directions']} directions per rule, "
           f"{c['configurations']:,d} configurations, {c['chunks']} chunks of <= {c['chunk_sets']}): sequential "
           f"{c['sequential_s']:.1f} s, workers {c['workers_s']:.1f} s -> ratio {c['ratio']:.2f}; same findings: "
           f"{c['same_findings']}",
           "  posterior log-probability, one call (in-process vs pool of 2):"]
    for r in result["posterior"]:
        out.append(f"    {r['directions']:5d} directions x {r['walkers']:4d} walkers: "
                   f"{1e3 * r['in_process_s']:8.1f} ms vs {1e3 * r['pool_s']:8.1f} ms -> "
                   f"{'pool' if r['pool_wins'] else 'in-process'}")
    return out
