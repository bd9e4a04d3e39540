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

BOUND_TOLERANCE = 1e-3
"""A coordinate within this fraction of (upper - lower) of a bound is flagged at_lower / at_upper (in the
optimiser's coordinates, linear in the transform: 84.998 of a [1, 85] deg range is flagged, 99.9 % of any
range too; a log-scaled parameter is flagged within 0.1 % of its log range)."""


def bound_flags(x, lower, upper, tolerance: float = BOUND_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """(at_lower, at_upper): coordinates of ``x`` within ``tolerance`` (a fraction of upper - lower) of a bound.
    The one place bound flags are computed (the optimiser's results and the posterior's identifiability)."""
    x, lower, upper = (np.asarray(a, dtype=np.float64) for a in (x, lower, upper))
    margin = (tolerance * (1.0 + 1e-9)) * (upper - lower)  # 1e-9: 0.999 of a range counts despite rounding
    return x - lower <= margin, upper - x <= margin

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
    box_check: dict | None = None  # the enlarged-box check (:func:`box_check`), when it ran

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
    at_lower, at_upper = bound_flags(x, lower, upper)
    return OptimizeResult(
        x=x, fun=objective.best_value if found else math.nan, nevals=objective.nevals,
        wall_time=wall_time, trace=objective.trace, status=status, success=success, converged=converged,
        message="; ".join(parts), at_lower=at_lower, at_upper=at_upper, seed=int(seed),
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


#: Points of the space-filling design screened before the starts (at most; a power of 2, the balance unit of a
#: Sobol sequence), and at most this fraction of max_evals.
DESIGN_POINTS = 1024
DESIGN_FRACTION = 0.25
#: Probes are taken from the best screened points that lie at least this far apart (max-norm, unit box).
START_SEPARATION = 0.15
#: Probes (short local searches of PROBE_EVALS evaluations) per start; the starts continue from the best probes.
PROBES_PER_START = 3
PROBE_EVALS = 100
MIN_PROBE_EVALS = 20


def design_points(design: str, k: int, n: int, seed: int) -> np.ndarray:
    """(n, k) points in [0, 1)^k: a scrambled Sobol sequence (``sobol``; Owen scrambling, scipy.stats.qmc) or a
    Latin hypercube (``lhs``), seeded, so a fit is reproducible."""
    from scipy.stats import qmc

    if design == "sobol":
        return qmc.Sobol(k, scramble=True, seed=seed).random(n)
    if design == "lhs":
        return qmc.LatinHypercube(k, seed=seed).random(n)
    raise ValueError(f"unknown start design {design!r}; expected sobol or lhs")


def spread_starts(X: np.ndarray, values: np.ndarray, n: int, separation: float = START_SEPARATION) -> list[int]:
    """Indices of up to ``n`` rows of ``X``, best ``values`` first, each at least ``separation`` (max-norm) from
    the ones already taken (non-finite values are never taken)."""
    taken: list[int] = []
    for i in np.argsort(np.where(np.isfinite(values), values, np.inf), kind="stable"):
        if not np.isfinite(values[i]):
            break
        if all(np.max(np.abs(X[i] - X[j])) >= separation for j in taken):
            taken.append(int(i))
            if len(taken) == n:
                break
    return taken


def _screen(problem, X: np.ndarray, callback, bar) -> tuple[np.ndarray, list[TraceRow]]:
    """The objective at every design point (batched when the problem can, ``FitProblem.many``), as trace rows
    of stage "design"."""
    start = time.perf_counter()
    many = getattr(problem, "many", None)
    values = np.asarray(many(X) if many is not None else [problem(x) for x in X], dtype=np.float64)
    elapsed = time.perf_counter() - start
    rows, best = [], math.inf
    for i, value in enumerate(values.tolist()):
        if math.isfinite(value):
            best = min(best, value)
        row = TraceRow(i + 1, elapsed * (i + 1) / len(values), value, best, "design")
        rows.append(row)
        bar.update(1)
        if callback is not None:
            callback(row)
    return values, rows


def multistart_minimize(problem, x0, opt, callback=None) -> OptimizeResult:
    """A fit's starts on ``problem``'s unit box, the best kept and polished (:func:`polish`), then (unless
    ``opt.box_check`` is False) the enlarged-box check (:func:`box_check`, when the problem can enlarge its box).

    With ``opt.design`` ``sobol`` (default) or ``lhs`` the global stage is a space-filling screen: a seeded
    scrambled Sobol (or Latin hypercube) design of min(:data:`DESIGN_POINTS`, DESIGN_FRACTION x max_evals)
    points (a power of 2) plus ``x0`` is evaluated (in batches), and ``opt.starts`` local searches (the local
    algorithm; ``opt.global_algorithm`` as well in start 1 only when ``opt.local_algorithm`` is None) run from
    the best screened points at least :data:`START_SEPARATION` apart, sharing the remaining budget.  With
    ``design: none`` every start is a seeded run of the global algorithm then the local one from ``x0`` (the
    earlier scheme).  The measurements behind this split are in docs/notes/fit-defaults.md ("The global stage").

    ``opt`` is a fit's optimizer settings (algorithms, max_evals, starts, seed, max_time, polish_evals, design,
    box_check); ``callback(row)`` is called after each evaluation.  The traces are concatenated (stage names
    carry the start number when there are several).  With no free parameter the coefficients are solved once
    (:func:`minimize`)."""
    k = len(problem.free)
    if k == 0:
        return minimize(problem, x0, np.zeros(0), np.zeros(0), seed=opt.seed, callback=callback)
    design = getattr(opt, "design", "none")
    best, trace, offset, time_offset = None, [], 0, 0.0
    if design == "none":
        starts = [(np.asarray(x0, dtype=np.float64), opt.global_algorithm)] * opt.starts
    else:
        n_design = 1 << int(math.log2(max(2, min(DESIGN_POINTS, int(DESIGN_FRACTION * opt.max_evals)))))
        X = np.vstack([np.clip(np.asarray(x0, dtype=np.float64), 0.0, 1.0),
                       design_points(design, k, n_design, opt.seed)])
        with Progress(len(X), f"global, {design} design", unit="eval") as bar:
            values, rows = _screen(problem, X, callback, bar)
        trace += rows
        offset, time_offset = len(rows), rows[-1].time
        screen_best = int(np.argmin(np.where(np.isfinite(values), values, np.inf)))
        at_lower, at_upper = bound_flags(X[screen_best], 0.0, 1.0)
        best = OptimizeResult(x=X[screen_best].copy(), fun=float(values[screen_best]), nevals=offset,
                              wall_time=time_offset, trace=[], status={}, converged=False, message="",
                              success=bool(np.isfinite(values[screen_best])), at_lower=at_lower,
                              at_upper=at_upper, seed=int(opt.seed))
        # probes: short local searches from the best PROBES_PER_START x starts spread screened points; the starts
        # continue from the best probes (successive halving: a screened value alone picks the wrong basin of a
        # rough valley, measured on cotton-denim, docs/notes/fit-defaults.md)
        local = opt.local_algorithm or MLSL_LOCAL
        picked = spread_starts(X, values, PROBES_PER_START * opt.starts)
        probe_evals = min(PROBE_EVALS, (opt.max_evals - offset) // (2 * max(len(picked), 1)))
        if probe_evals < MIN_PROBE_EVALS:  # a small budget: the starts go straight from the best screened points
            picked, probe_evals = [], 0
        probes = [replace(best, x=X[i], fun=float(values[i])) for i in spread_starts(X, values, opt.starts)]
        for j, i in enumerate(picked):
            if j == 0:
                probes = []
            with Progress(probe_evals, f"probe {j + 1}/{len(picked)}", unit="eval") as bar:
                probe = minimize(problem, X[i], np.zeros(k), np.ones(k), global_algorithm=None, local_algorithm=local,
                                 max_evals=probe_evals, seed=opt.seed, callback=_StageCallback(bar, "", callback))
            for row in probe.trace:
                trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage="probe",
                                          best=min(row.best, best.fun)))
            offset += probe.nevals
            time_offset += probe.wall_time
            probes.append(probe)
            if probe.fun < best.fun:
                best = probe
        order = np.argsort([p.fun for p in probes], kind="stable")[:opt.starts]
        global_algorithm = None if opt.local_algorithm is not None else opt.global_algorithm
        starts = [(probes[i].x, global_algorithm) for i in order]
        n_screened = len(X)
    budget = max((opt.max_evals - offset) // max(len(starts), 1), 1)
    for start, (x_start, global_algorithm) in enumerate(starts):
        prefix = f"start {start + 1}/{len(starts)}"
        with Progress(budget, f"{prefix}, global", unit="eval") as bar:
            result = minimize(problem, x_start, np.zeros(k), np.ones(k), global_algorithm=global_algorithm,
                              local_algorithm=opt.local_algorithm, max_evals=budget, seed=opt.seed + start,
                              max_time=opt.max_time, callback=_StageCallback(bar, prefix, callback))
        best_before = best.fun if best is not None else np.inf
        for row in result.trace:
            stage = row.stage if len(starts) == 1 and design == "none" else f"{row.stage}#{start + 1}"
            trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage=stage,
                                      best=min(row.best, best_before)))
        offset += result.nevals
        time_offset += result.wall_time
        if best is None or result.fun <= best.fun:
            best = result
    if design != "none":
        note = (f"{design} design: {n_screened} points screened, {len(picked)} probes of {probe_evals} evaluations, "
                f"{len(starts)} starts")
        best = replace(best, status={"design": note, **best.status}, message=f"{note}; {best.message}")
    best = replace(best, trace=trace, nevals=offset, wall_time=time_offset)
    best = polish(problem, best, opt, callback)
    if getattr(opt, "box_check", False) and hasattr(problem, "enlarged"):
        best = box_check(problem, best, opt, callback)
    return best


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


# ---------------------------------------------------------------------------------------------- box check
#: The enlarged-box check moves every bound out by this fraction of its range (in the optimiser's coordinates,
#: i.e. in log for log-scaled parameters), clipped to the parameter's physical range.
BOX_ENLARGE = 0.25
#: Evaluations of each local search of the check; points of its design screen of the enlarged box: at most
#: these, and at most a fifth (local searches) and an eighth (screen, a power of 2) of the fit's own
#: ``max_evals`` (:func:`box_check_budget`), so a small fit gets a small check.
BOX_CHECK_EVALS = 300
BOX_CHECK_POINTS = 128
#: The optimum "moves" when the enlarged box holds a point lower by more than this fraction of the objective
#: that lies more than BOX_MOVE_SHIFT (fraction of the original range) from it.
BOX_MOVE_RTOL = 1e-4
BOX_MOVE_SHIFT = 1e-2


def box_check_budget(max_evals: int) -> tuple[int, int]:
    """(evaluations of each local search, points of the screen) of the box check of a fit of ``max_evals``."""
    evals = max(1, min(BOX_CHECK_EVALS, int(max_evals) // 5))
    points = min(BOX_CHECK_POINTS, 2 ** max(1, int(np.log2(max(2, int(max_evals) // 8)))))
    return evals, points


def _swapped_twin(problem, params: dict, fun: float, rtol: float = 1e-6) -> dict | None:
    """The warp/weft-swapped twin of ``params`` - every ``warp.X`` exchanged with ``weft.X``, the orientation
    turned by half its period - when it lies inside ``problem``'s box and has the objective ``fun`` (to
    ``rtol``): the same reflectance with the two yarn sets relabelled.  None otherwise (one evaluation)."""
    names = set(problem.free)
    if not any(n.startswith("warp.") for n in names):
        return None
    twin = dict(params)
    for n in names:
        if n.startswith("warp.") and "weft." + n[5:] in params:
            twin[n], twin["weft." + n[5:]] = params["weft." + n[5:]], params[n]
    for spec, lo in zip(problem.specs, problem.lower, strict=True):
        if spec.period:
            twin[spec.name] = float(lo + (params[spec.name] + 0.5 * spec.period - lo) % spec.period)
    if not all(lo <= twin[n] <= hi for n, lo, hi in zip(problem.free, problem.lower, problem.upper, strict=True)):
        return None
    value = problem.solve(twin).objective
    return {n: float(twin[n]) for n in problem.free} if abs(value - fun) <= rtol * max(abs(fun), 1e-300) else None


def box_check(problem, best: OptimizeResult, opt, callback=None) -> OptimizeResult:
    """Does the optimum move when the box is enlarged?  ``problem.enlarged(BOX_ENLARGE)`` is searched (1) locally
    from the optimum and (2) locally from the best point of a small design screen of the enlarged box that lies
    outside the original box.  The fit keeps ``best`` (the configured bounds hold); the outcome is recorded in
    ``status["box_check"]``, the message and ``box_check`` (a dict: enlarged bounds, objective found there,
    ``moved``, the largest shift as a fraction of the original range and the parameters there).  The check's
    evaluations continue the trace (stage "box-check")."""
    big = problem.enlarged(BOX_ENLARGE)
    k = len(problem.free)
    if np.array_equal(big.lower, problem.lower) and np.array_equal(big.upper, problem.upper):
        out = {"enlarged_by": BOX_ENLARGE, "moved": False, "ran": False,
               "note": "not run: the bounds are already the physical range"}
        return replace(best, box_check=out, status=dict(best.status, box_check=out["note"]))
    x_big = big.to_unit(problem.from_unit(best.x))
    trace, offset, time_offset = list(best.trace), best.nevals, best.wall_time
    local = opt.local_algorithm or MLSL_LOCAL
    found: list[tuple[float, np.ndarray]] = []
    evals, points = box_check_budget(opt.max_evals)
    with Progress(2 * evals + points, "box check", unit="eval") as bar:
        step = _StageCallback(bar, "", callback)
        design = getattr(opt, "design", "none")
        X = design_points("sobol" if design == "none" else design, k, points, opt.seed + 1)
        values, rows = _screen(big, X, callback, bar)
        theta = np.array([[p[name] for name in problem.free] for p in big.from_unit_many(X)])
        outside = ((theta < problem.lower) | (theta > problem.upper)).any(axis=1)
        starts = [x_big]
        candidates = np.where(outside & np.isfinite(values), values, np.inf)
        if np.isfinite(candidates).any():
            starts.append(X[int(np.argmin(candidates))])
        for row in rows:
            trace.append(row._replace(index=row.index + offset, time=row.time + time_offset, stage="box-check",
                                      best=min(row.best, best.fun)))
        offset += len(rows)
        time_offset += rows[-1].time
        for x_start in starts:
            result = minimize(big, x_start, np.zeros(k), np.ones(k), global_algorithm=None, local_algorithm=local,
                              max_evals=evals, seed=opt.seed, callback=step)
            for row in result.trace:
                trace.append(row._replace(index=row.index + offset, time=row.time + time_offset,
                                          stage="box-check", best=min(row.best, best.fun)))
            offset += result.nevals
            time_offset += result.wall_time
            found.append((result.fun, result.x))
    fun, x = min(found, key=lambda item: item[0])
    params = big.from_unit(x)
    t = problem._t([params[name] for name in problem.free])
    lo, hi = problem._t(problem.lower), problem._t(problem.upper)
    delta = t - (lo + best.x * (hi - lo))
    periods = np.array([float(s.period or 0.0) for s in problem.specs])
    # a periodic parameter (orientation) moves by its shortest distance modulo the period: one period away
    # is the same model (issue 28: "shift 125 %" for a point 45 deg from the optimum)
    delta = np.where(periods > 0, (delta + 0.5 * periods) % np.where(periods > 0, periods, 1.0) - 0.5 * periods,
                     delta)
    shift = float(np.max(np.abs(delta) / (hi - lo)))
    wrapped = {n: (float(lo_ + (params[n] - lo_) % p) if p > 0 else params[n])
               for n, lo_, p in zip(problem.free, problem.lower, periods, strict=True)}
    inside = all(lo_ <= wrapped[n] <= hi_ for n, lo_, hi_ in zip(problem.free, problem.lower, problem.upper,
                                                                   strict=True))
    twin = None
    if not inside and fun < best.fun * (1.0 - BOX_MOVE_RTOL) and shift > BOX_MOVE_SHIFT:
        twin = _swapped_twin(problem, params, fun)
        inside = twin is not None
    moved = bool(fun < best.fun * (1.0 - BOX_MOVE_RTOL) and shift > BOX_MOVE_SHIFT and not inside)
    out = {"ran": True, "enlarged_by": BOX_ENLARGE, "moved": moved, "objective": float(fun),
           "objective_in_box": float(best.fun), "max_shift": shift,
           "bounds": {name: [float(a), float(b)] for name, a, b in zip(problem.free, big.lower, big.upper,
                                                                        strict=True)},
           "params": {name: float(params[name]) for name in problem.free}}
    if twin is not None:
        out["twin"] = twin
    out["better_inside"] = bool(inside and fun < best.fun * (1.0 - BOX_MOVE_RTOL) and shift > BOX_MOVE_SHIFT)
    if moved:
        note = (f"box check: the optimum MOVES when every bound is moved out by {100 * BOX_ENLARGE:g} % of its "
                f"range (objective {fun:.6g} < {best.fun:.6g}, shift {100 * shift:.1f} % of the range)")
    elif out["better_inside"]:  # e.g. a warp/weft-swapped twin at another orientation: not a bound problem
        note = (f"box check: the bounds hold (moved out by {100 * BOX_ENLARGE:g} %, the better point found, "
                f"objective {fun:.6g} < {best.fun:.6g}, lies inside the box once the orientation is taken modulo "
                f"its period{' and warp and weft are swapped' if twin is not None else ''}): the fit's search "
                "missed another basin inside the box - more starts, not wider bounds")
    else:
        note = (f"box check: the optimum stays when every bound is moved out by {100 * BOX_ENLARGE:g} % of its "
                f"range (best there {fun:.6g}, in the box {best.fun:.6g})")
    return replace(best, trace=trace, nevals=offset, wall_time=time_offset, box_check=out,
                   status=dict(best.status, box_check=note), message=f"{best.message}; {note}")
