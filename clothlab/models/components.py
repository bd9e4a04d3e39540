"""Combining model components with their linear coefficients.

A model returns named components (N,), e.g. ``diffuse``, ``specular_warp``, ``specular_weft``; the fabric's
value in channel c is  sum_k coef_k[c] * component_k.  Each component has a coefficient name (kd, ks_warp,
...) under which fits store and reports show it.
"""

from __future__ import annotations

import numpy as np

COEFFICIENT_OF = {
    "diffuse": "kd",
    "diffuse_warp": "kd_warp",
    "diffuse_weft": "kd_weft",
    "specular_warp": "ks_warp",
    "specular_weft": "ks_weft",
}


def coefficient_name(component: str) -> str:
    """The coefficient name of a component (its own name if it has no conventional one)."""
    return COEFFICIENT_OF.get(component, component)


def combine(components: dict, coefficients: dict) -> np.ndarray:
    """(N, C) = sum_k coefficients[coef_name(k)] (C,) * components[k] (N,); a missing coefficient is 0."""
    total = None
    for name, comp in components.items():
        coef = coefficients.get(coefficient_name(name), coefficients.get(name))
        if coef is None:
            continue
        term = np.asarray(comp)[:, None] * np.atleast_1d(np.asarray(coef, dtype=np.float64))[None, :]
        total = term if total is None else total + term
    if total is None:
        raise ValueError(f"no coefficient among {sorted(coefficients)} matches a component of {sorted(components)}")
    return total


def per_yarn_coefficients(coefficients: dict) -> dict:
    """An Irawan-Marschner coefficient set (kd, ks_warp, ks_weft; Irawan & Marschner 2012, sec. 8: one diffuse
    colour for the fabric) for a model with a diffuse colour per yarn type: kd_warp = kd_weft = kd, the specular
    coefficients kept; a missing coefficient is 0 (its component is then not computed)."""
    kd = coefficients.get("kd", 0.0)
    return {"kd_warp": kd, "kd_weft": kd, "ks_warp": coefficients.get("ks_warp", 0.0),
            "ks_weft": coefficients.get("ks_weft", 0.0)}
