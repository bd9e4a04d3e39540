"""Bench section ``speed``: direction pairs per second of the two-yarn IM model (Irawan & Marschner 2012,
eq. 10 for warp and weft, phase function eq. 7, diffuse term), RGB, trapezoid 11, on the paper's 1,575
directions (best of repeats), next to a per-direction scipy.integrate.quad loop (their ratio).

Beside it, per preset, the ``support`` rule (4 and 8 Gauss-Legendre nodes per lit piece) against trapezoid-11,
timed call by call in alternation (:func:`support_vs_trapezoid`): the issue-12 target is support within 1.5x.

Then the issue-27 table (:func:`cold_warm_table`): one objective evaluation of the cotton-denim example (1,575 x 3
values) and, per preset, the IM model warm (a fit's evaluation: the direction set's terms kept) against cold (new
directions every call), timed call by call in alternation, in CPU seconds of this process (fastest and median
call), with the load average; the Kang rows are the ``kang`` section's.

The frozen pre-rewrite kernels (issue 10) are no longer timed here: their ratio is reported in docs/notes, and
the frozen copy lives in tests/im_kernels_before.py, where a regression test compares values with it.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from clothlab.studies.data import paper_directions
from clothlab.studies.quad_reference import quad_reference
from clothlab.studies.timing import alternating_timings, best_time, clear_memo, paired_timings

FABRICS = ("polyester-lining", "cotton-denim")
OBJECTIVE_FABRIC = "cotton-denim"
OBJECTIVE_TARGET_S = 0.3e-3
"""Issue 27: one objective evaluation of the cotton-denim example (1,575 x 3 values) within 0.3 ms."""
COLD_TARGET = 1.5
"""Issue 27: a model evaluated at new directions (cold) within this factor of a warm evaluation."""
SUPPORT_NODES = (4, 8)
SUPPORT_TARGET = 1.5
"""The issue-12 target: the support rule's time on 1,575 directions within this factor of trapezoid-11's."""


def model_speed(quick: bool, fabrics=FABRICS) -> dict:
    """Per fabric: pairs_per_second and seconds_1575 of the model, quad_pairs_per_second of the quad loop,
    speedup_vs_quad = pairs_per_second / quad_pairs_per_second."""
    from scipy.integrate import IntegrationWarning

    from clothlab.models.components import combine
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.weave.presets import get_preset

    wi, wo = paper_directions()
    coef = {"kd": np.array([0.2, 0.1, 0.1]), "ks_warp": np.array([0.1, 0.1, 0.1]),
            "ks_weft": np.array([0.1, 0.1, 0.1])}
    out = {}
    for name in fabrics:
        model = IrawanModel(get_preset(name))
        p = model.default_parameters()

        def evaluate(model=model, p=p):
            clear_memo(model)  # time the full evaluation, not the cache
            return combine(model.components(wi, wo, p, normalised=False, warn=False), coef)

        evaluate()
        seconds = best_time(evaluate, 5 if quick else 20)
        n_quad = 20 if quick else 60
        t0 = time.perf_counter()
        with warnings.catch_warnings():  # only timed here; the accuracy sections count quad's warnings
            warnings.simplefilter("ignore", IntegrationWarning)
            for kind in ("warp", "weft"):
                quad_reference(wi[:n_quad], wo[:n_quad], p, kind)
        quad_rate = n_quad / (time.perf_counter() - t0)
        out[name] = {"pairs_per_second": len(wi) / seconds, "seconds_1575": seconds,
                     "quad_pairs_per_second": quad_rate, "speedup_vs_quad": len(wi) / seconds / quad_rate}
    return out


def support_vs_trapezoid(quick: bool, fabrics=None) -> dict:
    """Per preset: the whole model (both yarns, raw components) on the 1,575 directions with trapezoid-11 and
    with support-n (n in :data:`SUPPORT_NODES`), each support rule timed in alternation with trapezoid-11
    (:func:`clothlab.studies.timing.paired_timings`).

    ``warm``: a fit's evaluation - the direction set's parameter-free terms kept (for support the staple
    integrand's lit pieces, for both rules the filament moments), the integrals recomputed (memo cleared);
    ``cold``: a new direction set every call (those terms computed too, as for a single evaluation)."""
    from clothlab.models.irawan.model import IrawanModel, Quadrature
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    wi, wo = paper_directions()
    rounds = 3 if quick else 9
    out = {}
    for name in fabrics or PRESET_NAMES:
        weave = get_preset(name)
        row = {}
        for mode in ("warm", "cold"):
            def runner(q, weave=weave, mode=mode):
                model = IrawanModel(weave, q)
                p = model.default_parameters()

                def evaluate():
                    if mode == "cold":
                        model.forget_directions()  # forget the direction set's terms
                    clear_memo(model)
                    return model.components(wi, wo, p, normalised=False, warn=False)
                evaluate()
                return evaluate
            base = runner(Quadrature("trapezoid", 11))
            fns = [runner(Quadrature("support", n)) for n in SUPPORT_NODES]
            base_s, timed = paired_timings(base, fns, rounds)
            row[mode] = {"trapezoid11_ms": 1e3 * base_s,
                         **{f"support{n}_ms": 1e3 * t for n, (t, _) in zip(SUPPORT_NODES, timed, strict=True)},
                         **{f"support{n}_ratio": r for n, (_, r) in zip(SUPPORT_NODES, timed, strict=True)}}
        row["within_target"] = {n: row["warm"][f"support{n}_ratio"] <= SUPPORT_TARGET for n in SUPPORT_NODES}
        out[name] = row
    return out


def support_lines(result: dict) -> list[str]:
    """The support-vs-trapezoid-11 table (ms per 1,575 directions and the paired ratio)."""
    heads = "".join(f" {'support-' + str(n):>10s} {'x t11':>6s}" for n in SUPPORT_NODES)
    out = ["", f"  support rule vs trapezoid-11, whole model, 1,575 directions (target <= {SUPPORT_TARGET}x; warm: "
           "a fit's evaluation, lit pieces kept; cold: new directions every call)",
           f"  {'fabric':18s} {'mode':5s} {'t11 ms':>7s}{heads}"]
    for name, row in result.items():
        for mode in ("warm", "cold"):
            r = row[mode]
            cells = "".join(f" {r[f'support{n}_ms']:10.3f} {r[f'support{n}_ratio']:6.2f}" for n in SUPPORT_NODES)
            out.append(f"  {name:18s} {mode:5s} {r['trapezoid11_ms']:7.3f}{cells}")
    met = {n: sum(bool(row["within_target"][n]) for row in result.values()) for n in SUPPORT_NODES}
    out.append("  within the target (warm): " + ", ".join(f"support-{n} on {k} of {len(result)} fabrics"
                                                         for n, k in met.items()))
    return out


def objective_timing(quick: bool, data) -> dict:
    """CPU seconds of one objective evaluation (``FitProblem.__call__``: the model's components at the measured
    directions, then the NNLS) of the :data:`OBJECTIVE_FABRIC` example (its fabric.yaml) at points near its
    start, every call timed: the fastest and the median over all calls of two rounds."""
    import statistics

    from clothlab.fit.problem import build_problem

    problem = build_problem(data.load_config(OBJECTIVE_FABRIC))
    rng = np.random.default_rng(0)
    x0 = problem.to_unit(problem.start)
    points = np.clip(x0[None] + 0.05 * rng.standard_normal((100 if quick else 400, len(x0))), 0.0, 1.0)
    for x in points[:5]:
        problem(x)  # compile, fill the direction terms
    calls = []
    for _ in range(2):
        for x in points:
            t = time.process_time()
            problem(x)
            calls.append(time.process_time() - t)
    return {"fabric": OBJECTIVE_FABRIC, "values": int(problem.y.size), "calls": len(calls),
            "cpu_fastest_s": min(calls), "cpu_median_s": statistics.median(calls), "target_s": OBJECTIVE_TARGET_S}


def im_cold_warm(quick: bool, fabrics=None) -> dict:
    """Per preset: the whole IM model (raw components, trapezoid-11, the preset's parameters) on the 1,575 paper
    directions, warm (the memo of integrals cleared, the direction set's terms kept: a fit's evaluation) and cold
    (the direction set forgotten too: eval, render, CV, the surrogate's R), in alternation
    (:func:`clothlab.studies.timing.alternating_timings`); ratio = cold / warm CPU time (fastest, median)."""
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    wi, wo = paper_directions()
    out = {}
    for name in fabrics or PRESET_NAMES:
        model = IrawanModel(get_preset(name))
        p = model.default_parameters()

        def warm(model=model, p=p):
            model.forget_results()
            return model.components(wi, wo, p, normalised=False, warn=False)

        def cold(model=model, p=p):
            model.forget_directions()
            return model.components(wi, wo, p, normalised=False, warn=False)

        warm_t, cold_t = alternating_timings([warm, cold], 100 if quick else 400, min_sample_s=0.0)
        out[name] = {"warm": warm_t, "cold": cold_t, "ratio": cold_t["cpu_s"] / warm_t["cpu_s"],
                     "ratio_median": cold_t["cpu_median_s"] / warm_t["cpu_median_s"]}
    return out


def cold_warm_table(quick: bool, data) -> dict:
    """The issue-27 rows of this section: :func:`objective_timing` and :func:`im_cold_warm`, with the load."""
    import os

    return {"load_average": os.getloadavg(), "objective": objective_timing(quick, data), "im": im_cold_warm(quick)}


def cold_warm_lines(table: dict) -> list[str]:
    """The issue-27 rows: the objective, then IM warm / cold per preset (CPU ms per 1,575 directions)."""
    o = table["objective"]
    load = table["load_average"]
    out = ["", f"  issue 27 (CPU time of this process, every call timed; load average {load[0]:.2f} {load[1]:.2f} "
               f"{load[2]:.2f}):",
           f"  one objective evaluation, {o['fabric']} {o['values']:,d} values: fastest {1e3 * o['cpu_fastest_s']:.3f} "
           f"ms, median {1e3 * o['cpu_median_s']:.3f} ms of {o['calls']} calls (target <= {1e3 * o['target_s']:g} ms)",
           f"  IM whole model, trapezoid-11, 1,575 directions, ms (fastest / median); target cold <= {COLD_TARGET}x "
           "warm",
           f"  {'fabric':18s} {'warm':>15s} {'cold':>15s} {'cold/warm':>11s}"]
    for name, r in table["im"].items():
        w, c = r["warm"], r["cold"]
        out.append(f"  {name:18s} {1e3 * w['cpu_s']:7.3f} {1e3 * w['cpu_median_s']:7.3f} "
                   f"{1e3 * c['cpu_s']:7.3f} {1e3 * c['cpu_median_s']:7.3f} {r['ratio']:5.2f} {r['ratio_median']:5.2f}")
    return out


def run(context) -> dict:
    result = {"model": model_speed(context.quick), "support": support_vs_trapezoid(context.quick),
              "cold_warm": cold_warm_table(context.quick, context.data)}
    return result


def lines(result: dict) -> list[str]:
    out = ["== evaluation speed: two-yarn IM model, RGB, trapezoid 11, 1,575 directions =="]
    for name, s in result["model"].items():
        out.append(f"  {name:18s} {s['pairs_per_second']:12,.0f} pairs/s ({1e3 * s['seconds_1575']:.2f} ms per set); "
                   f"quad loop {s['quad_pairs_per_second']:8,.1f} pairs/s; ratio {s['speedup_vs_quad']:,.0f}x")
    if "support" in result:
        out += support_lines(result["support"])
    if "cold_warm" in result:
        out += cold_warm_lines(result["cold_warm"])
    return out
