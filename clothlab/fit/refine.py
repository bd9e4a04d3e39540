"""Refinement of a fit through a neural surrogate with the exact model it learnt (``kind: neural``,
``model.options.refine``; docs/neural.md "Fits with kind: neural").

A multi-material network (``clothlab train-surrogate --vary``) answers other parameter sets through its
encoder (Chen, Wang & Wang 2024, sec. 4.2): a fit through it is a fast approximation, within the network's
own error of the exact model.  :func:`refine_exact` polishes the free parameters from that optimum with the
exact model (the network's target kind, ``model.exact_model()``): the same free parameters, bounds, metric
and loss, coefficients by NNLS as always, the local polish of :func:`clothlab.fit.optimize.polish`.  The fit
keeps its model (kind neural) at the refined parameters; what each stage reached is recorded.
"""

from __future__ import annotations

import time
from dataclasses import replace

from clothlab.fit.optimize import OptimizeResult, polish
from clothlab.fit.problem import FitProblem


def exact_problem(problem: FitProblem) -> FitProblem:
    """``problem`` with its model replaced by the exact model it approximates (same free parameters, bounds
    and unit coordinates, metric and loss)."""
    exact = problem.model.exact_model()
    bounds = {name: (float(lo), float(hi)) for name, lo, hi in zip(problem.free, problem.lower, problem.upper,
                                                                    strict=True)}
    return FitProblem(exact, problem.measurement, problem.free, problem.start, bounds, problem.metric,
                      loss=problem.loss, loss_scale=problem.loss_scale, orientation_nodes=problem.orientation_nodes)


def refine_exact(problem: FitProblem, optimum: OptimizeResult, opt, callback=None) -> tuple[OptimizeResult, dict]:
    """Polish ``optimum`` (of ``problem``, the fit through the network) with the exact model; ``opt``: the
    fit's optimizer settings (its local algorithm; budget ``opt.polish_evals``, at least 50 evaluations).
    Returns (the optimum at the refined parameters with ``fun`` = ``problem``'s objective there and the
    evaluations of both stages, the record of the refinement for fit.json)."""
    started = time.perf_counter()
    exact = exact_problem(problem)
    start_value = exact(optimum.x)
    seed = replace(optimum, fun=start_value, trace=[], nevals=0, wall_time=0.0)
    budget = replace(opt, polish=max(50, opt.polish_evals))
    refined = polish(exact, seed, budget, callback)
    encoder = problem.from_unit(optimum.x)
    params = problem.from_unit(refined.x)
    record = {
        "kind": exact.model.kind,
        "encoder": {"params": {k: encoder[k] for k in problem.free}, "objective": float(optimum.fun),
                    "objective_exact": float(start_value)},
        "refined": {"params": {k: params[k] for k in problem.free}, "objective_exact": float(refined.fun)},
        "evaluations": int(refined.nevals),
        "wall_time_s": time.perf_counter() - started,
    }
    trace = list(optimum.trace) + [row._replace(index=row.index + optimum.nevals, time=row.time + optimum.wall_time,
                                                stage="refine") for row in refined.trace]
    status = dict(optimum.status, refine=f"{refined.nevals} evaluations of the exact {exact.model.kind} model, "
                                        f"objective {start_value:.6g} -> {refined.fun:.6g}")
    result = replace(optimum, x=refined.x, fun=float(problem(refined.x)), nevals=optimum.nevals + refined.nevals,
                     wall_time=optimum.wall_time + refined.wall_time, trace=trace, status=status,
                     at_lower=refined.at_lower, at_upper=refined.at_upper,
                     message=f"{optimum.message}; refined with the exact {exact.model.kind} model: "
                             f"{refined.nevals} evaluations")
    return result, record
