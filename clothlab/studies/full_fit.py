"""Bench section ``fit``: optimisation wall time of one full fit of the noisy polyester-lining example as its
fabric.yaml configures the optimiser (global GN_CRS2_LM + local LN_BOBYQA, six free parameters, 1,575 x 3
values; no cross-validation or posterior), against the target of :data:`FIT_TARGET_S`."""

from __future__ import annotations

import time

from clothlab.studies.data import StudyData, study_data

FIT_TARGET_S = 3.0
"""Target: one full fit (all starts + polish, six free parameters, 1,575 x 3 values) in under 3 s."""
FABRIC = "polyester-lining"


def full_fit(quick: bool, *, data: StudyData | None = None, max_evals=None) -> dict:
    """One full fit (all its starts, global + local stages and the final polish; the quick run: one start of
    1,000 evaluations, or ``max_evals`` when given), cross-validation and the posterior off (they are timed by
    their own sections), so the reported wall time is the optimisation's (``FitResult.timings
    ["optimisation_s"]``: loading, all stages, coefficients at the optimum) against FIT_TARGET_S."""
    from clothlab.fit.runner import run_fit
    from clothlab.studies.posterior import optimisation_only

    with study_data(data) as d:
        config = d.load_config(FABRIC)
        if quick or max_evals:
            evals = max_evals or 1000
            cfg = optimisation_only(config, max_evals=evals, starts=1)
        else:
            evals = config.fit.optimizer.max_evals + config.fit.optimizer.polish_evals
            cfg = optimisation_only(config)
        result = run_fit(cfg)
    seconds = float(result.timings["optimisation_s"])
    return {"fabric": f"{FABRIC} (noisy)", "free": list(result.problem.free),
            "values": int(result.problem.y.size), "evaluations": int(result.optimum.nevals), "budget": evals,
            "starts": cfg.fit.optimizer.starts, "wall_time_s": seconds,
            "total_wall_time_s": result.wall_time, "seconds_per_evaluation": seconds / result.optimum.nevals,
            "cross_validation": result.cross_validation is not None, "posterior": result.posterior is not None,
            "target_s": FIT_TARGET_S, "meets_target": seconds < FIT_TARGET_S,
            "p50": result.errors["overall"]["p50"], "p80": result.errors["overall"]["p80"]}


class _ScalarObjective:
    """A fit problem's objective by the scalar path (:mod:`clothlab.studies.scalar_path`): the "before"."""

    def __init__(self, problem):
        self.problem, self.free = problem, problem.free

    def __call__(self, x) -> float:
        from clothlab.studies.scalar_path import scalar_objective

        return scalar_objective(self.problem, x)


def before_after(quick: bool, *, data: StudyData | None = None, repeats: int = 200, max_evals=None) -> dict:
    """In one run: one objective evaluation (the example's 1,575 x 3 values, trapezoid 11) by the scalar and the
    batched path on the same points (CPU time per evaluation, best of alternated rounds), and one full fit
    (all starts + polish; the quick run: one start of 1,000 evaluations, or ``max_evals``) by each path from
    the same start and seed, with both optima."""
    import numpy as np

    from clothlab.fit.optimize import multistart_minimize
    from clothlab.fit.problem import build_problem
    from clothlab.studies.posterior import optimisation_only
    from clothlab.studies.scalar_path import scalar_objective

    with study_data(data) as d:
        config = d.load_config(FABRIC)
        if quick or max_evals:
            config = optimisation_only(config, max_evals=max_evals or 1000, starts=1)
        problem = build_problem(config)
    rng = np.random.default_rng(0)
    x0 = problem.to_unit(problem.start)
    points = np.clip(x0[None] + 0.05 * rng.standard_normal((20 if quick else repeats, len(x0))), 0.0, 1.0)
    best = {"scalar": float("inf"), "batched": float("inf")}
    for _ in range(3):
        for name, fn in (("scalar", lambda x: scalar_objective(problem, x)), ("batched", problem)):
            t = time.process_time()
            for x in points:
                fn(x)
            best[name] = min(best[name], (time.process_time() - t) / len(points))
    fits = {}
    for name, fn in (("scalar", _ScalarObjective(problem)), ("batched", problem)):
        t, c = time.perf_counter(), time.process_time()
        result = multistart_minimize(fn, x0, config.fit.optimizer)
        fits[name] = {"wall_s": time.perf_counter() - t, "cpu_s": time.process_time() - c,
                      "objective": float(result.fun), "evaluations": int(result.nevals), "x": result.x.tolist()}
    scale = np.maximum(np.abs(np.array(fits["scalar"]["x"])), 1e-12)
    return {"objective_s": best, "objective_ratio": best["scalar"] / best["batched"], "fits": fits,
            "optimum_relative_difference": abs(fits["scalar"]["objective"] - fits["batched"]["objective"])
            / fits["scalar"]["objective"],
            "x_max_difference": float(np.max(np.abs(np.array(fits["scalar"]["x"]) - fits["batched"]["x"]) / scale)),
            "values": int(problem.y.size)}


def run(context) -> dict:
    result = full_fit(context.quick, data=context.data)
    result["before_after"] = before_after(context.quick, data=context.data)
    return result


def _before_after_lines(b: dict) -> list[str]:
    s, f = b["objective_s"], b["fits"]
    return [f"  one objective evaluation ({b['values']:,d} values, CPU): scalar path {1e3 * s['scalar']:.3f} ms, "
            f"batched {1e3 * s['batched']:.3f} ms, ratio {b['objective_ratio']:.1f}x",
            f"  full fit, same start and seed: scalar path {f['scalar']['wall_s']:.1f} s wall / "
            f"{f['scalar']['cpu_s']:.1f} s CPU ({f['scalar']['evaluations']} evaluations), batched "
            f"{f['batched']['wall_s']:.1f} s wall / {f['batched']['cpu_s']:.1f} s CPU "
            f"({f['batched']['evaluations']}); optima differ by {b['optimum_relative_difference']:.1e} relative "
            f"(unit coordinates by up to {b['x_max_difference']:.1e})"]


def lines(f: dict) -> list[str]:
    return [f"== one full fit ({f['fabric']}, {len(f['free'])} free, {f['values']:,d} values, "
            f"{f['evaluations']} evaluations, {f['starts']} start(s) + polish, no cross-validation or posterior) ==",
            f"  optimisation wall time {f['wall_time_s']:.1f} s ({1e3 * f['seconds_per_evaluation']:.2f} "
            f"ms/evaluation); target < {f['target_s']:g} s: {'met' if f['meets_target'] else 'NOT met'}; "
            f"median {100 * f['p50']:.2f} %, 80th {100 * f['p80']:.2f} %"] + (
        _before_after_lines(f["before_after"]) if "before_after" in f else [])
