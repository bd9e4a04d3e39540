"""Robust losses on top of a fit metric's residuals, and the IRLS weights that solve the linear coefficients.

A fit minimises ``mean_{n,c} rho(r[n,c])`` over the free parameters, r the metric's residuals
(:func:`clothlab.fit.metrics.metric_residuals`, dimensionless for ``relative``: 0.1 = 10 %) and ``rho`` one of
(``LOSSES``; s = ``fit.loss_scale``, in the metric's units, default :data:`DEFAULT_SCALE`):

``squared``  rho(r) = r^2 (the default: mean squared residual, as before);
``l1``       rho(r) = |r| (least absolute deviations; no scale);
``huber``    rho(r) = r^2 for |r| <= s, s (2 |r| - s) beyond (Huber 1964; quadratic core, linear tails);
``cauchy``   rho(r) = s^2 log(1 + (r / s)^2) (Cauchy / Lorentzian; Holland & Welsch 1977).

Each is written rho(r) = g(r^2) with g concave, so g(t) <= g(t0) + g'(t0) (t - t0): a weighted least-squares
problem with row weights u = g'(r0^2) majorises the loss at r0 (Lange, Hunter & Yang 2000, "Optimization
transfer using surrogate objective functions").  Minimising it exactly (the weighted NNLS of
:mod:`clothlab.fit.nnls`, coefficients >= 0) never increases the loss: iteratively reweighted least squares
(IRLS, :func:`irls_coefficients`) therefore decreases it monotonically from the squared-loss solution.  The
weights (up to a constant factor, which least squares ignores): squared 1, l1 1 / |r|, huber
min(1, s / |r|), cauchy 1 / (1 + (r / s)^2).
"""

from __future__ import annotations

import numpy as np

from clothlab.config.choices import DEFAULT_LOSS_SCALE, LOSSES
from clothlab.fit.nnls import nnls_small

DEFAULT_SCALE = DEFAULT_LOSS_SCALE
"""Default ``fit.loss_scale`` of ``huber`` and ``cauchy``: residuals below 0.1 (10 % relative error under the
``relative`` metric, about twice the examples' 5 % noise) count as squared, larger ones are down-weighted."""

L1_FLOOR = 1e-6
"""The l1 IRLS weight is 1 / max(|r|, L1_FLOOR): finite at a residual that is exactly 0."""

IRLS_MAX_ITERATIONS = 12
IRLS_RTOL = 1e-7
"""IRLS stops when one iteration lowers the mean loss by less than this fraction (or after the maximum)."""


def check_loss(loss: str) -> None:
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {', '.join(LOSSES)}")


def rho(residuals, loss: str, scale: float = DEFAULT_SCALE) -> np.ndarray:
    """The loss of each residual (module docstring), same shape as ``residuals``."""
    check_loss(loss)
    r = np.asarray(residuals, dtype=np.float64)
    if loss == "squared":
        return r * r
    a = np.abs(r)
    if loss == "l1":
        return a
    if loss == "huber":
        return np.where(a <= scale, r * r, scale * (2.0 * a - scale))
    return scale * scale * np.log1p((r / scale) ** 2)


def loss_value(residuals, loss: str, scale: float = DEFAULT_SCALE) -> float:
    """mean rho(r), the scalar a fit minimises (NaN propagates, on purpose)."""
    return float(np.mean(rho(residuals, loss, scale)))


def effective_residuals(residuals, loss: str, scale: float = DEFAULT_SCALE) -> np.ndarray:
    """sign(r) sqrt(rho(r)): residuals whose sum of squares is the summed loss (for Gauss-Newton)."""
    r = np.asarray(residuals, dtype=np.float64)
    return r if loss == "squared" else np.sign(r) * np.sqrt(rho(r, loss, scale))


def irls_weights(residuals, loss: str, scale: float = DEFAULT_SCALE) -> np.ndarray:
    """u = g'(r^2) up to a constant (module docstring): the row weights of one IRLS step."""
    check_loss(loss)
    a = np.abs(np.asarray(residuals, dtype=np.float64))
    if loss == "squared":
        return np.ones_like(a)
    if loss == "l1":
        return 1.0 / np.maximum(a, L1_FLOOR)
    if loss == "huber":
        return np.minimum(1.0, scale / np.maximum(a, 1e-300))
    return 1.0 / (1.0 + (a / scale) ** 2)


def irls_coefficients(design, y, weights, loss: str, scale: float = DEFAULT_SCALE):
    """Non-negative coefficients (k, C) minimising sum rho(w (A c - y)) per channel, by IRLS from the squared
    solution (each step one weighted NNLS, :func:`clothlab.fit.nnls.nnls_small`).

    ``design`` (N, k), ``y`` and ``weights`` (N, C): the metric's linearised residual is w (A c - y) (exact
    for ``relative``).  Returns (coef, iterations, converged); the loss never increases from one iterate to
    the next (a step that would, by rounding, is not taken)."""
    coef, _ = nnls_small(design, y, weights)
    if loss == "squared":
        return coef, 0, True
    value = loss_value(weights * (design @ coef - y), loss, scale)
    for iteration in range(1, IRLS_MAX_ITERATIONS + 1):
        r = weights * (design @ coef - y)
        new, _ = nnls_small(design, y, weights * np.sqrt(irls_weights(r, loss, scale)))
        new_value = loss_value(weights * (design @ new - y), loss, scale)
        if not new_value <= value:  # NaN, or no decrease (rounding): keep the current iterate
            return coef, iteration, bool(np.isfinite(value))
        decrease = value - new_value
        coef, value = new, new_value
        if decrease <= IRLS_RTOL * value:
            return coef, iteration, True
    return coef, IRLS_MAX_ITERATIONS, False
