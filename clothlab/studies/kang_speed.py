"""Bench section ``kang``: Kang's tile average (papers/003 eqs. 1-4), the previous peak rule against the current
one, timed side by side in one run, each beside its error against a converged reference.

Per preset, at the saved example fit's parameters (``fits/<fabric>-kang``; defaults without one), the
specular components of ``components()`` on the paper's 1,575 directions (the call a fit makes):

- ``previous``: the peak rule as it was (:func:`clothlab.models.kang.kernels.previous_peak_tile_average`, a
  tan per node, node count 2 + ceil(1.5 r + 4 c), eq. 1's factor in numpy per call);
- ``new per pair``: the current rule with the previous path's structure (no cache, no grouping): the rule's
  own speed;
- ``new (fit)``: the current rule as a fit evaluates it - the direction set's parameter-free terms kept
  (``KangModel._at``: yarn-frame half vectors, eq. 1's Fresnel-free factors, groups of equal |h|), the tile
  average recomputed;
- ``new (cold)``: the same with those terms recomputed every call (a new direction set each time).

The four are timed call by call in strict alternation (fastest call; wall and CPU time), so a change in the
shared machine's load hits them alike; the ratio is previous / new.  Errors: the specular total against a
400 x 400-node Gauss-Legendre rule (compiled) on a fixed subset of the directions, relative, floored at 1 %
of the reference's mean.  Then the LoD render's prefiltered weave level (alpha = 1, eq. 5): microseconds per
point, legendre against peak.
"""

from __future__ import annotations

import json

import numpy as np

from clothlab.studies.data import StudyData, paper_directions
from clothlab.studies.timing import alternating_timings, paired_timings

REFERENCE_NODES = 400
COLD_TARGET_PAIRS_PER_S = 1.5e6
"""Issue 27: Kang's tile average on a new direction set (cold) at >= 1.5 M pairs/s."""


def _fitted(data: StudyData, name: str):
    """(model, parameters, fit.json or None) of the saved Kang fit of preset ``name`` (defaults without one)."""
    from clothlab.fit.store import load_fitted
    from clothlab.models.kang.model import KangModel
    from clothlab.weave.presets import get_preset

    fit_dir = data.fit_dir(f"{name}-kang")
    if fit_dir is None:
        model = KangModel(get_preset(name))
        return model, model.default_parameters(), None
    model, params, _, _ = load_fitted(fit_dir)
    fit = json.loads((fit_dir / "fit.json").read_text())
    return model, {k: v for k, v in params.items() if k in model.params}, fit


def reference_specular(model, wi, wo, p, nodes: int = REFERENCE_NODES) -> np.ndarray:
    """The specular total of the tile average with a ``nodes`` x ``nodes`` tensor Gauss-Legendre rule
    over the perturbation rectangle (compiled; converged where its spacing resolves the lobe)."""
    from clothlab.frames import to_yarn_frame
    from clothlab.models.kang import kernels, microfacet
    from clothlab.weave.model import YARN_KINDS

    x, w = np.polynomial.legendre.leggauss(nodes)
    w = w / 2.0
    p = model.resolve(p)
    out = np.zeros(len(wi))
    for kind in YARN_KINDS:
        if model.shares[kind] == 0.0:
            continue
        wi_l, wo_l = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
        nx, ny = model._exponents(kind, p)
        xa, wa = (x, w) if p["yarn_curvature"] > 0.0 else (np.zeros(1), np.ones(1))
        xl, wl = (x, w) if p["fibre_curvature"] > 0.0 else (np.zeros(1), np.ones(1))
        a = kernels.legendre_tile_average(microfacet.half_vector(wi_l, wo_l), float(nx), float(ny),
                                          float(p["yarn_curvature"]), float(p["fibre_curvature"]), xa, wa, xl, wl)
        out += model.shares[kind] * microfacet.ashikhmin_shirley(wi_l, wo_l, 1.0, p["fresnel_f0"]) * a
    return out


def _errors(value, reference) -> dict:
    e = np.abs(value - reference) / np.maximum(reference, 0.01 * reference.mean())
    return {"max": float(e.max()), "p99": float(np.percentile(e, 99))}


def previous_specular(model, wi, wo, p, need=("specular_warp", "specular_weft")) -> dict:
    """The specular components of the previous peak rule (the model's path before the current one, verbatim:
    yarn frame, half vectors and eq. 1's factor in numpy per call, :func:`.kernels.previous_peak_tile_average`
    at most 10 nodes per axis)."""
    from clothlab.frames import to_yarn_frame
    from clothlab.models.kang import kernels, microfacet
    from clothlab.models.kang.model import _gauss_legendre_table
    from clothlab.weave.model import YARN_KINDS

    p = model.resolve(p)
    x_gl, w_gl = _gauss_legendre_table(10)
    out = {}
    for kind in YARN_KINDS:
        if model.shares[kind] == 0.0 or f"specular_{kind}" not in need:
            continue
        wi_l, wo_l = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
        nx, ny = model._exponents(kind, p)
        h = np.ascontiguousarray(microfacet.half_vector(wi_l, wo_l).reshape(-1, 3))
        g = microfacet.ashikhmin_shirley(wi_l, wo_l, 1.0, p["fresnel_f0"])
        a = kernels.previous_peak_tile_average(h, float(nx), float(ny), float(p["yarn_curvature"]),
                                               float(p["fibre_curvature"]), x_gl, w_gl, 10)
        out[f"specular_{kind}"] = model.shares[kind] * g * a
    return out


def per_pair_specular(model, wi, wo, p) -> dict:
    """The specular components of the current rule evaluated pair by pair with the previous path's structure
    (numpy yarn frame and eq. 1 factor per call, no direction cache, no grouping of equal half vectors): the
    rule's own speed, apples to apples with :func:`previous_specular`."""
    from clothlab.frames import to_yarn_frame
    from clothlab.weave.model import YARN_KINDS

    p = model.resolve(p)
    return {f"specular_{kind}": model.shares[kind] * model._peak_average(kind, to_yarn_frame(wi, kind),
                                                                          to_yarn_frame(wo, kind), p)
            for kind in YARN_KINDS if model.shares[kind] > 0.0}


def tile_average_rows(quick: bool, data: StudyData) -> list[dict]:
    """Per preset: pairs/s (wall and CPU) of the previous and the current peak rule (fit / cold), their ratio,
    each one's error against the converged reference, and the saved fit's optimisation time."""
    from clothlab.weave.presets import PRESET_NAMES

    wi, wo = paper_directions()
    subset = np.random.default_rng(0).choice(len(wi), 300, replace=False)
    specular = ("specular_warp", "specular_weft")
    rows = []
    for name in PRESET_NAMES:
        model, p, fit = _fitted(data, name)
        p = model.resolve(p)

        def fit_call(model=model, p=p):
            return model.components(wi, wo, p, need=specular)

        def cold_call(model=model, p=p):
            model.forget_directions()  # forget the direction set's parameter-free terms
            return model.components(wi, wo, p, need=specular)

        def previous_call(model=model, p=p):
            return previous_specular(model, wi, wo, p)

        def per_pair_call(model=model, p=p):
            return per_pair_specular(model, wi, wo, p)

        calls = [previous_call, per_pair_call, cold_call, fit_call]
        for fn in calls:
            fn()  # compile and fill the direction cache outside the timing
        previous, per_pair, cold, warm = alternating_timings(calls, 5 if quick else 15)
        fit_call()
        groups = sum(len(g[0]) for g in model._at(wi, wo)["groups"].values())
        reference = reference_specular(model, wi[subset], wo[subset], p)

        def total(comps):
            return comps["specular_warp"] + comps["specular_weft"]

        row = {"fabric": name, "parameters": "fitted" if fit else "defaults",
               "previous": _rates(previous, len(wi)), "new_fit": _rates(warm, len(wi)),
               "new_cold": _rates(cold, len(wi)), "new_per_pair": _rates(per_pair, len(wi)),
               "speedup_per_pair": previous["cpu_s"] / per_pair["cpu_s"],
               "speedup_fit": previous["cpu_s"] / warm["cpu_s"], "speedup_cold": previous["cpu_s"] / cold["cpu_s"],
               "previous_error": _errors(total(previous_specular(model, wi[subset], wo[subset], p)), reference),
               "new_error": _errors(total(model.components(wi[subset], wo[subset], p, need=specular)), reference),
               "reference_directions": len(subset), "half_vector_groups": groups}
        if fit is not None:
            row["fit_optimisation_s"] = fit["timings"]["optimisation_s"]
        rows.append(row)
    return rows


def cold_rows(quick: bool, data: StudyData) -> list[dict]:
    """Issue 27's Kang rows: per preset the specular components on the 1,575 paper directions cold (a new
    direction set every call) and warm (the set's terms kept), at the defaults and at the saved fit's parameters
    (``fits/<fabric>-kang``; None without one), the four timed in alternation (CPU of this process)."""
    from clothlab.models.kang.model import KangModel
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    wi, wo = paper_directions()
    specular = ("specular_warp", "specular_weft")
    rows = []
    for name in PRESET_NAMES:
        fitted_model, fitted_p, fit = _fitted(data, name)
        cases = {"defaults": (KangModel(get_preset(name)), None)}
        if fit is not None:
            cases["fitted"] = (fitted_model, fitted_model.resolve(fitted_p))
        calls = []
        for model, p in cases.values():
            p = model.resolve(p)

            def warm(model=model, p=p):
                return model.components(wi, wo, p, need=specular)

            def cold(model=model, p=p):
                model.forget_directions()
                return model.components(wi, wo, p, need=specular)

            calls += [cold, warm]
        for fn in calls:
            fn()  # compile outside the timing
        timed = alternating_timings(calls, 10 if quick else 30)
        row = {"fabric": name}
        for k, case in enumerate(cases):
            row[case] = {"cold": _rates(timed[2 * k], len(wi)), "warm": _rates(timed[2 * k + 1], len(wi))}
        rows.append(row)
    return rows


def cold_lines(rows: list[dict]) -> list[str]:
    """The issue-27 Kang rows: M pairs/s from the fastest call's CPU time, cold (warm), defaults and fitted."""
    def cell(r):
        return f"{r['cold']['pairs_per_second_cpu'] / 1e6:6.2f} ({r['warm']['pairs_per_second_cpu'] / 1e6:6.2f})"

    out = ["", "  issue 27: Kang specular components, 1,575 directions, cold (warm) in M pairs/s from the fastest "
               f"call's CPU time; target cold >= {COLD_TARGET_PAIRS_PER_S / 1e6:g} M",
           f"  {'fabric':17s} {'defaults':>17s} {'fitted':>17s}"]
    for r in rows:
        fitted = cell(r["fitted"]) if "fitted" in r else f"{'(no fit)':>17s}"
        out.append(f"  {r['fabric']:17s} {cell(r['defaults']):>17s} {fitted:>17s}")
    return out


def _rates(timing: dict, n: int) -> dict:
    return {"wall_s": timing["wall_s"], "cpu_s": timing["cpu_s"], "pairs_per_second_wall": n / timing["wall_s"],
            "pairs_per_second_cpu": n / timing["cpu_s"]}


def weave_level_row(quick: bool) -> dict:
    """The LoD render's prefiltered weave level (alpha = 1) at the defaults on cotton-denim: us per point."""
    from clothlab.models.kang.model import KangModel
    from clothlab.weave.presets import get_preset

    rng = np.random.default_rng(1)
    n = 500 if quick else 2000
    wi, wo = paper_directions()
    pick = rng.integers(0, len(wi), n)
    u, v = rng.uniform(0.0, 1.0, (2, n))
    weave = get_preset("cotton-denim")
    old, new = KangModel(weave, tile_rule="legendre"), KangModel(weave)
    p = new.default_parameters()

    def run(model):
        return lambda: model.point_components(u, v, wi[pick], wo[pick], p, footprint=1.0)

    new_fn = run(new)
    new_fn()
    t_old, [(t_new, ratio)] = paired_timings(run(old), [new_fn], 2 if quick else 4)
    far_old, far_new = run(old)(), new_fn()
    s_old = far_old["specular_warp"] + far_old["specular_weft"]
    s_new = far_new["specular_warp"] + far_new["specular_weft"]
    return {"points": n, "old_us_per_point": 1e6 * t_old / n, "new_us_per_point": 1e6 * t_new / n,
            "speedup": 1.0 / ratio, "max_rel_difference": float(np.max(np.abs(s_new - s_old)
                                                                       / np.maximum(s_old, 0.01 * s_old.mean())))}


def run(context) -> dict:
    import os

    return {"load_average": os.getloadavg(), "tile_average": tile_average_rows(context.quick, context.data),
            "weave_level": weave_level_row(context.quick), "cold": cold_rows(context.quick, context.data)}


def _pair(error: dict) -> str:
    return f"{100 * error['max']:.3f} / {100 * error['p99']:.3f} %"


def lines(result: dict) -> list[str]:
    load = result.get("load_average")
    out = ["== Kang tile average: previous peak rule vs current, 1,575 paper directions, timed in alternation ==",
           "  pairs/s from the fastest call's CPU time (wall in brackets); ratio = previous / new CPU time; per pair: "
           "the rule alone (no cache, no grouping); fit: the direction set's terms kept (a fit's evaluation); cold: "
           "recomputed every call; groups: distinct |h| (of 3,150) the kernel evaluates",
           f"  error: specular vs a {REFERENCE_NODES} x {REFERENCE_NODES} Gauss-Legendre rule on 300 directions, "
           "max / p99, floored at 1 % of its mean"
           + (f"; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}" if load else ""),
           f"  {'fabric':17s} {'params':8s} {'previous pairs/s':>22s} {'new per pair':>23s} {'ratio':>6s} "
           f"{'new (fit) pairs/s':>23s} {'ratio':>6s} "
           f"{'new (cold) pairs/s':>23s} {'ratio':>6s} {'previous error':>17s} {'new error':>17s} {'groups':>6s} "
           f"{'fit (s)':>7s}"]
    for r in result["tile_average"]:
        fit = f"{r['fit_optimisation_s']:7.1f}" if "fit_optimisation_s" in r else f"{'-':>7s}"

        def rate(x):
            return f"{x['pairs_per_second_cpu']:11,.0f} ({x['pairs_per_second_wall']:9,.0f})"

        out.append(f"  {r['fabric']:17s} {r['parameters']:8s} {rate(r['previous']):>22s} "
                   f"{rate(r['new_per_pair']):>23s} "
                   f"{r['speedup_per_pair']:5.1f}x {rate(r['new_fit']):>23s} "
                   f"{r['speedup_fit']:5.1f}x {rate(r['new_cold']):>23s} {r['speedup_cold']:5.1f}x "
                   f"{_pair(r['previous_error']):>17s} {_pair(r['new_error']):>17s} {r['half_vector_groups']:6d} {fit}")
    w = result["weave_level"]
    out.append(f"  LoD prefiltered weave level (cotton-denim defaults, {w['points']} points, alpha = 1): legendre "
               f"{w['old_us_per_point']:.2f} -> peak {w['new_us_per_point']:.2f} us/point ({w['speedup']:.1f}x), "
               f"max difference {100 * w['max_rel_difference']:.3f} %")
    if "cold" in result:
        out += cold_lines(result["cold"])
    return out
