"""The fit objective: free parameters in a unit box, linear coefficients eliminated inside.

For free parameters theta (declared units) the objective is

    F(theta) = mean_{n,c} rho( r(measured[n,c], sum_k c_k[c] component_k(theta)[n]) )

with r the chosen metric (:mod:`clothlab.fit.metrics`), rho the loss (:mod:`clothlab.fit.loss`; ``squared``
rho = r^2 by default) and the coefficients c_k >= 0 solved per channel at every evaluation by non-negative
least squares with the metric's linearised row weights (:func:`clothlab.fit.metrics.linear_weights`; the
paper fits kd and ks linearly too, sec. 8) - for a robust loss by IRLS from that solution
(:func:`clothlab.fit.loss.irls_coefficients`).  Parameters are
seen by the optimiser in [0, 1]: x = (T(theta) - T(lo)) / (T(hi) - T(lo)) with T = log for parameters
declared with a log transform, identity otherwise (the parameters' scales differ by orders of magnitude).
With no free parameter (k = 0) the box is empty and the objective is a single NNLS solve of the coefficients.

An isotropic measurement (``Measurement.isotropic``, e.g. a MERL table: only phi_o - phi_i was measured)
constrains only the BRDF averaged over the fabric's orientation about the normal, so for it every component
is that average (``orientation_nodes`` orientations, midpoint rule over one period of the model,
:attr:`clothlab.models.base.Model.orientation_period`):

    component_k(theta)[n] = (1/M) sum_{m=0}^{M-1} component_k(theta, orientation = (m + 1/2) P / M - P/2)[n]

and ``orientation`` itself cannot be fitted (docs/formats.md, "MERL"; accuracy against M:
docs/notes/orientation-average.md).

:func:`build_problem` makes the problem of a configuration (measurement, weave, model);
:func:`collinearity_notes` and :func:`evaluation_speed` describe a problem's design at a parameter point.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from clothlab.config.build import model_from_config
from clothlab.config.schema import DEFAULT_ORIENTATION_AVERAGE
from clothlab.errors import ConfigError, GeometryWarning
from clothlab.fit.loss import DEFAULT_SCALE, check_loss, effective_residuals, irls_coefficients, loss_value
from clothlab.fit.metrics import check_measurement_for_metric, linear_weights, metric_residuals
from clothlab.fit.nnls import nnls_sets, nnls_small
from clothlab.io.loader import load_measurement
from clothlab.models.base import ORIENTATION
from clothlab.models.components import coefficient_name


@dataclass(frozen=True)
class Solution:
    """Everything at one parameter point: raw coefficients (k, C), prediction (N, C), objective value."""

    params: dict
    coefficients: np.ndarray
    prediction: np.ndarray
    objective: float


class FitProblem:
    """Measurement + model + free parameter set + bounds + metric -> a scalar objective on [0, 1]^k."""

    def __init__(self, model, measurement, free, start: dict | None = None, bounds: dict | None = None,
                 metric: str = "relative", *, loss: str = "squared", loss_scale: float = DEFAULT_SCALE,
                 valid_geometry: bool = False, orientation_nodes: int = DEFAULT_ORIENTATION_AVERAGE):
        check_loss(loss)
        if not (np.isfinite(loss_scale) and loss_scale > 0):
            raise ConfigError(f"loss scale must be a positive number, got {loss_scale!r}", field="fit.loss_scale")
        self.model = model
        self.measurement = measurement
        self.metric = metric
        self.loss, self.loss_scale = loss, float(loss_scale)
        self.free = tuple(free)
        self.start = model.resolve(start or {})
        self.specs = [model.params[name] for name in self.free]
        bounds = bounds or {}
        self.lower = np.array([float(bounds.get(s.name, s.bounds)[0]) for s in self.specs])
        self.upper = np.array([float(bounds.get(s.name, s.bounds)[1]) for s in self.specs])
        for spec, lo, hi in zip(self.specs, self.lower, self.upper, strict=True):
            spec.check(lo, f"fit.bounds.{spec.name}")
            spec.check(hi, f"fit.bounds.{spec.name}")
            if not lo < hi or (spec.transform == "log" and lo <= 0):
                raise ConfigError(f"bounds [{lo:g}, {hi:g}] of {spec.name} are empty or not positive for a "
                                  "log-scaled parameter", field=f"fit.bounds.{spec.name}")
            if spec.period and hi - lo > spec.period * (1.0 + 1e-12):
                raise ConfigError(f"bounds [{lo:g}, {hi:g}] of {spec.name} span more than its period of "
                                  f"{spec.period:g} {spec.unit}: values one period apart are the same model; give at "
                                  "most one period", field=f"fit.bounds.{spec.name}")
        self.valid_geometry = bool(valid_geometry)
        self.geometry_caps: dict = {}
        if valid_geometry:
            self._cap_invalid_geometry(bounds)
        self.wi = np.ascontiguousarray(measurement.wi)
        self.wo = np.ascontiguousarray(measurement.wo)
        self.y = measurement.values
        check_measurement_for_metric(measurement, metric)  # the file, channel and row of a bad value
        self.weights = linear_weights(self.y, metric)
        self.component_names = tuple(model.component_names)
        self.evaluations = 0
        self.orientation_nodes = int(orientation_nodes)
        self.orientations = self._averaged_orientations(self.orientation_nodes)

    def _averaged_orientations(self, nodes: int) -> np.ndarray | None:
        """The orientations (deg) an isotropic measurement averages the model over (module docstring), or
        None (an anisotropic measurement, or a model that does not depend on the orientation)."""
        period = float(self.model.orientation_period)
        if not self.measurement.isotropic or period <= 0:
            return None
        if ORIENTATION in self.free:
            raise ConfigError(f"{self.measurement.source or 'the measurement'} is an isotropic measurement (only "
                              "phi_o - phi_i was measured): the model is averaged over the fabric's orientation, "
                              "which therefore cannot be fitted; remove orientation from fit.free",
                              field="fit.free")
        if int(nodes) < 2:
            raise ConfigError(f"orientation average needs at least 2 orientations, got {nodes}",
                              field="fit.orientation_average")
        return (np.arange(int(nodes)) + 0.5) * period / int(nodes) - 0.5 * period

    def _cap_invalid_geometry(self, given: dict, steps: int = 60) -> None:
        """Shrink the default bounds (not those given in ``given``) of each free parameter to the geometry the
        model accepts without a warning (``Model.geometry_warnings``; for the IM model the segment constraint
        w sin(umax) < l of sec. 5.3), the other parameters at their start values: the valid end is found by
        bisection between the start and the bound (``steps`` halvings).  Recorded in ``geometry_caps``."""
        if self.model.geometry_warnings(self.start):
            return  # the start itself is outside: the user works in the model's limit (nothing to cap towards)
        for i, spec in enumerate(self.specs):
            if spec.name in given:
                continue
            for side, array in ((1, self.upper), (0, self.lower)):
                bound = float(array[i])
                if not self.model.geometry_warnings({**self.start, spec.name: bound}):
                    continue
                good, bad = float(self.start[spec.name]), bound
                for _ in range(steps):
                    mid = 0.5 * (good + bad)
                    if self.model.geometry_warnings({**self.start, spec.name: mid}):
                        bad = mid
                    else:
                        good = mid
                array[i] = good
                self.geometry_caps[spec.name] = {"bound": "upper" if side else "lower", "declared": bound,
                                                 "capped": good}

    # ------------------------------------------------------------------ coordinates
    def _t(self, values):
        return np.array([np.log(v) if s.transform == "log" else v for s, v in zip(self.specs, values, strict=True)])

    def to_unit(self, params: dict) -> np.ndarray:
        """Unit-box coordinates of the free parameters of ``params`` (clipped into the box)."""
        t = self._t([params[name] for name in self.free])
        lo, hi = self._t(self.lower), self._t(self.upper)
        return np.clip((t - lo) / (hi - lo), 0.0, 1.0)

    def from_unit(self, x) -> dict:
        """The full parameter dict (start values with the free ones replaced) at unit coordinates ``x``."""
        return self.from_unit_many(np.asarray(x, dtype=np.float64)[None, :])[0]

    def from_unit_many(self, X) -> list[dict]:
        """:meth:`from_unit` for each row of ``X`` (J, k), in one array operation."""
        X = np.clip(np.atleast_2d(np.asarray(X, dtype=np.float64)), 0.0, 1.0)
        lo, hi = self._t(self.lower), self._t(self.upper)
        t = lo + X * (hi - lo)
        log = np.array([s.transform == "log" for s in self.specs], dtype=bool)
        t[:, log] = np.exp(t[:, log])
        # exp(log(b)) can land an ulp outside the box (5.000000000000001 for a bound of 5): back inside it
        t = np.clip(t, np.asarray(self.lower, dtype=np.float64), np.asarray(self.upper, dtype=np.float64))
        return [{**self.start, **dict(zip(self.free, row, strict=True))} for row in t.tolist()]

    def enlarged(self, fraction: float) -> FitProblem:
        """The same problem on a larger box: every bound moved out by ``fraction`` of the range in the
        optimiser's coordinates (log for log-scaled parameters), clipped to the physical range (an open end
        kept 1e-9 of the range away) and, for a periodic parameter, to one period about the box's centre."""
        lo, hi = self._t(self.lower), self._t(self.upper)
        lo, hi = lo - fraction * (hi - lo), hi + fraction * (hi - lo)
        bounds = {}
        for spec, a, b, old_a, old_b in zip(self.specs, lo, hi, self.lower, self.upper, strict=True):
            a, b = (np.exp(a), np.exp(b)) if spec.transform == "log" else (a, b)
            v_lo, v_hi = spec.valid
            eps = 1e-9 * (v_hi - v_lo)
            a = max(a, v_lo + (eps if spec.open_lower else 0.0))
            b = min(b, v_hi - (eps if spec.open_upper else 0.0))
            if spec.period and b - a > spec.period:  # a periodic parameter's box is at most one period wide
                mid = 0.5 * (old_a + old_b)
                a, b = mid - 0.5 * spec.period, mid + 0.5 * spec.period
            bounds[spec.name] = (float(min(a, old_a)), float(max(b, old_b)))
        return FitProblem(self.model, self.measurement, self.free, self.start, bounds, self.metric,
                          loss=self.loss, loss_scale=self.loss_scale,
                          orientation_nodes=self.orientation_nodes)  # the enlarged box: no geometry cap

    # ------------------------------------------------------------------ evaluation
    def design(self, params: dict, *, normalised: bool = False) -> np.ndarray:
        """(N, k) matrix of the model components at ``params``."""
        return self.designs([params], normalised=normalised)[0]

    def designs(self, params_list, *, normalised: bool = False, wi=None, wo=None) -> np.ndarray:
        """(J, N, k) design matrices at J parameter dicts, in one model call (``Model.components_many``); at the
        measured directions unless ``wi``, ``wo`` are given."""
        wi = self.wi if wi is None else np.ascontiguousarray(wi, dtype=np.float64)
        wo = self.wo if wo is None else np.ascontiguousarray(wo, dtype=np.float64)
        angles = self.orientations
        if angles is not None:  # every set at every orientation of the average, averaged below
            params_list = [{**p, ORIENTATION: float(a)} for p in params_list for a in angles]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GeometryWarning)
            comps = self.model.components_many(wi, wo, params_list, normalised=normalised, warn=False)
        out = np.stack([comps[name] for name in self.component_names], axis=2)
        if angles is None:
            return out
        return out.reshape((-1, len(angles)) + out.shape[1:]).mean(axis=1)

    def solve(self, params: dict, *, normalised: bool = False) -> Solution:
        """Coefficients by weighted NNLS (IRLS for a robust loss), prediction and objective at ``params``."""
        design = self.design(params, normalised=normalised)
        coef, _, _ = irls_coefficients(design, self.y, self.weights, self.loss, self.loss_scale)
        prediction = design @ coef
        value = loss_value(metric_residuals(self.y, prediction, self.metric), self.loss, self.loss_scale)
        return Solution(params, coef, prediction, float(value))

    def residuals(self, params: dict) -> np.ndarray:
        """The residual vector (N C,) at ``params`` whose sum of squares is N C times the objective:
        the metric's residuals, each mapped to sign(r) sqrt(rho(r)) under a robust loss."""
        prediction = self.solve(params).prediction
        return effective_residuals(metric_residuals(self.y, prediction, self.metric).ravel(), self.loss,
                                   self.loss_scale)

    def _fast(self) -> bool:
        return self.metric == "relative" and self.loss == "squared"

    def __call__(self, x) -> float:
        """The objective F at unit coordinates ``x``.  For the ``relative`` metric and the squared loss the
        NNLS weights are 1 / measured, so its residual norms already give F = sum ||w (A c - y)||^2 / (N C) (no
        prediction is formed); the other metrics and losses go through :meth:`solve`."""
        self.evaluations += 1
        params = self.from_unit(x)
        if not self._fast():
            return self.solve(params).objective
        _, residual_norm = nnls_small(self.design(params), self.y, self.weights)
        return float(np.sum(residual_norm**2) / self.y.size)

    def many(self, X, chunk: int = 32) -> np.ndarray:
        """The objective at each row of ``X`` (J, k) unit coordinates, (J,): the model evaluated for
        ``chunk`` points per call (``Model.components_many``) and, for the relative metric and squared loss,
        the coefficients of all of them in one NNLS call (:func:`clothlab.fit.nnls.nnls_sets`)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        out = np.empty(len(X))
        for lo in range(0, len(X), chunk):
            params = self.from_unit_many(X[lo:lo + chunk])
            designs = self.designs(params)
            self.evaluations += len(params)
            if self._fast():
                _, norms = nnls_sets(designs, self.y, self.weights)
                out[lo:lo + len(params)] = np.sum(norms**2, axis=1) / self.y.size
                continue
            for j, design in enumerate(designs):
                coef, _, _ = irls_coefficients(design, self.y, self.weights, self.loss, self.loss_scale)
                out[lo + j] = loss_value(metric_residuals(self.y, design @ coef, self.metric), self.loss,
                                         self.loss_scale)
        return out


def build_problem(config, measurement=None) -> FitProblem:
    """Measurement, weave and model of a configuration -> FitProblem (``measurement`` replaces the configured
    file when given)."""
    if measurement is None:
        measurement = load_measurement(config.measurement.path, None if config.measurement.format == "auto"
                                       else config.measurement.format, **config.measurement.options)
    model = model_from_config(config)
    fit = config.fit
    return FitProblem(model, measurement, fit.free, config.model.params, fit.bounds, fit.metric,
                      loss=fit.loss, loss_scale=fit.loss_scale, valid_geometry=fit.valid_geometry,
                      orientation_nodes=fit.orientation_average)


def collinearity_notes(design: np.ndarray, names, threshold: float = 0.999) -> list[str]:
    """Warnings for pairs of components whose columns are nearly proportional over the measured directions:
    their linear coefficients (colours) are then not separately determined by the data."""
    out = []
    norms = np.linalg.norm(design, axis=0)
    for i in range(design.shape[1]):
        for j in range(i + 1, design.shape[1]):
            if norms[i] == 0.0 or norms[j] == 0.0:
                continue
            cosine = float(design[:, i] @ design[:, j] / (norms[i] * norms[j]))
            if cosine > threshold:
                out.append(f"components {names[i]} and {names[j]} are nearly proportional over these directions "
                           f"(cosine {cosine:.5f}): {coefficient_name(names[i])} and {coefficient_name(names[j])} "
                           "are not separately determined, only their combination is")
    return out


def evaluation_speed(problem: FitProblem, params: dict, repeats: int = 5) -> dict:
    """Direction pairs per second of one full model evaluation (all components) on the measured directions,
    best of ``repeats`` (memoised yarn integrals cleared, so this is the cost of a new parameter point)."""
    best = float("inf")
    for _ in range(repeats):
        problem.model.forget_results()
        t = time.perf_counter()
        problem.design(params)
        best = min(best, time.perf_counter() - t)
    return {"pairs_per_second": problem.measurement.n / best, "seconds_per_evaluation": best,
            "directions": problem.measurement.n}
