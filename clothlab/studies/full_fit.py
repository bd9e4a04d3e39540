"""Bench section ``fit``: optimisation wall time of one full fit of the noisy polyester-lining example as its
fabric.yaml configures the optimiser (global GN_CRS2_LM + local LN_BOBYQA, six free parameters, 1,575 x 3
values; no cross-validation or posterior), against the target of :data:`FIT_TARGET_S`."""

from __future__ import annotations

from clothlab.studies.data import StudyData, study_data

FIT_TARGET_S = 20.0
"""Target: one full fit (global + local, six free parameters, 1,575 x 3 values) in under 20 s."""
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


def run(context) -> dict:
    return full_fit(context.quick, data=context.data)


def lines(f: dict) -> list[str]:
    return [f"== one full fit ({f['fabric']}, {len(f['free'])} free, {f['values']:,d} values, "
            f"{f['evaluations']} evaluations, {f['starts']} start(s) + polish, no cross-validation or posterior) ==",
            f"  optimisation wall time {f['wall_time_s']:.1f} s ({1e3 * f['seconds_per_evaluation']:.2f} "
            f"ms/evaluation); target < {f['target_s']:g} s: {'met' if f['meets_target'] else 'NOT met'}; "
            f"median {100 * f['p50']:.2f} %, 80th {100 * f['p80']:.2f} %"]
