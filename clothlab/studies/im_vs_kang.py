"""Bench section ``models``: the IM model (Irawan & Marschner 2012) against the Kang shader on the paper's
1,575 directions, timed in the same run.

Per preset, each saved example fit (``fits/<fabric>``, ``fits/<fabric>-kang`` of the data directory) as
fitted - IM trapezoid-11, Kang's tile average with its rule (the peak rule by default) - at its fitted
parameters, beside IM support-8 and Kang's previous Gauss-Legendre rule with a fixed 8 nodes per axis at the
same parameters (previous against current in detail: bench section ``kang``); plus each fit's errors and
optimisation time.  Without saved fits (no data directory, or none under it) the models run at their default
parameters and the rows say "defaults".
"""

from __future__ import annotations

import json
import warnings

from clothlab.errors import GeometryWarning
from clothlab.studies.data import StudyData, paper_directions
from clothlab.studies.timing import best_time, clear_memo


def im_vs_kang(quick: bool, data: StudyData) -> list[dict]:
    """Rows (fabric, model, pairs_per_second, seconds_1575, parameters "fitted" / "defaults", and for a saved
    fit its name, p50, p80 and optimisation wall time)."""
    from clothlab.fit.store import load_fitted
    from clothlab.models.irawan.model import IrawanModel, Quadrature
    from clothlab.models.kang.model import KangModel
    from clothlab.report.data import optimisation_seconds
    from clothlab.weave.presets import PRESET_NAMES, get_preset

    wi, wo = paper_directions()

    def fitted(fit_name, fallback):
        fit_dir = data.fit_dir(fit_name)
        if fit_dir is not None:
            model, params, _, _ = load_fitted(fit_dir)
            return model, params, json.loads((fit_dir / "fit.json").read_text())
        return fallback, fallback.default_parameters(), None

    rows = []
    for name in PRESET_NAMES[:2] if quick else PRESET_NAMES:
        weave = get_preset(name)
        im, im_params, im_fit = fitted(name, IrawanModel(weave, Quadrature("trapezoid", 11)))
        kang, kang_params, kang_fit = fitted(f"{name}-kang", KangModel(weave))
        support = IrawanModel(weave, Quadrature("support", 8))
        legendre = KangModel(weave, tile_rule="legendre", tile_nodes=8, alternating=kang.alternating)
        # (label, model, parameters, its own fit, the fit its parameters come from)
        candidates = [(f"{im.kind} {im.quadrature.rule}-{im.quadrature.nodes}{' (fit)' if im_fit else ''}", im,
                       im_params, im_fit, im_fit),
                      (f"{support.kind} support-8", support, im_params, None, im_fit),
                      (f"{kang.kind} {kang.tile_rule}{' (fit)' if kang_fit else ''}", kang, kang_params, kang_fit,
                       kang_fit),
                      (f"{legendre.kind} legendre-8", legendre, kang_params, None, kang_fit)]
        for label, model, p, fit, source in candidates:
            p = {k: v for k, v in p.items() if k in model.params}

            def evaluate(model=model, p=p):
                clear_memo(model)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", GeometryWarning)
                    model.components(wi, wo, p, normalised=False, warn=False)

            evaluate()
            seconds = best_time(evaluate, 3 if quick else 7)
            row = {"fabric": name, "model": label, "pairs_per_second": len(wi) / seconds, "seconds_1575": seconds,
                   "parameters": "fitted" if source else "defaults"}
            if fit is not None:
                row.update({"fit": fit["name"], "p50": fit["errors"]["overall"]["p50"],
                            "p80": fit["errors"]["overall"]["p80"], "fit_wall_time_s": optimisation_seconds(fit)})
            rows.append(row)
    return rows


def run(context) -> dict:
    rows = im_vs_kang(context.quick, context.data)
    defaults = sum(r["parameters"] == "defaults" for r in rows)
    note = None if not defaults else (
        f"{defaults} of {len(rows)} rows at default parameters: no saved fit (fits/<fabric>, fits/<fabric>-kang "
        "under --data DIR)")
    return {"rows": rows, "note": note}


def lines(result: dict) -> list[str]:
    out = ["== IM vs Kang: evaluation speed on 1,575 directions (same run) and the saved example fits ==",
           f"  {'fabric':18s} {'model':26s} {'params':8s} {'pairs/s':>12s} {'median':>8s} {'80th':>8s} "
           f"{'optim. (s)':>10s}"]
    for r in result["rows"]:
        err = (f"{100 * r['p50']:7.2f}% {100 * r['p80']:7.2f}% {r['fit_wall_time_s']:10.1f}" if "p50" in r
               else f"{'-':>8s} {'-':>8s} {'-':>10s}")
        out.append(f"  {r['fabric']:18s} {r['model']:26s} {r['parameters']:8s} {r['pairs_per_second']:12,.0f} {err}")
    if result.get("note"):
        out.append(f"  note: {result['note']}")
    return out
