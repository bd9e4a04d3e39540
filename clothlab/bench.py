"""``clothlab bench``: speed and accuracy figures, measured side by side in one run (never timed tests).

Sections (each prints a table; ``--json`` writes all figures with the machine description):

1. ``accuracy``  - per preset and yarn type, median / 80th-percentile relative error of each quadrature rule
   against scipy.integrate.quad (breakpoints at the closed-form support ends, epsrel 1e-10) on the paper's
   1,575 directions (a seeded subset in ``--quick``), with the time per evaluation of the full set.
2. ``speed``     - direction pairs per second of the two-yarn model, RGB, trapezoid 11, on the 1,575-direction
   set (best of repeats), next to a per-direction scipy.integrate.quad loop (ratio).
3. ``fit``       - wall time of one full fit (global GN_CRS2_LM + local LN_BOBYQA, six free parameters,
   1,575 x 3 values, 4,000 evaluations, one start) of the noisy polyester-lining example.
4. ``cli``       - ``clothlab --help`` time and the heavy modules ``import clothlab`` pulls in.
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from clothlab.errors import GeometryWarning

RULES = (("trapezoid", 3), ("trapezoid", 5), ("trapezoid", 7), ("trapezoid", 11), ("trapezoid", 21),
         ("trapezoid", 41), ("trapezoid", 81), ("gauss", 3), ("gauss", 5), ("gauss", 7), ("gauss", 11),
         ("gauss", 21), ("gauss", 41), ("gauss", 81), ("support", 4), ("support", 8), ("support", 16),
         ("adaptive", 4))


def machine() -> dict:
    from clothlab.fit.runner import package_versions

    return {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": platform.processor(),
            "versions": package_versions()}


def _best_time(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def quad_reference(wi, wo, params, kind):
    """f_c I_j by scipy.integrate.quad per direction pair, integrating the compiled integrand node by node."""
    from scipy.integrate import quad

    from clothlab.frames import to_yarn_frame
    from clothlab.models.irawan import kernels
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD
    from clothlab.models.irawan.phase import phase_function
    from clothlab.models.irawan.yarn import _filament_breaks, _staple_breaks, half_vectors

    psi = math.radians(params[f"{kind}.psi"])
    umax = math.radians(params[f"{kind}.umax"])
    kappa, w, l, delta = params[f"{kind}.kappa"], params[f"{kind}.w"], params[f"{kind}.l"], params["delta"]
    lw, lo = to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)
    staple = abs(psi) >= PSI_FILAMENT_THRESHOLD
    h, _ = half_vectors(lw, lo)
    breaks = _staple_breaks(h, psi, umax) if staple else _filament_breaks(lw, lo, h)
    one = np.ones((1, 1))
    out = np.zeros(len(wi))
    for n in range(len(wi)):
        a, b = lw[n:n + 1], lo[n:n + 1]
        if staple:
            def f(u, a=a, b=b):
                return kernels.staple_quadrature(a, b, np.array([[u]]), one, psi, umax, kappa, w, l)[0]
        else:
            def f(v, a=a, b=b):
                return kernels.filament_quadrature(a, b, np.array([[v]]), one, umax, kappa, w, l, delta)[0]
        edges = np.unique(breaks[n])
        total = 0.0
        for lo_, hi_ in zip(edges[:-1], edges[1:], strict=True):
            total += quad(f, lo_, hi_, epsabs=0.0, epsrel=1e-10, limit=200)[0]
        out[n] = total
    return out * phase_function(wi, wo, params["alpha"], params["beta"])


def accuracy_section(quick: bool) -> list[dict]:
    from clothlab.models.irawan.model import IrawanModel, Quadrature, yarn_specular
    from clothlab.presets import PRESET_NAMES, get_preset
    from clothlab.simulate import paper_sampling

    ti, pi_, to, po = paper_sampling()
    from clothlab.frames import spherical_to_vector

    wi_all, wo_all = spherical_to_vector(ti, pi_), spherical_to_vector(to, po)
    subset = np.random.default_rng(5).choice(len(ti), 150 if quick else len(ti), replace=False)
    rows = []
    for name in PRESET_NAMES:
        p = IrawanModel(get_preset(name)).default_parameters()
        for kind in ("warp", "weft"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", GeometryWarning)
                t0 = time.perf_counter()
                ref = quad_reference(wi_all[subset], wo_all[subset], p, kind)
                quad_time = (time.perf_counter() - t0) / len(subset) * len(ti)
                significant = ref > 1e-4 * ref.max()
                for rule, nodes in RULES:
                    q = Quadrature(rule, nodes)
                    yarn_specular(wi_all[:8], wo_all[:8], p, kind, q)  # compile / warm up
                    got = yarn_specular(wi_all[subset], wo_all[subset], p, kind, q)
                    seconds = _best_time(lambda q=q, p=p, k=kind: yarn_specular(wi_all, wo_all, p, k, q), 3)
                    rel = np.abs(got - ref)[significant] / ref[significant]
                    rows.append({"fabric": name, "yarn": kind, "rule": rule, "nodes": nodes,
                                 "p50": float(np.median(rel)), "p80": float(np.percentile(rel, 80)),
                                 "seconds_1575": seconds, "quad_seconds_1575": quad_time})
    return rows


def speed_section(quick: bool) -> dict:
    from clothlab.frames import spherical_to_vector
    from clothlab.models.components import combine
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.presets import get_preset
    from clothlab.simulate import paper_sampling

    ti, pi_, to, po = paper_sampling()
    wi, wo = spherical_to_vector(ti, pi_), spherical_to_vector(to, po)
    out = {}
    for name in ("polyester-lining", "cotton-denim"):
        model = IrawanModel(get_preset(name))
        p = model.default_parameters()
        coef = {"kd": np.array([0.2, 0.1, 0.1]), "ks_warp": np.array([0.1, 0.1, 0.1]),
                "ks_weft": np.array([0.1, 0.1, 0.1])}

        def evaluate(model=model, p=p, coef=coef):
            model._memo.clear()  # time the full evaluation, not the memo
            return combine(model.components(wi, wo, p, normalised=False, warn=False), coef)

        evaluate()
        seconds = _best_time(evaluate, 5 if quick else 20)
        n_quad = 20 if quick else 60
        t0 = time.perf_counter()
        for kind in ("warp", "weft"):
            quad_reference(wi[:n_quad], wo[:n_quad], p, kind)
        quad_rate = n_quad / (time.perf_counter() - t0)
        out[name] = {"pairs_per_second": len(wi) / seconds, "seconds_1575": seconds,
                     "quad_pairs_per_second": quad_rate, "speedup_vs_quad": len(wi) / seconds / quad_rate}
    return out


def fit_section(quick: bool) -> dict:
    from dataclasses import replace

    from clothlab.config import load_config
    from clothlab.fit.runner import run_fit

    root = Path(__file__).resolve().parents[1] / "measurements" / "polyester-lining" / "fabric.yaml"
    if not root.is_file():
        return {"skipped": f"{root} not found (bench runs from a source checkout)"}
    cfg = load_config(root)
    evals = 1000 if quick else 4000
    cfg = replace(cfg, fit=replace(cfg.fit, optimizer=replace(cfg.fit.optimizer, max_evals=evals, starts=1)))
    result = run_fit(cfg)
    return {"fabric": "polyester-lining (noisy)", "free": list(result.problem.free), "evaluations":
            int(result.optimum.nevals), "wall_time_s": result.wall_time,
            "seconds_per_evaluation": result.wall_time / result.optimum.nevals,
            "p50": result.errors["overall"]["p50"], "p80": result.errors["overall"]["p80"]}


def cli_section() -> dict:
    times = []
    for _ in range(5):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "clothlab.cli", "--help"], capture_output=True, check=True)
        times.append(time.perf_counter() - t)
    code = ("import sys, clothlab; print(','.join(m for m in ('matplotlib', 'colour', 'OpenImageIO', 'emcee', "
            "'nlopt', 'numba', 'scipy') if m in sys.modules))")
    heavy = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    return {"help_seconds_best": min(times), "help_seconds_median": float(np.median(times)),
            "import_pulls": heavy.split(",") if heavy else []}


def _print_accuracy(rows):
    print("\n== quadrature accuracy vs scipy.integrate.quad (relative error of f_c I_j, significant values) ==")
    print(f"{'fabric':18s} {'yarn':5s} {'rule':10s} {'n':>3s} {'median':>10s} {'p80':>10s} {'ms/1575':>9s}")
    for r in rows:
        print(f"{r['fabric']:18s} {r['yarn']:5s} {r['rule']:10s} {r['nodes']:3d} {r['p50']:10.2e} {r['p80']:10.2e} "
              f"{1e3 * r['seconds_1575']:9.2f}")
    base = {(r["fabric"], r["yarn"]): r for r in rows if r["rule"] == "trapezoid" and r["nodes"] == 11}
    print("\n  rules reaching 10x lower p80 than trapezoid-11 at no more than its run time:")
    for key, b in base.items():
        better = [f"{r['rule']}-{r['nodes']}" for r in rows if (r["fabric"], r["yarn"]) == key
                  and r["p80"] <= 0.1 * b["p80"] and r["seconds_1575"] <= b["seconds_1575"]]
        print(f"  {key[0]:18s} {key[1]:5s} trapezoid-11 p80 {b['p80']:.2e}: {', '.join(better) or 'none'}")


def run_benchmarks(*, quick: bool = False, json_path=None) -> int:
    figures = {"machine": machine(), "quick": quick}
    print(f"clothlab bench ({'quick' if quick else 'full'}) on {figures['machine']['cpus']} CPUs")
    figures["cli"] = cli_section()
    print(f"\n== cli ==\n  clothlab --help: best {figures['cli']['help_seconds_best']:.3f} s; "
          f"import clothlab pulls in: {figures['cli']['import_pulls'] or 'none of the heavy modules'}")
    figures["speed"] = speed_section(quick)
    print("\n== evaluation speed: two-yarn IM model, RGB, trapezoid 11, 1,575 directions ==")
    for name, s in figures["speed"].items():
        print(f"  {name:18s} {s['pairs_per_second']:12,.0f} pairs/s ({1e3 * s['seconds_1575']:.2f} ms per set); "
              f"quad loop {s['quad_pairs_per_second']:8,.1f} pairs/s; ratio {s['speedup_vs_quad']:,.0f}x")
    figures["accuracy"] = accuracy_section(quick)
    _print_accuracy(figures["accuracy"])
    figures["fit"] = fit_section(quick)
    f = figures["fit"]
    if "skipped" not in f:
        print(f"\n== one full fit ({f['fabric']}, {len(f['free'])} free, {f['evaluations']} evaluations) ==\n"
              f"  wall time {f['wall_time_s']:.1f} s ({1e3 * f['seconds_per_evaluation']:.2f} ms/evaluation); "
              f"median {100 * f['p50']:.2f} %, 80th {100 * f['p80']:.2f} %")
    if json_path:
        from clothlab.atomic import atomic_write_text

        atomic_write_text(json_path, json.dumps(figures, indent=1, default=float) + "\n")
        print(f"\nfigures written to {json_path}")
    return 0
