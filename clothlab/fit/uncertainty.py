"""Standard errors and correlations of the fitted parameters from the Gauss-Newton approximation.

At the optimum x* (unit-box coordinates of :class:`clothlab.fit.problem.FitProblem`) the residual vector r(x)
of the fit metric (all values and channels, the linear coefficients re-solved at every x, i.e. the profiled
or "variable projection" residual; under a robust loss each residual is sign(r) sqrt(rho(r)),
:meth:`clothlab.fit.problem.FitProblem.residuals`, so that sum r^2 is the summed loss) is linearised,
r(x) ~ r(x*) + J (x - x*), J by central differences.  The
covariance of the free parameters is then

    C = s^2 (J^T J)^-1,   s^2 = sum r^2 / (n - p),

n the number of values, p the number of fitted quantities (free parameters and linear coefficients): the
estimate least-squares fitters report (lmfit scales its covariance by the reduced chi-square the same way).
It is a local, Gaussian approximation; the emcee posterior (:mod:`clothlab.fit.posterior`) is the better
statement when it ran.  Correlations are those of the unit-box coordinates (linear in log for log-scaled
parameters), as the posterior reports them; standard errors are converted to the declared units.
"""

from __future__ import annotations

import numpy as np

METHOD = "gauss-newton"
STEP = 1e-3
"""Central-difference step in unit-box coordinates (one-sided at a bound).  Not smaller: under a fixed-node
quadrature rule the model is only piecewise smooth in some parameters (yarn angles), and a tiny step measures
the kinks instead of the slope over the parameters' uncertainty (typically 1e-4 to 1e-2 of the range)."""

MAX_CONDITION = 1e12
"""J^T J with a larger condition number is treated as singular (the parameters are not separately determined)."""


def _residuals(problem, x, fixed: dict | None = None) -> np.ndarray:
    at = problem.from_unit(x)
    params = at if fixed is None else {**fixed, **{name: at[name] for name in problem.free}}
    return problem.residuals(params)


def jacobian(problem, x, step=STEP, fixed: dict | None = None) -> np.ndarray:
    """(n, k) derivative of the profiled residual vector with respect to the unit-box coordinates at ``x``
    (``step`` a scalar or one per coordinate); the other parameters from ``fixed`` (default: the problem's
    start values)."""
    x = np.asarray(x, dtype=np.float64)
    steps = np.broadcast_to(np.asarray(step, dtype=np.float64), x.shape)
    columns = []
    for j in range(x.size):
        hi, lo = x.copy(), x.copy()
        hi[j], lo[j] = min(x[j] + steps[j], 1.0), max(x[j] - steps[j], 0.0)
        columns.append((_residuals(problem, hi, fixed) - _residuals(problem, lo, fixed)) / (hi[j] - lo[j]))
    return np.stack(columns, axis=1) if columns else np.zeros((problem.y.size, 0))


def central_jacobian(residuals_many, x, step=STEP) -> np.ndarray:
    """(n, k) central-difference derivative of a residual vector at unit coordinates ``x`` (k,) (one-sided at
    the box's faces), from ``residuals_many(X) -> (2k, n)``: every shifted point in one call."""
    x = np.asarray(x, dtype=np.float64)
    k = x.size
    hi = np.repeat(x[None], k, axis=0)
    lo = hi.copy()
    idx = np.arange(k)
    hi[idx, idx] = np.minimum(x + step, 1.0)
    lo[idx, idx] = np.maximum(x - step, 0.0)
    r = np.asarray(residuals_many(np.concatenate([hi, lo])))
    return ((r[:k] - r[k:]) / (hi[idx, idx] - lo[idx, idx])[:, None]).T


def laplace_covariance(J: np.ndarray, scale: float = 1.0) -> np.ndarray | None:
    """The Laplace (Gauss-Newton) covariance scale (J^T J)^-1 of the coordinates J differentiates, or None
    when J^T J is singular (condition above :data:`MAX_CONDITION` after unit-diagonal scaling, or a column
    without effect): the posterior's start (:mod:`clothlab.fit.posterior.sampler`)."""
    jtj = J.T @ J
    diag = np.sqrt(np.diag(jtj))
    if not np.all(diag > 0) or not np.all(np.isfinite(jtj)):
        return None
    sub = jtj / np.outer(diag, diag)
    if np.linalg.cond(sub) >= MAX_CONDITION:
        return None
    return scale * np.linalg.inv(sub) / np.outer(diag, diag)


def gauss_newton(problem, params: dict, step: float = STEP) -> dict:
    """Standard errors [declared units] and correlations of ``problem``'s free parameters at ``params`` (all
    parameters: the free ones are varied, the others held at their values there).

    Returns ``{"method", "names", "stderr" {name: value or None}, "correlation" {"names", "matrix"}, "dof",
    "scale" (s^2), "notes"}``; None where the Gauss-Newton matrix is singular in that direction."""
    names = list(problem.free)
    k = len(names)
    x = problem.to_unit(params)
    r = _residuals(problem, x, params)
    n_coefficients = len(problem.component_names) * problem.y.shape[1]
    dof = int(r.size - k - n_coefficients)
    out = {"method": METHOD, "names": names, "stderr": {}, "correlation": {"names": names, "matrix": []},
           "dof": dof, "scale": None, "notes": []}
    if k == 0:
        return out
    if dof <= 0:
        out["notes"].append(f"no standard errors: {r.size} values for {k + n_coefficients} fitted quantities")
        out["stderr"] = dict.fromkeys(names)
        return out
    J = jacobian(problem, x, step, params)
    scale = float(r @ r) / dof
    jtj = J.T @ J
    diag = np.sqrt(np.diag(jtj))
    determined = diag > 0
    cov = np.full((k, k), np.nan)
    if determined.any():
        sub = jtj[np.ix_(determined, determined)] / np.outer(diag[determined], diag[determined])
        if np.linalg.cond(sub) < MAX_CONDITION:
            inv = np.linalg.inv(sub) / np.outer(diag[determined], diag[determined])
            cov[np.ix_(determined, determined)] = scale * inv
        else:
            out["notes"].append("the Gauss-Newton matrix is singular: some combination of the free parameters is "
                                "not determined by these data; no standard errors")
    if not determined.all():
        out["notes"].append("no effect on the residuals within the step: "
                            + ", ".join(n for n, d in zip(names, determined, strict=True) if not d))
    lo, hi = problem._t(problem.lower), problem._t(problem.upper)
    values = np.array([params[name] for name in names])
    log = np.array([s.transform == "log" for s in problem.specs])
    dtheta_dx = (hi - lo) * np.where(log, values, 1.0)  # d theta / d x of the unit-box map
    variance = np.diag(cov)
    with np.errstate(invalid="ignore"):
        stderr = np.abs(dtheta_dx) * np.sqrt(variance)
        corr = cov / np.sqrt(np.outer(variance, variance))
    out["stderr"] = {name: (float(v) if np.isfinite(v) else None) for name, v in zip(names, stderr, strict=True)}
    out["correlation"]["matrix"] = [[float(v) if np.isfinite(v) else None for v in row] for row in corr]
    out["scale"] = scale
    return out
