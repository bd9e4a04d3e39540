"""Residual diagnostics that point at physics (issue 28 build item 4; docs/select.md).

The relative residual r = (model - measured) / measured of every row is binned against the geometry a missing
term would follow:

* ``theta_i``, ``theta_o``: incident and exitant polar angle (grazing-angle Fresnel and shadowing-masking grow
  toward 90 deg);
* ``phase``: the phase angle g = angle(w_i, w_o), which is also the distance to the **retro-reflection**
  direction (w_o = w_i; a fibre sheen or retro-reflection peak sits at small g);
* ``theta_h``: polar angle of the half vector h = (w_i + w_o) / |w_i + w_o| (a microfacet lobe follows it);
* ``specular``: the angle between w_o and the mirror direction of w_i, (-x, -y, z) (a surface glint sits at 0);
* ``azimuth_h``: the azimuth of the half vector in the table's frame, 0-360 (a model unchanged by a half turn
  about the normal - every woven kind, period 180 deg, and the isotropic ones - has the same bias at phi_h and
  phi_h + 180; opposite biases there are an asymmetry it cannot have: a tilted sample plane or a nap).

Per bin: the rows, the median signed r (a bias: the model too dark < 0 or too bright > 0 there), the median |r|,
and the share of the **p80 tail** (rows whose |r| exceeds the 80th percentile of all |r|) against the share of
rows - the enrichment (> 1: the tail is concentrated there).  :func:`tail_rows` lists the worst directions.
All angles in degrees (clothlab frame, docs/design.md principle 1).

:func:`half_turn_pairs` (model-free): rows whose directions are another row's turned by a half turn about the
normal - as they are, or swapped (Helmholtz reciprocity) - have the same value under any half-turn-symmetric
model, so their measured ratio is an error such a model must make: it errs on one of the two by at least
|a - b| / (a + b) (the best common value 2ab / (a + b) errs by that on both).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

BINS = {
    "theta_i": (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0),
    "theta_o": (0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0),
    "phase": (0.0, 10.0, 20.0, 40.0, 60.0, 90.0, 180.0),
    "theta_h": (0.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0),
    "specular": (0.0, 10.0, 20.0, 40.0, 60.0, 90.0, 180.0),
    "azimuth_h": (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 360.0),
}
LABELS = {"theta_i": "incident polar angle", "theta_o": "exitant polar angle",
          "phase": "phase angle = distance to retro-reflection", "theta_h": "half-vector polar angle",
          "specular": "distance to the mirror direction", "azimuth_h": "half-vector azimuth (table frame)"}
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
            "specular": _angle(wo, mirror), "azimuth_h": np.mod(np.degrees(np.arctan2(h[:, 1], h[:, 0])), 360.0)}


def relative_residuals(measured, model) -> np.ndarray:
    """(model - measured) / measured per value, NaN where measured <= 0 or not finite."""
    y, m = np.asarray(measured, dtype=np.float64), np.asarray(model, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((y > 0) & np.isfinite(y) & np.isfinite(m), (m - y) / y, np.nan)


def diagnostics(theta_i, phi_i, theta_o, phi_o, measured, model) -> dict:
    """The binned residual table (module docstring) of rows with (N,) or (N, C) ``measured`` / ``model``
    (channels pooled: each row's mean |r| over its channels decides the tail, each value counts in the bias).

    Returns ``{"features": {name: {"label", "bins": [{"lo", "hi", "n", "median_r", "median_abs_r",
    "tail_share", "row_share", "enrichment"}]}}, "tail_threshold", "tail_rows", "enriched", "rule", "half_turn",
    "worst"}`` (``half_turn``: :func:`half_turn_pairs` of the measured values)."""
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
    out["half_turn"] = half_turn_pairs(theta_i, phi_i, theta_o, phi_o, y)
    out["worst"] = tail_rows(theta_i, phi_i, theta_o, phi_o, row_abs, np.nanmean(r, axis=1) if r.size else r)
    return out


def tail_rows(theta_i, phi_i, theta_o, phi_o, row_abs, row_r, count: int = 10) -> list[dict]:
    """The ``count`` rows with the largest mean |r|: their directions and signed r."""
    order = [i for i in np.argsort(-np.nan_to_num(row_abs, nan=-1.0)) if np.isfinite(row_abs[i])][:count]
    return [{"row": int(i), "theta_i": float(theta_i[i]), "phi_i": float(phi_i[i]), "theta_o": float(theta_o[i]),
             "phi_o": float(phi_o[i]), "r": float(row_r[i])} for i in order]


def half_turn_pairs(theta_i, phi_i, theta_o, phi_o, measured, tolerance: float = 1.0) -> dict:
    """The pairs of rows related by a half turn about the normal, as they are or swapped (module docstring):
    (N,) or (N, C) ``measured`` (channels averaged), ``tolerance`` (deg) on the distance of the direction pairs
    (the chord distance of the 6-vectors (wi, wo), ~ sqrt(d_i^2 + d_o^2) for small angles).  Returns
    ``{"pairs", "median_abs_log_ratio", "floor_median", "floor_p80", "darker_azimuth", "sentence", "list"}``:
    the floor = |a - b| / (a + b) per pair (the least error a half-turn-symmetric model makes on one of its
    rows); ``darker_azimuth`` (deg in (-180, 180], table frame): the mean half-vector azimuth of the darker rows
    weighted by |ln(a / b)|, None without pairs."""
    y = np.asarray(measured, dtype=np.float64)
    y = y.mean(axis=1) if y.ndim == 2 else y
    wi, wo = _unit(theta_i, phi_i), _unit(theta_o, phi_o)
    turn = np.array([-1.0, -1.0, 1.0])
    azimuth = features(theta_i, phi_i, theta_o, phi_o)["azimuth_h"]
    tree = cKDTree(np.hstack([wi, wo]))
    found = {}
    for a, b in ((wi * turn, wo * turn), (wo * turn, wi * turn)):
        distance, nearest = tree.query(np.hstack([a, b]), distance_upper_bound=np.radians(tolerance))
        for k, (d, j) in enumerate(zip(distance, nearest, strict=True)):
            if np.isfinite(d) and j != k:
                found.setdefault((min(j, k), max(j, k)), float(d))
    pairs = [(k, j) for k, j in found if y[k] > 0 and y[j] > 0 and np.isfinite(y[k]) and np.isfinite(y[j])]
    if not pairs:
        return {"pairs": 0, "median_abs_log_ratio": None, "floor_median": None, "floor_p80": None,
                "darker_azimuth": None, "list": [], "sentence": "no rows related by a half turn about the normal"}
    log_ratio = np.array([np.log(y[k] / y[j]) for k, j in pairs])
    floor = np.array([abs(y[k] - y[j]) / (y[k] + y[j]) for k, j in pairs])
    darker = np.array([k if y[k] < y[j] else j for k, j in pairs])
    weight = np.abs(log_ratio)
    vector = np.sum(weight[:, None] * _unit(np.full(len(pairs), 90.0), azimuth[darker])[:, :2], axis=0)
    direction = float(np.degrees(np.arctan2(vector[1], vector[0]))) if weight.sum() > 0 else None
    out = {"pairs": len(pairs), "median_abs_log_ratio": float(np.median(weight)),
           "floor_median": float(np.median(floor)), "floor_p80": float(np.percentile(floor, 80)),
           "darker_azimuth": direction,
           "list": [{"rows": [int(k), int(j)], "values": [float(y[k]), float(y[j])]} for k, j in pairs]}
    out["sentence"] = (f"{len(pairs)} pairs of rows related by a half turn about the normal differ by a median "
                       f"{100 * np.median(floor):.1f} % (80th percentile {100 * out['floor_p80']:.1f} %) from their "
                       "common best value: a half-turn-symmetric model errs by at least that on one row of each pair"
                       + (f"; the darker rows' half vectors lean toward azimuth {direction:.0f} deg"
                          if direction is not None else ""))
    return out


def summary_sentence(diag: dict) -> str:
    """Where the p80 tail concentrates, in one sentence."""
    if not diag or not diag.get("rows"):
        return "no residuals"
    half = diag.get("half_turn") or {}
    pairs = (f" ({half['pairs']} pairs of rows related by a half turn about the normal differ by a median "
             f"{100 * half['floor_median']:.1f} % from their common value: a floor for half-turn-symmetric models)"
             if half.get("pairs") else "")
    if not diag["enriched"]:
        return (f"the p80 tail (mean |r| > {100 * diag['tail_threshold']:.1f} %, {diag['tail_rows']} rows) is spread "
                "over the geometry: no bin holds more than 1.5 x its share" + pairs)
    return (f"the p80 tail (mean |r| > {100 * diag['tail_threshold']:.1f} %, {diag['tail_rows']} rows) is "
            "concentrated at: " + "; ".join(diag["enriched"]) + pairs)


__all__ = ["BINS", "diagnostics", "features", "half_turn_pairs", "relative_residuals", "summary_sentence",
           "tail_rows"]
