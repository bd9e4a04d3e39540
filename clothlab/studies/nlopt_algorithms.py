"""Bench section ``fit_algorithms``: objective value against wall time for every supported nlopt algorithm
on the noisy example data - globals followed by the default local polish, locals alone - from the same start
(the example fabric.yaml's), on the same data, with the same evaluation budget and seed; table and plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from clothlab.studies.data import StudyData, study_data
from clothlab.studies.timing import clear_memo

FIT_DATA = ("polyester-lining", "cotton-denim")


def nlopt_algorithms(quick: bool, *, data: StudyData | None = None, figures_dir=None, fabrics=FIT_DATA,
                     max_evals=None) -> dict:
    """Per fabric: one row per algorithm (objective, evaluations, wall time, status, a thinned trace of the
    best objective so far against time) and ``excess`` = objective / best objective - 1."""
    from clothlab.fit.optimize import SUPPORTED_GLOBAL, SUPPORTED_LOCAL, minimize
    from clothlab.fit.runner import build_problem

    max_evals = max_evals or (300 if quick else 3000)
    out = {"max_evals": max_evals, "fabrics": {}}
    runs = [(g, "LN_BOBYQA") for g in SUPPORTED_GLOBAL] + [(None, loc) for loc in SUPPORTED_LOCAL]
    with study_data(data) as d:
        problems = {name: build_problem(d.load_config(name)) for name in fabrics}
    for name, problem in problems.items():
        k = len(problem.free)
        x0 = problem.to_unit(problem.start)
        rows = []
        for global_alg, local_alg in runs:
            clear_memo(problem.model)
            result = minimize(problem, x0, np.zeros(k), np.ones(k), global_algorithm=global_alg,
                              local_algorithm=local_alg, max_evals=max_evals, seed=1)
            trace = result.trace
            keep = np.unique(np.geomspace(1, len(trace), 60).astype(int) - 1) if trace else []
            rows.append({"algorithm": f"{global_alg} + {local_alg}" if global_alg else local_alg,
                         "objective": float(result.fun), "evaluations": int(result.nevals),
                         "wall_time_s": float(result.wall_time), "status": result.message,
                         "trace_time_s": [trace[i].time for i in keep], "trace_best": [trace[i].best for i in keep]})
        best = min(r["objective"] for r in rows)
        for r in rows:
            r["excess"] = r["objective"] / best - 1.0
        out["fabrics"][name] = {"free": list(problem.free), "start_objective": float(problem(x0)), "rows": rows}
    if figures_dir is not None and out["fabrics"]:
        out["figure"] = str(plot_nlopt_algorithms(out, Path(figures_dir) / "fit_algorithms.png"))
    return out


def plot_nlopt_algorithms(result: dict, path: Path) -> Path:
    """Best objective so far against wall time (log-log), one line per algorithm, one panel per data set."""
    from matplotlib.figure import Figure

    names = list(result["fabrics"])
    fig = Figure(figsize=(6.5 * len(names), 4.5), layout="constrained")
    for k, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), k + 1)
        for r in result["fabrics"][name]["rows"]:
            ax.loglog(np.maximum(r["trace_time_s"], 1e-4), r["trace_best"], lw=1.2,
                      ls="-" if "+" in r["algorithm"] else "--", label=r["algorithm"])
        ax.set_title(f"{name} (noisy), {result['max_evals']} evaluations", fontsize=10)
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("best objective so far")
        ax.legend(fontsize=6)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def run(context) -> dict:
    return nlopt_algorithms(context.quick, data=context.data, figures_dir=context.figures_dir)


def lines(result: dict) -> list[str]:
    out = [f"== fit: objective against wall time, every supported nlopt algorithm, {result['max_evals']} "
           "evaluations each, same start and data =="]
    for name, f in result["fabrics"].items():
        out += ["", f"  {name} (noisy; free {', '.join(f['free'])}; start objective {f['start_objective']:.4e})",
                f"  {'algorithm':26s} {'objective':>11s} {'excess':>9s} {'evals':>6s} {'time s':>7s}  status"]
        for r in sorted(f["rows"], key=lambda r: r["objective"]):
            out.append(f"  {r['algorithm']:26s} {r['objective']:11.5e} {100 * r['excess']:8.3f}% "
                       f"{r['evaluations']:6d} {r['wall_time_s']:7.2f}  {r['status']}")
    if "figure" in result:
        out.append(f"  plot: {result['figure']}")
    return out
