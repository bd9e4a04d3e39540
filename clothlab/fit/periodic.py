"""Periodic parameters in a fit: bounds that span one period are one point, not two limits.

A parameter declared with a ``period`` (:class:`clothlab.params.ParamSpec`; the weave ``orientation`` of every
model, :mod:`clothlab.models.base`) makes the objective periodic along it.  When its fit bounds span (at
least) one period, the lower and the upper bound are the same orientation, so an optimum there is no sign
of a box too small: :func:`release_periodic_bounds` clears the optimiser's at-bound flags of such a
parameter, and :func:`wrap` maps a value into the bounds' period.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np


def spans_period(spec, lower: float, upper: float) -> bool:
    """True when ``spec`` is periodic and [lower, upper] covers a whole period (to 1e-9 relative)."""
    period = getattr(spec, "period", None)
    return bool(period) and (upper - lower) >= period * (1.0 - 1e-9)


def wrap(value: float, lower: float, period: float) -> float:
    """``value`` moved by whole periods into [lower, lower + period)."""
    return float(lower + np.mod(value - lower, period))


def release_periodic_bounds(problem, optimum):
    """``optimum`` (an :class:`clothlab.fit.optimize.OptimizeResult` on ``problem``'s unit box) with the
    at-bound flags cleared for every free periodic parameter whose bounds span a period."""
    periodic = np.array([spans_period(spec, lo, hi) for spec, lo, hi in
                         zip(problem.specs, problem.lower, problem.upper, strict=True)], dtype=bool)
    if not periodic.any() or len(optimum.at_lower) != len(periodic):
        return optimum
    return replace(optimum, at_lower=optimum.at_lower & ~periodic, at_upper=optimum.at_upper & ~periodic)
