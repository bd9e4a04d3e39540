"""Error figures and fit metrics for BRDF measurements.

Two uses share this module:

* **Reporting** - :func:`relative_errors` and :func:`error_percentiles` give the fit-quality figures of
  Irawan & Marschner 2012, sec. 8 (median and 80th-percentile relative error per fabric), as fractions
  (0.21 means 21 %).
* **Fitting** - :func:`metric_residuals` / :func:`objective_value` define what a fit minimises, and
  :func:`linear_weights` gives the row weights under which the linear coefficients (kd, ks) are solved
  by weighted least squares inside the objective (the paper fits kd and ks linearly too, sec. 8).

Arrays are ``(N,)`` or ``(N, C)`` (N directions, C colour channels); BRDF values are in 1/sr.

Metrics (``METRICS``):

``relative``  r = (model - measured) / measured; needs measured > 0.
``log``       r = log(max(model, LOG_FLOOR * measured) / measured); needs measured > 0.  The floor keeps
              r finite where the model is 0 (r >= log(1e-6) ~ -13.8) instead of letting one direction make
              the objective infinite.
``cube-root`` r = cbrt(model) - cbrt(measured), a difference of cube roots: the compression of the
              dynamic range of specular peaks used in BRDF fitting (e.g. Ngan, Durand & Matusik 2005,
              "Experimental analysis of BRDF models"; any cos(theta_i) factor is the caller's to apply).
              Units (1/sr)^(1/3); defined for every real measured value (cbrt is odd), so noisy values
              <= 0 are allowed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from clothlab.config.choices import METRICS
from clothlab.config.schema import DEFAULT_PERCENTILES
from clothlab.errors import InputError

LOG_FLOOR = 1e-6
"""Model values are floored at ``LOG_FLOOR * measured`` in the ``log`` metric (residual >= ln 1e-6)."""

CUBE_ROOT_WEIGHT_FLOOR = 1e-6
"""In the ``cube-root`` linear weights, measured is floored at this fraction of its channel maximum."""


def _as_pair(measured, model) -> tuple[np.ndarray, np.ndarray]:
    measured = np.asarray(measured, dtype=np.float64)
    model = np.asarray(model, dtype=np.float64)
    if measured.shape != model.shape:
        raise ValueError(f"measured has shape {measured.shape} but model has shape {model.shape}; "
                         "expected equal shapes (N,) or (N, C)")
    if measured.ndim not in (1, 2):
        raise ValueError(f"expected arrays of shape (N,) or (N, C), got {measured.shape}")
    return measured, model


def _check_metric(metric: str) -> None:
    if metric not in METRICS:
        raise ValueError(f"unknown metric {metric!r}; expected one of {', '.join(METRICS)}")


class MetricDataError(InputError, ValueError):
    """Measured values the chosen metric cannot use (<= 0 for ``relative`` / ``log``): a user-facing
    InputError (one line from the CLI) that is also a ValueError for library callers."""


def _require_positive(measured: np.ndarray, metric: str) -> None:
    bad = ~(measured > 0)
    if bad.any():
        first = np.unravel_index(int(np.argmax(bad)), measured.shape)
        raise MetricDataError(
            f"the {metric!r} metric needs measured values > 0; {int(bad.sum())} are not (first at index "
            f"{tuple(int(i) for i in first)}: {float(measured[first])!r}); drop those rows or use 'cube-root'")


def check_measurement_for_metric(measurement, metric: str) -> None:
    """MetricDataError naming the measurement file, the channel and the row (its four angles, clothlab
    convention, deg) of the first value that ``metric`` cannot use (``relative`` / ``log`` need > 0)."""
    _check_metric(metric)
    if metric == "cube-root":
        return
    values = np.asarray(measurement.values, dtype=np.float64)
    bad = ~(values > 0)
    if not bad.any():
        return
    row, col = np.unravel_index(int(np.argmax(bad)), values.shape)
    angles = ", ".join(f"{name} {float(getattr(measurement, name)[row]):g}"
                       for name in ("theta_i", "phi_i", "theta_o", "phi_o"))
    raise MetricDataError(
        f"the {metric!r} metric needs measured values > 0; {int(bad.sum())} are not, first {float(values[row, col])!r} "
        f"in data row {int(row) + 1} ({angles} deg); drop those rows or use 'cube-root'",
        path=measurement.source, field=str(measurement.channels[col]))


def relative_errors(measured, model) -> np.ndarray:
    """|model - measured| / measured, same shape as the inputs (fractions, dimensionless).

    Where measured <= 0 or either value is not finite the relative error is undefined and NaN is
    returned; :func:`error_percentiles` ignores those entries and reports how many it used (``n``).

    >>> relative_errors([1.0, 2.0, 0.0], [1.1, 1.5, 1.0]).round(6).tolist()
    [0.1, 0.25, nan]
    """
    measured, model = _as_pair(measured, model)
    valid = (measured > 0) & np.isfinite(measured) & np.isfinite(model)
    safe = np.where(valid, measured, 1.0)
    return np.where(valid, np.abs(model - measured) / safe, np.nan)


def _summary(errors: np.ndarray, percentiles: Sequence[float]) -> dict:
    finite = errors[np.isfinite(errors)]
    out: dict = {}
    for p in percentiles:
        out[f"p{p:g}"] = float(np.percentile(finite, p)) if finite.size else float("nan")
    out["mean"] = float(finite.mean()) if finite.size else float("nan")
    out["n"] = int(finite.size)
    return out


def error_percentiles(measured, model, percentiles: Sequence[float] = DEFAULT_PERCENTILES,
                      channels: Sequence[str] | None = None) -> dict:
    """Percentiles and mean of the relative error (Irawan & Marschner 2012, sec. 8), as fractions.

    Returns ``{"overall": {"p50": .., "p80": .., "p95": .., "mean": .., "n": ..}, "per_channel":
    {name: {...}}}``; keys are ``f"p{p:g}"``.  "overall" pools all channels.  Undefined entries
    (measured <= 0, non-finite) are skipped; ``n`` counts the entries used (NaN figures when n == 0).
    Channels default to ``"c0", "c1", ...``.

    >>> measured, model = [[1.0], [2.0], [4.0], [5.0]], [[1.1], [2.0], [3.0], [5.5]]  # errors 10, 0, 25, 10 %
    >>> overall = error_percentiles(measured, model, percentiles=(50, 80))["overall"]
    >>> {key: round(value, 4) for key, value in overall.items()}
    {'p50': 0.1, 'p80': 0.16, 'mean': 0.1125, 'n': 4}
    """
    errors = relative_errors(measured, model)
    if errors.ndim == 1:
        errors = errors[:, None]
    for p in percentiles:
        if not 0 <= p <= 100:
            raise ValueError(f"percentile {p!r} outside [0, 100]")
    n_channels = errors.shape[1]
    if channels is None:
        channels = [f"c{i}" for i in range(n_channels)]
    elif len(channels) != n_channels:
        raise ValueError(f"{len(channels)} channel names {list(channels)} for {n_channels} channels")
    return {
        "overall": _summary(errors.ravel(), percentiles),
        "per_channel": {name: _summary(errors[:, i], percentiles) for i, name in enumerate(channels)},
    }


def metric_residuals(measured, model, metric: str) -> np.ndarray:
    """Residuals of ``model`` against ``measured`` under ``metric`` (see the module docstring).

    Returns an array shaped like the inputs.  ``relative`` and ``log`` raise :class:`MetricDataError`
    (an InputError and ValueError) if any measured value is <= 0 (mask those rows first); a non-finite
    model value gives a non-finite residual, which the optimiser turns into its penalty.

    >>> measured, model = np.array([1.0, 8.0]), np.array([2.0, 1.0])
    >>> metric_residuals(measured, model, "relative").tolist()
    [1.0, -0.875]
    >>> metric_residuals(measured, model, "cube-root").round(6).tolist()  # cbrt(2) - 1, 1 - 2
    [0.259921, -1.0]
    """
    _check_metric(metric)
    measured, model = _as_pair(measured, model)
    if metric == "cube-root":
        return np.cbrt(model) - np.cbrt(measured)
    _require_positive(measured, metric)
    if metric == "relative":
        return (model - measured) / measured
    return np.log(np.maximum(model, LOG_FLOOR * measured) / measured)


def objective_value(residuals) -> float:
    """Mean squared residual, the scalar a fit minimises (NaN propagates, on purpose).

    >>> round(objective_value([0.1, -0.2]), 6)
    0.025
    """
    residuals = np.asarray(residuals, dtype=np.float64)
    return float(np.mean(residuals * residuals))


def information_criteria(objective: float, n: int, k: int) -> tuple[float, float]:
    """(AIC, BIC) = (n ln F + 2 k, n ln F + k ln n) of a fit with objective F (:func:`objective_value`, the
    mean of the loss over the fitted values) over n fitted values (rows x channels) and k estimated numbers (free
    parameters plus linear coefficients); -inf for F <= 0 (an exact fit) or n < 1.  The residuals are taken as
    independent Gaussian with one unknown variance, profiled out (-2 ln L = n ln F + const), so only differences
    between fits of the same data mean anything (the selection table, :mod:`clothlab.fit.select`).

    >>> [round(c, 3) for c in information_criteria(0.01, 100, 3)]  # 100 ln 0.01 + 6, + 3 ln 100
    [-454.517, -446.702]
    """
    if not objective > 0.0 or n < 1:
        return -math.inf, -math.inf
    log_f = n * math.log(objective)
    return log_f + 2.0 * k, log_f + k * math.log(n)


def fit_statistics(objective: float, n: int, k: int) -> dict:
    """lmfit's statistics block of a fit with objective F over n values and k estimated numbers:
    ``{"n", "k", "chi_square", "reduced_chi_square", "aic", "bic"}``.

    chi-square = n F, the sum of the squared metric residuals (under a robust loss the summed loss, the sum of
    squares of :func:`clothlab.fit.loss.effective_residuals`): lmfit's ``chisqr`` with the metric residual as
    the residual (unweighted: sigma plays no role); reduced chi-square = chi-square / (n - k) (NaN when
    n <= k); AIC and BIC by :func:`information_criteria`, which are lmfit's n ln(chisqr / n) + 2 k and
    n ln(chisqr / n) + k ln n.

    >>> stats = fit_statistics(0.01, 100, 3)
    >>> stats["chi_square"], round(stats["reduced_chi_square"], 6), round(stats["bic"], 3)
    (1.0, 0.010309, -446.702)
    """
    aic, bic = information_criteria(objective, n, k)
    chi_square = n * objective
    return {"n": int(n), "k": int(k), "chi_square": chi_square,
            "reduced_chi_square": chi_square / (n - k) if n > k else math.nan, "aic": aic, "bic": bic}


def linear_weights(measured, metric: str) -> np.ndarray:
    """Row weights w such that sum (w (A c - y))^2 is the metric linearised at the data y = measured.

    A residual r(m) is expanded to first order at m = y: r ~ r'(y) (m - y), so w = |r'(y)|:

    * relative: r = (m - y) / y is already linear in m -> w = 1 / y (exact);
    * log: d/dm log(m / y) at m = y is 1 / y -> w = 1 / y;
    * cube-root: d/dm (m^(1/3) - y^(1/3)) at m = y is (1/3) y^(-2/3) -> w = (1/3) y^(-2/3), with y
      floored at ``CUBE_ROOT_WEIGHT_FLOOR`` times its channel maximum (the derivative is infinite at 0).

    Same shape as ``measured``.  ``relative`` and ``log`` need measured > 0 (MetricDataError otherwise).
    """
    _check_metric(metric)
    measured = np.asarray(measured, dtype=np.float64)
    if measured.ndim not in (1, 2):
        raise ValueError(f"expected measured of shape (N,) or (N, C), got {measured.shape}")
    if metric != "cube-root":
        _require_positive(measured, metric)
        return 1.0 / measured
    if not np.isfinite(measured).all():
        raise ValueError("measured holds non-finite values; cannot form cube-root weights")
    peak = np.max(np.abs(measured), axis=0, keepdims=True)
    floor = np.where(peak > 0, CUBE_ROOT_WEIGHT_FLOOR * peak, 1.0)
    return np.cbrt(np.maximum(np.abs(measured), floor)) ** -2 / 3.0
