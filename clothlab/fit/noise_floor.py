"""The measurement's own scatter, from repeated or reciprocal direction pairs (issue 28 build item 7).

Two rows of a table measure the same BRDF value when their directions coincide (a **repeat**: the same
(w_i, w_o)) or are swapped (a **reciprocal** pair: (w_i, w_o) and (w_o, w_i); Helmholtz reciprocity,
f_r(w_i, w_o) = f_r(w_o, w_i), holds for any passive reflector, cloth included - Nicodemus et al. 1977, NBS
Monograph 160, sec. 3).  Directions match when both unit vectors are within :data:`MATCH_DEG` of each other.

For a pair with values a, b the relative difference d = (a - b) / ((a + b) / 2) has, under independent
relative noise of standard deviation s on each value, standard deviation sqrt(2) s.  The scatter is estimated
robustly, s = 1.4826 median|d| / sqrt(2) (the normal-consistent median absolute deviation about 0; a few
outlying pairs - a glint caught once - do not inflate it).

A perfect model would then still show relative errors |e| with e ~ N(0, s): median 0.6745 s and 80th
percentile 1.2816 s - the **noise floor** of the error percentiles (Irawan & Marschner 2012, sec. 8 report
those two).  The model's error over the floor ("the model is N x above the noise floor") says how much of
its error is the model's.  A table with no such pairs gives no estimate, and says so.
"""

from __future__ import annotations

import math

import numpy as np

MATCH_DEG = 0.5
#: |e| quantiles of a standard normal: the median and the 80th percentile of |N(0, 1)|
ABS_NORMAL_P50 = 0.6744897501960817
ABS_NORMAL_P80 = 1.2815515655446004
MAD_NORMAL = 1.482602218505602  # 1 / Phi^-1(3/4)
RULE = ("pairs of rows with the same (repeat) or swapped (reciprocal, Helmholtz) directions within "
        f"{MATCH_DEG:g} deg; relative difference d = (a - b) / mean(a, b); per-value relative scatter "
        "s = 1.4826 median|d| / sqrt(2); noise floor of the relative-error median 0.674 s, of the 80th "
        "percentile 1.28 s (|N(0, s)|)")


def _unit(theta, phi) -> np.ndarray:
    t, p = np.radians(np.asarray(theta, dtype=np.float64)), np.radians(np.asarray(phi, dtype=np.float64))
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def direction_pairs(theta_i, phi_i, theta_o, phi_o, tol_deg: float = MATCH_DEG) -> tuple[list, list]:
    """(repeats, reciprocal): index pairs (a, b), a < b, of rows measuring the same value (module docstring);
    angles in degrees.  A row pairs with each of its matches (a triple repeat gives 3 pairs)."""
    from scipy.spatial import cKDTree

    wi, wo = _unit(theta_i, phi_i), _unit(theta_o, phi_o)
    if wi.shape[0] < 2:
        return [], []
    chord = 2.0 * math.sin(math.radians(tol_deg) / 2.0)  # the 6-d distance bound: both vectors within tol
    tree = cKDTree(np.hstack([wi, wo]))
    radius = chord * math.sqrt(2.0)

    def close(a, b, swapped):
        x, y = (wo[b], wi[b]) if swapped else (wi[b], wo[b])
        return np.linalg.norm(wi[a] - x) <= chord and np.linalg.norm(wo[a] - y) <= chord

    repeats = sorted((a, b) for a, b in tree.query_pairs(radius) if close(a, b, False))
    swapped = tree.query_ball_point(np.hstack([wo, wi]), radius)
    seen = set(repeats)
    reciprocal = []
    for a, hits in enumerate(swapped):
        for b in hits:
            if b > a and (a, b) not in seen and close(a, b, True):
                reciprocal.append((a, b))
    return repeats, sorted(reciprocal)


def noise_floor(theta_i, phi_i, theta_o, phi_o, values, tol_deg: float = MATCH_DEG) -> dict:
    """The scatter estimate (module docstring) of a table: ``values`` (N,) or (N, C), angles in degrees.

    Returns ``{"pairs", "repeats", "reciprocal", "rule"}`` and, when at least one pair has two positive values,
    ``"sigma"`` (relative, per value), ``"floor": {"p50", "p80"}`` and ``"n_differences"``; else ``"note"``."""
    y = np.asarray(values, dtype=np.float64)
    y = y[:, None] if y.ndim == 1 else y
    repeats, reciprocal = direction_pairs(theta_i, phi_i, theta_o, phi_o, tol_deg)
    pairs = repeats + reciprocal
    out = {"pairs": len(pairs), "repeats": len(repeats), "reciprocal": len(reciprocal), "rule": RULE,
           "tolerance_deg": float(tol_deg)}
    if pairs:
        a, b = y[[p[0] for p in pairs]], y[[p[1] for p in pairs]]
        ok = (a > 0) & (b > 0) & np.isfinite(a) & np.isfinite(b)
        d = ((a - b) / (0.5 * (a + b)))[ok]
    else:
        d = np.zeros(0)
    if d.size == 0:
        out["note"] = ("no repeated or reciprocal direction pairs in this table: its own noise cannot be "
                       "estimated, so the model's error cannot be compared with a noise floor")
        return out
    sigma = MAD_NORMAL * float(np.median(np.abs(d))) / math.sqrt(2.0)
    out.update(sigma=sigma, n_differences=int(d.size),
               floor={"p50": ABS_NORMAL_P50 * sigma, "p80": ABS_NORMAL_P80 * sigma})
    return out


def measurement_noise_floor(measurement, tol_deg: float = MATCH_DEG) -> dict:
    """:func:`noise_floor` of a :class:`clothlab.io.measurement.Measurement` (its angles are in degrees)."""
    m = measurement
    return noise_floor(m.theta_i, m.phi_i, m.theta_o, m.phi_o, m.values, tol_deg)


def above_floor(floor: dict, errors: dict) -> dict | None:
    """The model's error percentiles (``errors``: ``p50``, ``p80`` fractions) over the noise floor, e.g.
    ``{"p50": 3.1, "p80": 2.4}`` ("the model is 3.1 x above the noise floor" at the median); None without an
    estimate or a zero floor."""
    f = (floor or {}).get("floor")
    if not f or not errors:
        return None
    out = {}
    for key in ("p50", "p80"):
        if errors.get(key) is not None and f.get(key):
            out[key] = float(errors[key]) / float(f[key])
    return out or None


def floor_sentence(floor: dict, errors: dict, label: str) -> str:
    """One sentence for the report and the printed summary."""
    if not floor:
        return ""
    if "sigma" not in floor:
        return floor.get("note", "")
    ratio = above_floor(floor, errors) or {}
    f = floor["floor"]
    head = (f"measurement scatter {100 * floor['sigma']:.2f} % per value from {floor['n_differences']} pair "
            f"differences ({floor['repeats']} repeated, {floor['reciprocal']} reciprocal pairs): noise floor "
            f"median {100 * f['p50']:.2f} %, 80th {100 * f['p80']:.2f} %")
    if "p50" in ratio:
        head += (f"; the model ({label}) is {ratio['p50']:.1f} x above the noise floor at the median"
                 + (f", {ratio['p80']:.1f} x at the 80th percentile" if "p80" in ratio else ""))
    return head


__all__ = ["RULE", "above_floor", "direction_pairs", "floor_sentence", "measurement_noise_floor", "noise_floor"]
