"""A robust driver around nlopt: a seeded global search, then a local polish from the best point.

:func:`minimize` runs one global + local search; :func:`multistart_minimize` runs a fit's seeded starts and
hands the best to :func:`polish` (restarted local searches).  Progress is shown through
:class:`clothlab.progress.Progress` ("start 2/4, global: 512/1500 eval", then "polish").

The caller hands over an objective in the optimiser's coordinates (already scaled / log-transformed: the
parameters' scales differ by orders of magnitude) and finite bounds.  With no coordinate at all (a fit of the
linear coefficients only) the objective is evaluated once and nlopt is not used.  The driver guards against
nlopt's pitfalls:

* a NaN objective makes BOBYQA / COBYLA report XTOL success at x0 -> every non-finite value is replaced
  by ``penalty`` before nlopt sees it;
* a Python exception inside the objective becomes ``SystemError`` under some algorithms -> the wrapper
  stores it, calls ``force_stop()`` and the original exception is re-raised after ``optimize()``;
* RoundoffLimited (and other failures) can discard the best x, and BOBYQA may step a rounding error
  outside the bounds -> the wrapper clips x to the bounds and keeps its own best point, which is what is
  returned;
* global algorithms stop on ``maxeval`` / ``maxtime`` only (DIRECT_L stops far too early with ftol).

nlopt is imported inside the functions (a heavy library, not needed at package import).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from clothlab.config.choices import GLOBAL_ALGORITHMS as SUPPORTED_GLOBAL
from clothlab.config.choices import LOCAL_ALGORITHMS as SUPPORTED_LOCAL
from clothlab.config.choices import MLSL_LOCAL
from clothlab.progress import Progress

BOUND_TOLERANCE = 1e-6
"""A coordinate within this fraction of (upper - lower) of a bound is flagged at_lower / at_upper."""

_RESULT_NAMES = {
    1: "SUCCESS", 2: "STOPVAL_REACHED", 3: "FTOL_REACHED", 4: "XTOL_REACHED", 5: "MAXEVAL_REACHED",
    6: "MAXTIME_REACHED", -1: "FAILURE", -2: "INVALID_ARGS", -3: "OUT_OF_MEMORY", -4: "ROUNDOFF_LIMITED",
    -5: "FORCED_STOP",
}
_CONVERGED = ("SUCCESS", "FTOL_REACHED", "XTOL_REACHED", "STOPVAL_REACHED")
_FAILED_PREFIXES = ("FAILURE", "INVALID_ARGS", "OUT_OF_MEMORY", "FORCED_STOP", "ERROR")


class TraceRow(NamedTuple):
    """One objective evaluation: 1-based index, wall time since start [s], value returned by the
    objective (NaN / inf kept as returned), best finite value so far (inf before the first), stage."""

    index: int
    time: float
    value: float
    best: float
    stage: str


@dataclass
class OptimizeResult:
    """Outcome of :func:`minimize`; ``x`` / ``fun`` are the best point the objective was evaluated at."""

    x: np.ndarray
    fun: float
    nevals: int
    wall_time: float
    trace: list[TraceRow]
    status: dict[str, str]
    success: bool
    converged: bool
    message: str
    at_lower: np.ndarray
    at_upper: np.ndarray
    seed: int
    algorithms: dict[str, str | None] = field(default_factory=dict)

    def trace_arrays(self) -> dict[str, np.ndarray]:
        """The trace as columns: index, time, value, best (float64 / int64) and stage (str)."""
        rows = self.trace
        return {
            "index": np.array([r.index for r in rows], dtype=np.int64),
            "time": np.array([r.time for r in rows], dtype=np.float64),
            "value": np.array([r.value for r in rows], dtype=np.float64),
            "best": np.array([r.best for r in rows], dtype=np.float64),
            "stage": np.array([r.stage for r in rows], dtype=str),
        }


class _Objective:
    """The wrapper nlopt calls: clip, evaluate, guard, record, remember the best point."""

    def __init__(self, fun, lower, upper, penalty, callback, start):
        self.fun, self.lower, self.upper = fun, lower, upper
        self.penalty, self.callback, self.start = penalty, callback, start
        self.stage = "global"
        self.opt = None
        self.error: BaseException | None = None
        self.nevals = 0
        self.best_x: np.ndarray | None = None
        self.best_value = math.inf
        self.trace: list[TraceRow] = []

    def __call__(self, x, grad):
        if self.error is not None:  # nlopt may call once more after force_stop
            return self.penalty
        try:
            x = np.clip(np.array(x, dtype=np.float64), self.lower, self.upper)
            value = float(self.fun(x.copy()))
            self.nevals += 1
            if math.isfinite(value) and value < self.best_value:
                self.best_value, self.best_x = value, x
            row = TraceRow(self.nevals, time.perf_counter() - self.start, value, self.best_value, self.stage)
            self.trace.append(row)
            if self.callback is not None:
                self.callback(row)
        except BaseException as error:  # noqa: BLE001 - re-raised by minimize after optimize() returns
            self.error = error
            if self.opt is not None:
                self.opt.force_stop()
            return self.penalty
        return value if math.isfinite(value) else self.penalty


def _algorithm(nlopt, name: str | None, supported: tuple[str, ...], kind: str):
    if name is None:
        return None
    if name not in supported:
        raise ValueError(f"unknown {kind} algorithm {name!r}; supported: {', '.join(supported)}")
    return getattr(nlopt, name)


def _check_bounds(x0, lower, upper) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x0 = np.array(x0, dtype=np.float64, ndmin=1)
    lower = np.array(lower, dtype=np.float64, ndmin=1)
    upper = np.array(upper, dtype=np.float64, ndmin=1)
    if x0.ndim != 1 or lower.shape != x0.shape or upper.shape != x0.shape:
        raise ValueError(f"x0, lower and upper must be 1-D of equal length; got shapes {x0.shape}, "
                         f"{lower.shape}, {upper.shape}")
    for i in range(x0.size):
        if not (np.isfinite(lower[i]) and np.isfinite(upper[i]) and lower[i] < upper[i]):
            raise ValueError(f"coordinate {i}: bounds [{float(lower[i])!r}, {float(upper[i])!r}] must be finite with "
                             "lower < upper (leave a fixed parameter out of the optimisation)")
        if not lower[i] <= x0[i] <= upper[i]:
            raise ValueError(f"coordinate {i}: x0 = {float(x0[i])!r} lies outside its bounds "
                             f"[{float(lower[i])!r}, {float(upper[i])!r}]")
    return x0, lower, upper


def _evaluate_once(fun, x0: np.ndarray, seed: int, callback) -> OptimizeResult:
    """The "optimisation" of an empty box: one evaluation, nothing to search (e.g. coefficients-only fits)."""
    start = time.perf_counter()
    value = float(fun(x0.copy()))
    row = TraceRow(1, time.perf_counter() - start, value, value if math.isfinite(value) else math.inf, "nnls")
    if callback is not None:
        callback(row)
    found = math.isfinite(value)
    status = {"nnls": "no free parameters: linear coefficients only, no optimiser run"}
    return OptimizeResult(x=x0.copy(), fun=value if found else math.nan, nevals=1, wall_time=row.time, trace=[row],
                          status=status, success=found, converged=found, message=status["nnls"],
                          at_lower=np.zeros(0, dtype=bool), at_upper=np.zeros(0, dtype=bool), seed=int(seed),
                          algorithms={"global": None, "local": None, "mlsl_local": None})


def _run_stage(nlopt, opt, objective: _Objective, x_start: np.ndarray) -> str:
    """Run one nlopt optimiser; return its status string.  Never loses the wrapper's best point."""
    objective.opt = opt
    opt.set_min_objective(objective)
    try:
        opt.optimize(x_start)
        status = _RESULT_NAMES.get(opt.last_optimize_result(), str(opt.last_optimize_result()))
    except nlopt.RoundoffLimited:
        status = "ROUNDOFF_LIMITED"
    except nlopt.ForcedStop:
        status = "FORCED_STOP"
    except Exception as error:  # noqa: BLE001 - nlopt's SWIG errors, or SystemError from a callback error
        if objective.error is not None:
            status = "FORCED_STOP"
        else:
            detail = opt.get_errmsg() or str(error) or type(error).__name__
            status = f"ERROR ({type(error).__name__}: {detail})"
    if objective.error is not None:
        raise objective.error
    return status


def minimize(fun: Callable[[np.ndarray], float], x0, lower, upper, *,
             global_algorithm: str | None = "GN_CRS2_LM", local_algorithm: str | None = "LN_BOBYQA",
             max_evals: int = 4000, global_fraction: float = 0.6, seed: int = 1, xtol_rel: float = 1e-6,
             ftol_rel: float = 1e-9, max_time: float | None = None,
             callback: Callable[[TraceRow], None] | None = None, penalty: float = 1e30) -> OptimizeResult:
    """Minimise ``fun`` over the box [lower, upper]: global stage, then local polish.

    Parameters
    ----------
    fun : maps a 1-D float64 array (optimiser coordinates) to a float; NaN / inf count as ``penalty``.
    x0, lower, upper : start point and finite bounds (x0 inside the bounds, else ValueError).
    global_algorithm : one of ``SUPPORTED_GLOBAL`` or None (local only).  Seeded with
        ``nlopt.srand(seed)``; stops on maxeval = round(global_fraction * max_evals) and on maxtime
        (global_fraction * max_time) only.  ``G_MLSL_LDS`` runs ``LN_BOBYQA`` from its start points.
    local_algorithm : one of ``SUPPORTED_LOCAL`` or None; polishes from the best point found, with the
        remaining evaluations and time, ``xtol_rel`` and ``ftol_rel``.
    max_evals : total objective evaluations over both stages.
    max_time : total wall-time budget [s] or None.
    callback : called with each :class:`TraceRow` (e.g. for a progress line); an exception from it stops
        the run like one from ``fun``.
    penalty : value nlopt sees for a non-finite objective.

    An exception raised by ``fun`` (or ``callback``) stops nlopt and is re-raised unchanged.  With zero
    coordinates ``fun`` is evaluated once (stage "nnls") and the algorithms are not run.
    """
    x0, lower, upper = _check_bounds(x0, lower, upper)
    if x0.size == 0:
        return _evaluate_once(fun, x0, seed, callback)
    import nlopt

    global_alg = _algorithm(nlopt, global_algorithm, SUPPORTED_GLOBAL, "global")
    local_alg = _algorithm(nlopt, local_algorithm, SUPPORTED_LOCAL, "local")
    if global_alg is None and local_alg is None:
        raise ValueError("at least one of global_algorithm and local_algorithm must be given")
    if int(max_evals) < 1:
        raise ValueError(f"max_evals must be a positive integer, got {max_evals!r}")
    if not 0.0 <= global_fraction <= 1.0:
        raise ValueError(f"global_fraction must lie in [0, 1], got {global_fraction!r}")
    if max_time is not None and not max_time > 0:
        raise ValueError(f"max_time must be positive seconds or None, got {max_time!r}")
    max_evals = int(max_evals)
    n = x0.size
    start = time.perf_counter()
    objective = _Objective(fun, lower, upper, float(penalty), callback, start)
    status: dict[str, str] = {}

    def configure(opt, evals: int, seconds: float | None):
        opt.set_lower_bounds(lower.tolist())
        opt.set_upper_bounds(upper.tolist())
        opt.set_maxeval(evals)
        if seconds is not None:
            opt.set_maxtime(seconds)

    if global_alg is not None:
        global_evals = max_evals if local_alg is None else int(round(global_fraction * max_evals))
        if global_evals > 0:
            nlopt.srand(int(seed))
            opt = nlopt.opt(global_alg, n)
            configure(opt, global_evals, None if max_time is None
                      else max_time * (1.0 if local_alg is None else global_fraction))
            if global_algorithm == "G_MLSL_LDS":
                local = nlopt.opt(getattr(nlopt, MLSL_LOCAL), n)
                local.set_xtol_rel(xtol_rel)
                local.set_ftol_rel(ftol_rel)
                opt.set_local_optimizer(local)
            objective.stage = "global"
            status["global"] = _run_stage(nlopt, opt, objective, x0)
        else:
            status["global"] = "SKIPPED (no evaluations allotted)"

    if local_alg is not None:
        remaining_evals = max_evals - objective.nevals
        remaining_time = None if max_time is None else max_time - (time.perf_counter() - start)
        if remaining_evals <= 0 or (remaining_time is not None and remaining_time <= 0):
            status["local"] = "SKIPPED (budget used by the global stage)"
        else:
            opt = nlopt.opt(local_alg, n)
            configure(opt, remaining_evals, remaining_time)
            opt.set_xtol_rel(xtol_rel)
            opt.set_ftol_rel(ftol_rel)
            objective.stage = "local"
            x_start = x0 if objective.best_x is None else objective.best_x
            status["local"] = _run_stage(nlopt, opt, objective, x_start)

    wall_time = time.perf_counter() - start
    found = objective.best_x is not None
    x = objective.best_x if found else x0.copy()
    failed = [stage for stage, s in status.items() if s.startswith(_FAILED_PREFIXES)]
    success = found and not failed
    final = status.get("local", status.get("global", ""))
    converged = success and final.startswith(_CONVERGED)
    parts = [f"{stage}: {s}" for stage, s in status.items()]
    if not found:
        parts.append(f"no finite objective value in {objective.nevals} evaluations")
    elif success and final.startswith(("MAXEVAL_REACHED", "MAXTIME_REACHED")):
        parts.append("budget exhausted before the tolerances were met")
    span = upper - lower
    return OptimizeResult(
        x=x, fun=objective.best_value if found else math.nan, nevals=objective.nevals,
        wall_time=wall_time, trace=objective.trace, status=status, success=success, converged=converged,
        message="; ".join(parts), at_lower=x - lower <= BOUND_TOLERANCE * span,
        at_upper=upper - x <= BOUND_TOLERANCE * span, seed=int(seed),
        algorithms={"global": global_algorithm, "local": local_algorithm,
                    "mlsl_local": MLSL_LOCAL if global_algorithm == "G_MLSL_LDS" else None},
    )


# ---------------------------------------------------------------------------------------------- a fit's stages
#: A polish round that improves the objective by less than this (relative) ends the polish.
POLISH_RTOL = 1e-6
#: Evaluations of one local search inside the polish.
POLISH_ROUND_EVALS = 600


class _StageCallback:
    """The per-evaluation callback of one start: advances its progress bar, renames it when the stage changes
    ("start 2/4, global" -> "start 2/4, local") and forwards each row to the caller's callback."""

    def __init__(self, bar: Progress, prefix: str, forward=None):
        self.bar, self.prefix, self.forward, self.stage = bar, prefix, forward, None

    def __call__(self, row: TraceRow) -> None:
        if self.prefix and row.stage != self.stage:
            self.stage = row.stage
            self.bar.set_description(f"{self.prefix}, {row.stage}")
        self.bar.update(1)
        if self.forward is not None:
            self.forward(row)


def multistart_minimize(problem, x0, opt, callback=None) -> OptimizeResult:
    """``opt.starts`` independent seeded global + local runs of ``problem`` on its unit box (the budget
    ``opt.max_evals`` split evenly), the best kept and polished (:func:`polish`); the traces are concatenated
    (stage names carry the start number when there are several).  ``opt`` is a fit's optimizer settings
    (algorithms, max_evals, starts, seed, max_time, polish_evals); ``callback(row)`` is called after each
    evaluation.  With no free parameter the coefficients are solved once (:func:`minimize`)."""
    k = len(problem.free)
    if k == 0:
        return minimize(problem, x0, np.zeros(0), np.zeros(0), seed=opt.seed, callback=callback)
    budget = max(opt.max_evals // opt.starts, 1)
    best, trace, offset, time_offset = None, [], 0, 0.0
    for start in range(opt.starts):
        prefix = f"start {start + 1}/{opt.starts}"
        with Progress(budget, f"{prefix}, global", unit="eval") as bar:
            result = minimize(problem, x0, np.zeros(k), np.ones(k), global_algorithm=opt.global_algorithm,
                              local_algorithm=opt.local_algorithm, max_evals=budget, seed=opt.seed + start,
                              max_time=opt.max_time, callback=_StageCallback(bar, prefix, callback))
        best_before = best.fun if best is not None else np.inf
        for row in result.trace:
            stage = row.stage if opt.starts == 1 else f"{row.stage}#{start + 1}"
            trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage=stage,
                                      best=min(row.best, best_before)))
        offset += result.nevals
        time_offset += result.wall_time
        if best is None or result.fun < best.fun:
            best = result
    best = replace(best, trace=trace, nevals=offset, wall_time=time_offset)
    return polish(problem, best, opt, callback)


def polish(problem, best: OptimizeResult, opt, callback=None) -> OptimizeResult:
    """Restart local searches from ``best`` until a round of [opt's local algorithm, LN_SBPLX] improves the
    objective by less than :data:`POLISH_RTOL` relative or ``opt.polish_evals`` is spent.  A restart gets a
    fresh trust region / simplex: on this objective (piecewise smooth under a fixed-node rule) BOBYQA often
    reports convergence early, and SBPLX copes with the roughness.  The result is never worse than ``best``;
    its trace continues best's, stage 'polish'."""
    budget = opt.polish_evals
    k = len(problem.free)
    if budget <= 0 or k == 0:
        return best
    algorithms = tuple(dict.fromkeys(a for a in (opt.local_algorithm, "LN_SBPLX") if a))
    x, fun, trace, offset, time_offset = best.x, best.fun, list(best.trace), best.nevals, best.wall_time
    used, improved = 0, True
    with Progress(budget, "polish", unit="eval") as bar:
        step = _StageCallback(bar, "", callback)
        while improved and used < budget:
            round_start = fun
            for algorithm in algorithms:
                evals = min(POLISH_ROUND_EVALS, budget - used)
                if evals <= 0:
                    break
                result = minimize(problem, x, np.zeros(k), np.ones(k), global_algorithm=None,
                                  local_algorithm=algorithm, max_evals=evals, seed=opt.seed, callback=step)
                for row in result.trace:
                    trace.append(row._replace(index=row.index + offset, time=row.time + time_offset,
                                              stage="polish", best=min(row.best, fun)))
                offset += result.nevals
                time_offset += result.wall_time
                used += result.nevals
                if result.fun < fun:
                    x, fun = result.x, result.fun
                    best = replace(best, x=x, fun=fun, at_lower=result.at_lower, at_upper=result.at_upper)
            improved = fun < round_start * (1.0 - POLISH_RTOL)
    status = dict(best.status, polish=f"{used} evaluations, objective {best.fun:.6g}")
    message = f"{best.message}; polish: {used} evaluations"
    return replace(best, trace=trace, nevals=offset, wall_time=time_offset, status=status, message=message)
