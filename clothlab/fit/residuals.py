"""Residual diagnostics that point at physics (issue 28 build item 4; docs/select.md).

The relative residual r = (model - measured) / measured of every row is binned against the geometry a missing
term would follow:

* ``theta_i``, ``theta_o``: incident and exitant polar angle (grazing-angle Fresnel and shadowing-masking grow
  toward 90 deg);
* ``phase``: the phase angle g = angle(w_i, w_o), which is also the distance to the **retro-reflection**
  direction (w_o = w_i; a fibre sheen or retro-reflection peak sits at small g);
* ``theta_h``: polar angle of the half vector h = (w_i + w_o) / |w_i + w_o| (a microfacet lobe follows it);
* ``specular``: the angle between w_o and the mirror direction of w_i, (-x, -y, z) (a surface glint sits at 0).

Per bin: the rows, the median signed r (a bias: the model too dark < 0 or too bright > 0 there), the median |r|,
and the share of the **p80 tail** (rows whose |r| exceeds the 80th percentile of all |r|) against the share of
rows - the enrichment (> 1: the tail is concentrated there).  :func:`tail_rows` lists the worst directions.
All angles in degrees (clothlab frame, docs/design.md principle 1).
"""

from __future__ import annotations

import numpy as np

BINS = {
    "theta_i": (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0),
    "theta_o": (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0),
    "phase": (0.0, 10.0, 20.0, 40.0, 60.0, 90.0, 180.0),
    "theta_h": (0.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0),
    "specular": (0.0, 10.0, 20.0, 40.0, 60.0, 90.0, 180.0),
}
LABELS = {"theta_i": "incident polar angle", "theta_o": "exitant polar angle",
          "phase": "phase angle = distance to retro-reflection", "theta_h": "half-vector polar angle",
          "specular": "distance to the mirror direction"}
TAIL = 80.0
ENRICHED = 1.5


def _unit(theta, phi):
    t, p = np.radians(np.asarray(theta, dtype=np.float64)), np.radians(np.asarray(phi, dtype=np.float64))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def features(theta_i, phi_i, theta_o, phi_o) -> dict:
    """{feature: (N,) degrees} of :data:`BINS` (module docstring)."""
    wi, wo = _unit(theta_i, phi_i), _unit(theta_o, phi_o)
    h = wi + wo
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    h = np.where(norm > 0, h / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    return {"theta_i": np.asarray(theta_i, dtype=np.float64), "theta_o": np.asarray(theta_o, dtype=np.float64),
            "phase": _angle(wi, wo), "theta_h": np.degrees(np.arccos(np.clip(h[:, 2], -1.0, 1.0))),
            "specular": _angle(wo, mirror)}


def relative_residuals(measured, model) -> np.ndarray:
    """(model - measured) / measured per value, NaN where measured <= 0 or not finite."""
    y, m = np.asarray(measured, dtype=np.float64), np.asarray(model, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((y > 0) & np.isfinite(y) & np.isfinite(m), (m - y) / y, np.nan)


def diagnostics(theta_i, phi_i, theta_o, phi_o, measured, model) -> dict:
    """The binned residual table (module docstring) of rows with (N,) or (N, C) ``measured`` / ``model``
    (channels pooled: each row's mean |r| over its channels decides the tail, each value counts in the bias).

    Returns ``{"features": {name: {"label", "bins": [{"lo", "hi", "n", "median_r", "median_abs_r",
    "tail_share", "row_share", "enrichment"}]}}, "tail_threshold", "tail_rows", "enriched", "rule"}``."""
    y = np.asarray(measured, dtype=np.float64)
    y = y[:, None] if y.ndim == 1 else y
    m = np.asarray(model, dtype=np.float64).reshape(y.shape)
    r = relative_residuals(y, m)
    row_abs = np.nanmean(np.abs(r), axis=1) if r.size else np.zeros(0)
    ok = np.isfinite(row_abs)
    threshold = float(np.percentile(row_abs[ok], TAIL)) if ok.any() else float("nan")
    tail = ok & (row_abs > threshold)
    feats = features(theta_i, phi_i, theta_o, phi_o)
    out = {"features": {}, "tail_threshold": threshold, "tail_rows": int(tail.sum()), "rows": int(ok.sum()),
           "rule": (f"r = (model - measured) / measured; the tail: rows whose mean |r| exceeds its {TAIL:g}th "
                    f"percentile; enrichment = the bin's share of the tail / its share of the rows (> {ENRICHED:g}: "
                    "the tail is concentrated there)")}
    enriched = []
    for name, edges in BINS.items():
        x = feats[name]
        bins = []
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            inside = ok & (x >= lo) & ((x < hi) if hi < edges[-1] else (x <= hi))
            n = int(inside.sum())
            values = r[inside].ravel()
            values = values[np.isfinite(values)]
            row_share = n / max(int(ok.sum()), 1)
            tail_share = int((tail & inside).sum()) / max(int(tail.sum()), 1)
            entry = {"lo": lo, "hi": hi, "n": n,
                     "median_r": float(np.median(values)) if values.size else None,
                     "median_abs_r": float(np.median(np.abs(values))) if values.size else None,
                     "row_share": row_share, "tail_share": tail_share,
                     "enrichment": tail_share / row_share if row_share > 0 else None}
            bins.append(entry)
            if n >= 5 and entry["enrichment"] is not None and entry["enrichment"] > ENRICHED:
                enriched.append(f"{LABELS[name]} {lo:g}-{hi:g} deg ({entry['enrichment']:.1f} x, median r "
                                f"{100 * entry['median_r']:+.1f} %)")
        out["features"][name] = {"label": LABELS[name], "bins": bins}
    out["enriched"] = enriched
    out["worst"] = tail_rows(theta_i, phi_i, theta_o, phi_o, row_abs, np.nanmean(r, axis=1) if r.size else r)
    return out


def tail_rows(theta_i, phi_i, theta_o, phi_o, row_abs, row_r, count: int = 10) -> list[dict]:
    """The ``count`` rows with the largest mean |r|: their directions and signed r."""
    order = [i for i in np.argsort(-np.nan_to_num(row_abs, nan=-1.0)) if np.isfinite(row_abs[i])][:count]
    return [{"row": int(i), "theta_i": float(theta_i[i]), "phi_i": float(phi_i[i]), "theta_o": float(theta_o[i]),
             "phi_o": float(phi_o[i]), "r": float(row_r[i])} for i in order]


def summary_sentence(diag: dict) -> str:
    """Where the p80 tail concentrates, in one sentence."""
    if not diag or not diag.get("rows"):
        return "no residuals"
    if not diag["enriched"]:
        return (f"the p80 tail (mean |r| > {100 * diag['tail_threshold']:.1f} %, {diag['tail_rows']} rows) is spread "
                "over the geometry: no bin holds more than 1.5 x its share")
    return (f"the p80 tail (mean |r| > {100 * diag['tail_threshold']:.1f} %, {diag['tail_rows']} rows) is "
            "concentrated at: " + "; ".join(diag["enriched"]))


__all__ = ["BINS", "diagnostics", "features", "relative_residuals", "summary_sentence", "tail_rows"]
