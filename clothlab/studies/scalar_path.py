"""The evaluation path before batching, kept as the benchmarks' "before": one model evaluation per parameter
set through the one-set quadrature loops (:func:`clothlab.models.irawan.integrals.yarn_specular` per segment
type for a model with IM yarn integrals, i.e. a ``quadrature``; other models' ``components``), the QR NNLS
(:func:`clothlab.fit.nnls._careful`) and the metric residuals formed from the prediction.  Same mathematics as
the batched path (Irawan & Marschner 2012, eqs. 1, 2, 7, 10; the coefficients solved linearly, sec. 8), so the
two agree to rounding; only the cost differs.
"""

from __future__ import annotations

import warnings

import numpy as np

from clothlab.errors import GeometryWarning
from clothlab.fit.metrics import LOG_FLOOR, metric_residuals, objective_value
from clothlab.fit.nnls import _careful


def scalar_design(problem, params: dict) -> np.ndarray:
    """(N, k) design of ``problem`` at one parameter dict, evaluated on its own."""
    model = problem.model
    p = model.resolve(params)
    quadrature = model.quadrature
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        if quadrature is None or not set(problem.component_names) <= {"diffuse", "specular_warp", "specular_weft"}:
            comps = model.components(problem.wi, problem.wo, p, normalised=False, warn=False)
            return np.stack([comps[name] for name in problem.component_names], axis=1)
        from clothlab.models.irawan.integrals import yarn_specular

        front = (problem.wi[:, 2] > 0.0) & (problem.wo[:, 2] > 0.0)
        columns = {"diffuse": np.where(front, 1.0 / np.pi, 0.0)}
        for name in problem.component_names:
            if name.startswith("specular_"):
                columns[name] = yarn_specular(problem.wi, problem.wo, p, name.split("_", 1)[1], quadrature)
    return np.stack([columns[name] for name in problem.component_names], axis=1)


def scalar_solve(problem, design: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(k, C) coefficients by the QR NNLS, channel by channel."""
    coef, _ = _careful(design[:, :, None], problem.y, weights)
    return coef.T


def scalar_objective(problem, x) -> float:
    """The fit objective at unit coordinates ``x`` by the scalar path."""
    design = scalar_design(problem, problem.from_unit(x))
    prediction = design @ scalar_solve(problem, design, problem.weights)
    return float(objective_value(metric_residuals(problem.y, prediction, problem.metric)))


def scalar_log_prob(like, X) -> np.ndarray:
    """The posterior's log-probability (:class:`clothlab.fit.posterior._Likelihood`) walker by walker."""
    X = np.atleast_2d(np.asarray(X, dtype=np.float64))
    out = np.full(len(X), -np.inf)
    for i, x in enumerate(X):
        if not np.all((x >= 0.0) & (x <= 1.0)):
            continue
        design = scalar_design(like.problem, like.problem.from_unit(x[:like.k]))
        model = design @ scalar_solve(like.problem, design, like.weights)
        if like.noise == "gaussian-sigma":
            r = (like.y - model) * like.weights
            value = -0.5 * float(np.sum(r * r))
        else:
            s = float(like.noise_scale(x[like.k]))
            r = np.log(np.maximum(model, LOG_FLOOR * like.y) / like.y)
            value = -0.5 * float(np.sum(r * r)) / s**2 - like.y.size * np.log(s)
        out[i] = value if np.isfinite(value) else -np.inf
    return out
