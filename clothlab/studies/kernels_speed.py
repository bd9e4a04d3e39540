"""Speed of the IM yarn integrals before and after the equation-by-equation rewrite, in one run.

:func:`compare_kernels` evaluates the warp and weft yarn integrals (eq. 10 of Irawan & Marschner 2012
without f_c) of each of the six presets at the paper's 225 x 7 measurement directions, once with the
current kernels (:mod:`clothlab.models.irawan.yarn`) and once with the frozen previous ones
(:mod:`clothlab.studies.kernels_baseline`), alternating the two so that machine load hits both alike,
and keeps the best of several repeats.  Remove with the baseline once the ratio has been reported.
"""

from __future__ import annotations

import math
import time

import numpy as np

QUICK_REPEATS = 11
FULL_REPEATS = 31
MIN_SAMPLE_S = 0.005  # each timed sample repeats the evaluation until it lasts at least this long


def _yarn_arguments(params: dict, kind: str, rule: str, nodes: int) -> dict:
    """Keyword arguments of ``yarn_integral`` for segment type ``kind`` (angles converted to radians)."""
    from clothlab.models.irawan.model import PSI_FILAMENT_THRESHOLD

    return {"psi": math.radians(params[f"{kind}.psi"]), "umax": math.radians(params[f"{kind}.umax"]),
            "kappa": params[f"{kind}.kappa"], "w": params[f"{kind}.w"], "l": params[f"{kind}.l"],
            "delta": params["delta"], "rule": rule, "n": int(nodes), "psi_threshold": PSI_FILAMENT_THRESHOLD}


def _best_pair(old, new, repeats: int) -> tuple[float, float]:
    """Best seconds per call of ``old`` and ``new``, timed alternately (old, new, old, new, ...)."""
    old()
    new()  # warm-up (compilation, caches)
    start = time.perf_counter()
    old()
    new()
    inner = max(1, math.ceil(2.0 * MIN_SAMPLE_S / max(time.perf_counter() - start, 1e-9)))
    best = [math.inf, math.inf]
    for _ in range(repeats):
        for i, fn in enumerate((old, new)):
            start = time.perf_counter()
            for _ in range(inner):
                fn()
            best[i] = min(best[i], (time.perf_counter() - start) / inner)
    return best[0], best[1]


def compare_kernels(quick: bool, rule: str = "trapezoid", nodes: int = 11) -> dict:
    """Pairs per second of the previous and the current yarn integrals, and their ratio (new / old).

    Same directions (the paper's 1,575 measurement pairs), parameters (each preset's Table I values) and
    quadrature (``rule``, ``nodes``; the model's default trapezoid-11) for both.  A pair is one direction
    pair with both segment types evaluated.  Returns ``{"rule", "pairs", "repeats", "presets": [{"preset",
    "old_pairs_per_s", "new_pairs_per_s", "ratio", "max_rel_diff"}, ...], "old_pairs_per_s",
    "new_pairs_per_s", "ratio"}``: the totals over all presets, ``ratio`` > 1 when the rewrite is faster;
    ``max_rel_diff`` is the largest |new - old| relative to the preset's largest value (round-off expected).
    """
    from clothlab.frames import spherical_to_vector, to_yarn_frame
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.models.irawan.yarn import yarn_integral
    from clothlab.simulate.gonio import paper_sampling
    from clothlab.studies.kernels_baseline import yarn_integral as baseline_yarn_integral
    from clothlab.weave.model import YARN_KINDS
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    theta_i, phi_i, theta_o, phi_o = paper_sampling()
    wi, wo = spherical_to_vector(theta_i, phi_i), spherical_to_vector(theta_o, phi_o)
    frames = {kind: (to_yarn_frame(wi, kind), to_yarn_frame(wo, kind)) for kind in YARN_KINDS}
    repeats = QUICK_REPEATS if quick else FULL_REPEATS
    rows = []
    for name in PRESET_NAMES:
        params = IrawanModel(get_preset(name)).default_parameters()
        calls = [(frames[kind], _yarn_arguments(params, kind, rule, nodes)) for kind in YARN_KINDS]

        def run(integral, calls=calls):
            return [integral(a, b, **kw) for (a, b), kw in calls]

        old_values, new_values = run(baseline_yarn_integral), run(yarn_integral)
        scale = max(max(float(np.max(np.abs(v))) for v in old_values), 1e-300)
        diff = max(float(np.max(np.abs(n - o))) for n, o in zip(new_values, old_values, strict=True)) / scale
        old_s, new_s = _best_pair(lambda run=run: run(baseline_yarn_integral), lambda run=run: run(yarn_integral),
                                  repeats)
        rows.append({"preset": name, "old_pairs_per_s": len(wi) / old_s, "new_pairs_per_s": len(wi) / new_s,
                     "ratio": old_s / new_s, "max_rel_diff": diff, "old_s": old_s, "new_s": new_s})
    old_total = sum(r.pop("old_s") for r in rows)
    new_total = sum(r.pop("new_s") for r in rows)
    n_pairs = len(wi) * len(rows)
    return {"rule": f"{rule}-{nodes}", "pairs": len(wi), "repeats": repeats, "presets": rows,
            "old_pairs_per_s": n_pairs / old_total, "new_pairs_per_s": n_pairs / new_total,
            "ratio": old_total / new_total}


def comparison_lines(result: dict) -> list[str]:
    """Text lines of a :func:`compare_kernels` result, for the benchmark report (one line per preset)."""
    lines = [f"IM yarn integrals ({result['rule']}, {result['pairs']} pairs x warp + weft, best of "
             f"{result['repeats']}, alternated): previous {result['old_pairs_per_s']:,.0f} pairs/s, current "
             f"{result['new_pairs_per_s']:,.0f} pairs/s, speed ratio current / previous {result['ratio']:.3f}"]
    for row in result["presets"]:
        lines.append(f"  {row['preset']:<18} {row['old_pairs_per_s']:>12,.0f} -> {row['new_pairs_per_s']:>12,.0f} "
                     f"pairs/s  ratio {row['ratio']:.3f}  max |difference| {row['max_rel_diff']:.1e} (relative)")
    return lines
