"""Bench section ``kang``: Kang's tile average (papers/003 eqs. 1-4), previous path against the current one,
timed side by side in one run, each beside its error against a converged reference.

Per preset, at the saved example fit's parameters (``fits/<fabric>-kang``; defaults without one): direction
pairs per second of ``components()`` on the paper's 1,575 directions with ``tile_rule: legendre`` (the
previous numpy Gauss-Legendre rule, adaptive node count) and with the default ``tile_rule: peak`` (the
compiled peak-centred rule, :mod:`clothlab.models.kang.kernels`), timed in alternation, and their ratio;
the relative error of each against a 400 x 400-node Gauss-Legendre rule (compiled) on a fixed subset of
the directions (the specular total, floored at 1 % of its mean); and the saved fit's optimisation time.
Then the LoD render's prefiltered weave level (alpha = 1, eq. 5): microseconds per point, both rules.
"""

from __future__ import annotations

import json

import numpy as np

from clothlab.studies.data import StudyData, paper_directions
from clothlab.studies.timing import paired_timings

REFERENCE_NODES = 400


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


def tile_average_rows(quick: bool, data: StudyData) -> list[dict]:
    from clothlab.models.kang.model import KangModel
    from clothlab.weave.presets import PRESET_NAMES

    wi, wo = paper_directions()
    subset = np.random.default_rng(0).choice(len(wi), 100 if quick else 300, replace=False)
    specular = ("specular_warp", "specular_weft")
    rows = []
    for name in PRESET_NAMES[:2] if quick else PRESET_NAMES:
        new, p, fit = _fitted(data, name)
        old = KangModel(new.weave, alternating=new.alternating, tile_rule="legendre")

        def run(model, p=p):
            return lambda: model.components(wi, wo, p, need=specular)

        old_fn, new_fn = run(old), run(new)
        new_fn()  # compile outside the timing
        t_old, [(t_new, ratio)] = paired_timings(old_fn, [new_fn], 2 if quick else 4)
        reference = reference_specular(new, wi[subset], wo[subset], p)

        def total(model, p=p):
            comps = model.components(wi[subset], wo[subset], p, need=specular)
            return comps["specular_warp"] + comps["specular_weft"]

        row = {"fabric": name, "parameters": "fitted" if fit else "defaults",
               "old_pairs_per_second": len(wi) / t_old, "new_pairs_per_second": len(wi) / t_new,
               "speedup": 1.0 / ratio, "old_error": _errors(total(old), reference),
               "new_error": _errors(total(new), reference), "reference_directions": len(subset)}
        if fit is not None:
            row["fit_optimisation_s"] = fit["timings"]["optimisation_s"]
        rows.append(row)
    return rows


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
    return {"tile_average": tile_average_rows(context.quick, context.data),
            "weave_level": weave_level_row(context.quick)}


def _pair(error: dict) -> str:
    return f"{100 * error['max']:.3f} / {100 * error['p99']:.3f} %"


def lines(result: dict) -> list[str]:
    out = ["== Kang tile average: legendre (previous, numpy) vs peak (compiled), 1,575 directions, same run ==",
           f"  error: specular vs a {REFERENCE_NODES} x {REFERENCE_NODES} Gauss-Legendre rule, max / p99, floored "
           "at 1 % of its mean; fit: the saved fit's optimisation time",
           f"  {'fabric':18s} {'params':8s} {'old pairs/s':>12s} {'new pairs/s':>12s} {'ratio':>7s} "
           f"{'old error':>17s} {'new error':>17s} {'fit (s)':>8s}"]
    for r in result["tile_average"]:
        fit = f"{r['fit_optimisation_s']:8.1f}" if "fit_optimisation_s" in r else f"{'-':>8s}"
        out.append(f"  {r['fabric']:18s} {r['parameters']:8s} {r['old_pairs_per_second']:12,.0f} "
                   f"{r['new_pairs_per_second']:12,.0f} {r['speedup']:6.1f}x "
                   f"{_pair(r['old_error']):>17s} {_pair(r['new_error']):>17s} {fit}")
    w = result["weave_level"]
    out.append(f"  LoD prefiltered weave level (cotton-denim defaults, {w['points']} points, alpha = 1): "
               f"{w['old_us_per_point']:.2f} -> {w['new_us_per_point']:.2f} us/point ({w['speedup']:.1f}x), "
               f"max difference {100 * w['max_rel_difference']:.3f} %")
    return out
