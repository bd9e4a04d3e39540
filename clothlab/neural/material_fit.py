"""Fast approximate material fit through a multi-material surrogate (Chen, Wang & Wang 2024, sec. 4.2: the
encoder maps the material to the latent z that the decoder reads).

The material vector m (:func:`clothlab.neural.encodings.material_vector`: normalised parameters, then the
pattern descriptor) is the encoder's input.  With encoder and decoder weights fixed, the free parameters'
entries of m (each in [0, 1] between its fit bounds, log-mapped where declared) are fitted to measured
values y (N,) at direction pairs (wi, wo) and one footprint size (the far view by default):

    min over m_free, c >= 0 of  sum_n (sum_k c_k f_k(m; wi_n, wo_n) - y_n)^2

c (the linear coefficients kd, ks_j; eqs. 7-8 of the paper, clothlab's components design) by NNLS at every
step; m_free by Adam on the gradient with c held at its NNLS optimum (at the optimum of the inner problem its
derivative in c vanishes, so this is the gradient of the profile objective), back-propagated through
decoder and encoder by the network's own backward pass (:meth:`SurrogateNetwork.backward`).  Several starts
(a grid over [0, 1]) guard against local minima; the best is returned.  Only meaningful for a network
trained over a range of the free parameters (``clothlab train-surrogate --vary``); a per-fabric network has
seen one material and its encoder does not constrain them.  Refine with the exact model by a fit of that
kind started at the result (docs/neural.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from clothlab.neural.losses import decode_outputs


@dataclass
class MaterialFit:
    """``params``: the fitted free parameters (declared units); ``unit``: their m entries; ``coefficients``
    (C,) by component; ``rms``: root-mean-square residual; ``steps``: Adam steps over all starts."""

    params: dict
    unit: dict
    coefficients: dict
    rms: float
    steps: int


def _design(surrogate, m: np.ndarray, spatial, angular, train: bool) -> tuple[np.ndarray, np.ndarray]:
    """Components (N, C) at material vector m, and the network outputs they were decoded from."""
    net = surrogate.network
    index = np.zeros(spatial.shape[0], dtype=np.int64)
    out = net.forward(m[None].astype(net.dtype), index, spatial, angular, train=train).astype(np.float64)
    return decode_outputs(out, surrogate._specular, surrogate.k), out


def fit_material(surrogate, wi, wo, values, base_vector: np.ndarray, free_index: dict, *, size: float = 4.5,
                 steps: int = 150, lr: float = 0.05, starts: int = 3) -> MaterialFit:
    """Fit the entries ``free_index`` ({name: position in m}) of ``base_vector`` (the encoder input of the
    start material) to ``values`` (N,) at fabric-frame directions (N, 3); ``size``: footprint (tiles) of the
    queries, centre (0.5, 0.5).  ``starts`` per free parameter: a grid of starting values in (0, 1)."""
    wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
    y = np.asarray(values, dtype=np.float64).reshape(-1)
    n = y.size
    spatial, angular = surrogate.features(np.full((n, 2), 0.5), np.full(n, size), wi, wo)
    names = list(free_index)
    pos = np.array([free_index[k] for k in names], dtype=np.int64)
    specular = surrogate._specular
    grid = (np.arange(starts) + 0.5) / starts
    best, total = None, 0
    for start in itertools.product(grid, repeat=len(names)):
        x = np.array(start, dtype=np.float64)
        m1, m2 = np.zeros_like(x), np.zeros_like(x)
        for t in range(1, steps + 1):
            m = np.array(base_vector, dtype=np.float64)
            m[pos] = x
            comps, out = _design(surrogate, m, spatial, angular, train=True)
            c, _ = nnls(comps, y)
            r = comps @ c - y
            d_comp = 2.0 * r[:, None] * c[None, :] / n
            d_out = np.where(specular, d_comp * np.exp(out) / surrogate.k * (out > 0.0), d_comp)
            g = surrogate.network.backward(d_out.astype(surrogate.network.dtype))[0, pos].astype(np.float64)
            m1 = 0.9 * m1 + 0.1 * g  # Adam (bias-corrected), projected onto [0, 1]
            m2 = 0.999 * m2 + 0.001 * g * g
            x = np.clip(x - lr * (m1 / (1 - 0.9 ** t)) / (np.sqrt(m2 / (1 - 0.999 ** t)) + 1e-12), 0.0, 1.0)
        total += steps
        m = np.array(base_vector, dtype=np.float64)
        m[pos] = x
        comps, _ = _design(surrogate, m, spatial, angular, train=False)
        c, res = nnls(comps, y)
        if best is None or res < best[0]:
            best = (res, x.copy(), c)
    res, x, c = best
    return MaterialFit(params={}, unit=dict(zip(names, x.tolist(), strict=True)),
                       coefficients=dict(zip(surrogate.component_names, c.tolist(), strict=True)),
                       rms=float(res / np.sqrt(n)), steps=total)


def unit_to_parameter(spec, t: float) -> float:
    """The parameter value (declared unit) at normalised coordinate t of ``spec`` (inverse of
    :func:`clothlab.neural.encodings.normalised_parameters`)."""
    lo, hi = (float(spec.to_internal(b)) for b in spec.bounds)
    return float(spec.from_internal(lo + t * (hi - lo)))


def refine_material(model, wi, wo, values, params: dict, free, *, max_nfev: int = 60) -> tuple[dict, dict, float]:
    """Refine the ``free`` parameters with the exact ``model`` (its far view, ``model.components``) from
    ``params`` (e.g. the fast fit's): bounded least squares (scipy ``least_squares``, trust-region
    reflective) in the normalised coordinates, coefficients by NNLS at every evaluation.  Returns (parameters,
    coefficients by component, RMS residual)."""
    from scipy.optimize import least_squares

    from clothlab.neural.encodings import normalised_parameters

    y = np.asarray(values, dtype=np.float64).reshape(-1)
    free = list(free)
    table = model.params

    def design(x):
        p = {**params, **{k: unit_to_parameter(table[k], t) for k, t in zip(free, x, strict=True)}}
        comps = model.components(wi, wo, p, warn=False)
        return np.column_stack([np.asarray(comps[c]).reshape(-1) for c in model.component_names]), p

    def residual(x):
        a, _ = design(x)
        c, _ = nnls(a, y)
        return a @ c - y

    x0 = np.clip(normalised_parameters(params, table, free), 1e-6, 1 - 1e-6)
    result = least_squares(residual, x0, bounds=(0.0, 1.0), max_nfev=max_nfev, diff_step=1e-4)
    a, p = design(result.x)
    c, res = nnls(a, y)
    return p, dict(zip(model.component_names, c.tolist(), strict=True)), float(res / np.sqrt(y.size))
