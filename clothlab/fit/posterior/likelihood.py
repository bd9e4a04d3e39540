"""The posterior's target: prior x likelihood of a fit problem on its unit box, vectorised over walkers.

Sampled coordinates are the unit box of :class:`clothlab.fit.problem.FitProblem`, plus one coordinate for a
noise scale when the data carry no uncertainties; the prior is uniform in them (:data:`PRIOR_TEXT`).

Likelihood (per value n, channel c; model m = sum_k c_k[c] component_k(theta)[n]):

* measurement with ``sigma``: Gaussian, log L = -1/2 sum ((y - m) / sigma)^2;
* without ``sigma``: log-normal, log(m / y) ~ N(0, s^2) with s sampled (log-uniform prior on ``NOISE_RANGE``),
  log L = -sum [ log(m / y)^2 / (2 s^2) + log s ]  (m floored as in :data:`clothlab.fit.metrics.LOG_FLOOR`).

The linear coefficients are profiled out: re-solved by weighted NNLS at every point (weights 1 / sigma, or
1 / y for the log-normal case; :func:`clothlab.fit.nnls.nnls_sets`), all walkers of a call at once; with
sigma the NNLS residual norms are the chi-square itself.
"""

from __future__ import annotations

import numpy as np

from clothlab.errors import InputError
from clothlab.fit.metrics import LOG_FLOOR, linear_weights
from clothlab.fit.nnls import nnls_sets

NOISE_NAME = "noise.s"
NOISE_UNIT = "1 (std. dev. of log(model / measured))"
NOISE_RANGE = (1e-4, 2.0)
"""Log-uniform prior range of the log-normal noise scale s (used only without sigma columns)."""

PRIOR_TEXT = ("uniform in the optimiser's transform within the fit bounds (uniform for linear parameters, "
              "log-uniform for log-scaled ones), zero outside")


class _Likelihood:
    """log prior + log likelihood of a FitProblem on the unit box, vectorised over walkers."""

    def __init__(self, problem):
        self.problem = problem
        m = problem.measurement
        self.y = problem.y
        k = len(problem.free)
        self.names = list(problem.free)
        self.units = [s.unit for s in problem.specs]
        if m.sigma is not None:
            sigma = np.asarray(m.sigma, dtype=np.float64)
            bad = ~(np.isfinite(sigma) & (sigma > 0))
            if bad.any():
                row = int(np.argwhere(bad)[0][0])
                raise InputError(f"sigma must be finite and > 0 for the Gaussian likelihood; {int(bad.sum())} "
                                 f"values are not (first in row {row}: {float(sigma[bad][0])!r})",
                                 path=m.source, field="sigma")
            self.noise = "gaussian-sigma"
            self.weights = 1.0 / sigma
            self.ndim = k
        else:
            self.noise = "lognormal-fitted-scale"
            self.weights = linear_weights(self.y, "log")  # 1 / y; raises for measured <= 0
            self.ndim = k + 1
            self.names.append(NOISE_NAME)
            self.units.append(NOISE_UNIT)
        self.k = k

    @property
    def description(self) -> str:
        if self.noise == "gaussian-sigma":
            return "Gaussian on the values with the measurement's sigma: log L = -1/2 sum ((y - m) / sigma)^2"
        return ("log-normal: log(m / y) ~ N(0, s^2), s sampled with a log-uniform prior on "
                f"[{NOISE_RANGE[0]:g}, {NOISE_RANGE[1]:g}]: log L = -sum [log(m/y)^2 / (2 s^2) + log s]")

    def noise_scale(self, x):
        """s from its unit coordinate (log-uniform on NOISE_RANGE)."""
        lo, hi = np.log(NOISE_RANGE[0]), np.log(NOISE_RANGE[1])
        return np.exp(lo + np.asarray(x) * (hi - lo))

    def noise_unit(self, s) -> float:
        lo, hi = np.log(NOISE_RANGE[0]), np.log(NOISE_RANGE[1])
        return float(np.clip((np.log(s) - lo) / (hi - lo), 0.0, 1.0))

    def solve_many(self, params_list, wi=None, wo=None):
        """Profiled coefficients (k, m, C) for m parameter dicts (weighted NNLS on the measurement, one call for
        all of them) and the model (m, N', C) at (wi, wo) (the measurement's directions by default)."""
        problem = self.problem
        designs = problem.designs(params_list)  # (m, N, k), one model call for all sets
        coef, _ = nnls_sets(designs, self.y, self.weights)  # (m, k, C)
        if wi is not None:
            designs = problem.designs(params_list, wi=wi, wo=wo)
        return coef.transpose(1, 0, 2), np.matmul(designs, coef)

    def __call__(self, X) -> np.ndarray:
        """log posterior (up to a constant) at unit coordinates X (W, ndim); -inf outside the box."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        out = np.full(X.shape[0], -np.inf)
        inside = np.flatnonzero(np.all((X >= 0.0) & (X <= 1.0), axis=1))
        if inside.size == 0:
            return out
        params = self.problem.from_unit_many(X[inside, :self.k])
        designs = self.problem.designs(params)  # (m, N, k), one model call for all walkers
        coef, residual_norm = nnls_sets(designs, self.y, self.weights)  # (m, k, C), (m, C)
        if self.noise == "gaussian-sigma":  # the weights are 1 / sigma: the NNLS residual is the chi-square
            loglike = -0.5 * np.sum(residual_norm**2, axis=1)
        else:
            model = np.matmul(designs, coef)  # (m, N, C)
            s = self.noise_scale(X[inside, self.k])
            with np.errstate(invalid="ignore"):
                r = np.log(np.maximum(model, LOG_FLOOR * self.y[None]) / self.y[None])
            loglike = -0.5 * np.einsum("mnc,mnc->m", r, r) / s**2 - self.y.size * np.log(s)
        out[inside] = np.where(np.isfinite(loglike), loglike, -np.inf)
        return out
