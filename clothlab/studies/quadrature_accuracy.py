"""Bench section ``accuracy``: per preset and yarn type, the median / 80th-percentile relative error of each
quadrature rule of the yarn integral f_c I_j (Irawan & Marschner 2012, sec. 5, eq. 10) against
scipy.integrate.quad (:mod:`clothlab.studies.quad_reference`) on the paper's 1,575 directions (a seeded
subset of 150 in the quick run), with the time per evaluation of the full set."""

from __future__ import annotations

import time
import warnings

import numpy as np

from clothlab.errors import GeometryWarning
from clothlab.studies.data import paper_directions
from clothlab.studies.quad_reference import quad_reference
from clothlab.studies.timing import best_time

RULES = tuple((r, n) for r in ("trapezoid", "gauss") for n in (3, 5, 7, 11, 21, 41, 81)) + (
    ("support", 4), ("support", 8), ("support", 16), ("adaptive", 4))
"""The production quadrature rules and node counts of the accuracy and tradeoff studies."""


def accuracy_study(quick: bool, fabrics=None) -> list[dict]:
    """Rows per preset of ``fabrics`` (all by default) and yarn type: fabric, yarn, rule, nodes, p50, p80,
    seconds_1575, quad_seconds_1575 and quad_warnings (the directions on which quad raised an
    IntegrationWarning, counted instead of shown)."""
    from scipy.integrate import IntegrationWarning

    from clothlab.models.irawan.model import IrawanModel, Quadrature, yarn_specular
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    wi_all, wo_all = paper_directions()
    n_all = len(wi_all)
    subset = np.random.default_rng(5).choice(n_all, 150 if quick else n_all, replace=False)
    rows = []
    for name in fabrics or PRESET_NAMES:
        p = IrawanModel(get_preset(name)).default_parameters()
        for kind in ("warp", "weft"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GeometryWarning)
                t0 = time.perf_counter()
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", IntegrationWarning)
                    ref = quad_reference(wi_all[subset], wo_all[subset], p, kind)
                quad_time = (time.perf_counter() - t0) / len(subset) * n_all
                quad_warnings = sum(issubclass(c.category, IntegrationWarning) for c in caught)
                significant = ref > 1e-4 * ref.max()
                for rule, nodes in RULES:
                    q = Quadrature(rule, nodes)
                    yarn_specular(wi_all[:8], wo_all[:8], p, kind, q)  # compile / warm up
                    got = yarn_specular(wi_all[subset], wo_all[subset], p, kind, q)
                    seconds = best_time(lambda q=q, p=p, k=kind: yarn_specular(wi_all, wo_all, p, k, q), 3)
                    rel = np.abs(got - ref)[significant] / ref[significant]
                    rows.append({"fabric": name, "yarn": kind, "rule": rule, "nodes": nodes,
                                 "p50": float(np.median(rel)), "p80": float(np.percentile(rel, 80)),
                                 "seconds_1575": seconds, "quad_seconds_1575": quad_time,
                                 "quad_warnings": quad_warnings})
    return rows


def run(context) -> dict:
    return {"rows": accuracy_study(context.quick)}


def lines(result: dict) -> list[str]:
    rows = result["rows"]
    out = ["== quadrature accuracy vs scipy.integrate.quad (relative error of f_c I_j, significant values) ==",
           f"{'fabric':18s} {'yarn':5s} {'rule':10s} {'n':>3s} {'median':>10s} {'p80':>10s} {'ms/1575':>9s}"]
    for r in rows:
        out.append(f"{r['fabric']:18s} {r['yarn']:5s} {r['rule']:10s} {r['nodes']:3d} {r['p50']:10.2e} "
                   f"{r['p80']:10.2e} {1e3 * r['seconds_1575']:9.2f}")
    base = {(r["fabric"], r["yarn"]): r for r in rows if r["rule"] == "trapezoid" and r["nodes"] == 11}
    warned = {key: b["quad_warnings"] for key, b in base.items() if b["quad_warnings"]}
    if warned:
        out += ["", "  quad IntegrationWarnings (reference less certain there): " + ", ".join(
            f"{fabric} {yarn} {n}" for (fabric, yarn), n in warned.items())]
    out += ["", "  rules reaching 10x lower p80 than trapezoid-11 at no more than its run time:"]
    for key, b in base.items():
        better = [f"{r['rule']}-{r['nodes']}" for r in rows if (r["fabric"], r["yarn"]) == key
                  and r["p80"] <= 0.1 * b["p80"] and r["seconds_1575"] <= b["seconds_1575"]]
        out.append(f"  {key[0]:18s} {key[1]:5s} trapezoid-11 p80 {b['p80']:.2e}: {', '.join(better) or 'none'}")
    return out
