"""k-fold cross-validated error of a fit: held-out relative-error percentiles next to in-sample ones.

Fold schemes (``SCHEMES``):

* ``grouped``: the rows of **each exitant direction** are shuffled (seeded) and dealt to the k folds in turn,
  so every fold holds out about 1/k of the incident directions of every exitant direction (the paper's
  sampling is 225 incident x 7 exitant directions, sec. 4.1).  No fold loses a whole exitant direction.
  Needs at least k rows in every exitant direction.
* ``grouped-incident``: the same with the roles swapped: the rows of each **incident** direction are dealt to
  the folds (every fold holds out ~1/k of the exitant directions of every illumination).  Needs at least k
  rows in every incident direction.
* ``leave-one-direction-out``: one fold per exitant direction, holding out **all** its rows: how well the
  model predicts a view it has never seen (k is then the number of exitant directions, >= 2).
* ``random``: all rows shuffled (seeded) and dealt to the k folds in turn, for scattered data where
  directions have few rows.  Needs at least k rows.

``auto`` (the default) picks ``grouped`` when every exitant direction has at least k rows, else
``grouped-incident`` when every incident direction has, else ``random``; the result names the scheme and the
reason.  No held-out row is used to fit anything: for each fold

* the non-linear parameters are refitted on the training rows, by ``refit``:

  - ``neutral`` (``fit.cv_refit`` default): the fit's own global + local search
    (:func:`clothlab.fit.optimize.multistart_minimize`) from the problem's **start values**, not from the
    full fit's optimum, with a stated budget (``max_evals`` per fold, default :data:`NEUTRAL_EVALS`, the
    enlarged-box check off).  A refit started at the full-data optimum sits in the basin the held-out rows
    helped choose, which makes held-out errors optimistic; the neutral refit repeats the whole fit.
  - ``local``: the local optimiser only (LN_BOBYQA, ``max_evals`` evaluations, default 300) from the full
    fit's optimum - cheap, and it measures how far the optimum moves when 1/k of the data is withheld.

* the linear coefficients (kd, ks) are re-solved on the training rows (weighted NNLS, as in the fit);
* the model of that fold is evaluated on its held-out rows.

Every row is held out exactly once; the pooled held-out predictions give the cross-validated relative-error
percentiles (paper sec. 8 figures: median, 80th), reported with the in-sample ones of the full fit and the
pooled training-row errors of the fold fits.

The folds are independent: with a :class:`clothlab.parallel.Runner` each is one task (:func:`fold_task` on the
shared :class:`FoldJob`), collected in fold order, so the figures are the in-process loop's bit for bit
(docs/parallel.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from clothlab.config.choices import CV_REFITS, CV_SCHEMES
from clothlab.config.schema import OptimizerConfig
from clothlab.fit.metrics import error_percentiles
from clothlab.fit.optimize import minimize, multistart_minimize
from clothlab.fit.problem import FitProblem, build_problem
from clothlab.progress import Progress

DEFAULT_LOCAL = "LN_BOBYQA"
LOCAL_EVALS = 300
"""Default evaluations of a ``local`` fold refit."""
NEUTRAL_EVALS = 2000
"""Default evaluations of a ``neutral`` fold refit (design screen, starts and polish; measured in
docs/notes/fit-defaults.md: on the polyester-lining example a 5-fold neutral CV costs about 1.3 full fits)."""
SCHEMES = CV_SCHEMES
REFITS = CV_REFITS
SPLITS = {
    "grouped": ("by incident direction within each exitant direction: each exitant direction's rows are "
                "shuffled and dealt to the folds in turn; every row is held out once"),
    "grouped-incident": ("by exitant direction within each incident direction: each incident direction's rows "
                         "are shuffled and dealt to the folds in turn; every row is held out once"),
    "leave-one-direction-out": ("leave one exitant direction out: each fold holds out all rows of one exitant "
                                "direction; every row is held out once"),
    "random": "random by row: all rows shuffled and dealt to the folds in turn; every row is held out once",
}


class CrossValidationError(ValueError):
    """Cross-validation cannot run on these data (e.g. fewer rows than folds)."""


DIRECTION_DECIMALS = 3
"""Directions are grouped after rounding (theta, phi) to this many decimals of a degree - the rule of the
report's direction counts (:data:`clothlab.report.data.EXITANT_DECIMALS`), so both count the same directions
(CUReT's tables give one direction as e.g. 11.24997 and 11.25003 deg)."""


def _groups(theta, phi) -> np.ndarray:
    key = np.stack([np.round(np.asarray(theta, dtype=np.float64), DIRECTION_DECIMALS),
                    np.round(np.asarray(phi, dtype=np.float64), DIRECTION_DECIMALS)], axis=1)
    return np.unique(key, axis=0, return_inverse=True)[1].reshape(-1)


def _exitant_groups(measurement) -> np.ndarray:
    return _groups(measurement.theta_o, measurement.phi_o)


def _incident_groups(measurement) -> np.ndarray:
    return _groups(measurement.theta_i, measurement.phi_i)


def _smallest(groups) -> tuple[np.ndarray, int]:
    counts = np.bincount(groups) if groups.size else np.zeros(0, dtype=int)
    return counts, int(counts.min()) if counts.size else 0


def choose_scheme(measurement, k: int, scheme: str = "auto") -> tuple[str, str]:
    """(scheme, reason): ``auto`` resolves to ``grouped`` if every exitant direction has >= k rows, else to
    ``grouped-incident`` if every incident direction has, else ``random``."""
    if scheme not in SCHEMES:
        raise ValueError(f"unknown cross-validation scheme {scheme!r}; expected one of {', '.join(SCHEMES)}")
    if scheme != "auto":
        return scheme, f"{scheme} (requested)"
    counts, smallest = _smallest(_exitant_groups(measurement))
    if smallest >= k:
        return "grouped", (f"grouped by exitant direction: all {counts.size} exitant directions have at least "
                           f"k = {k} rows")
    short = int((counts < k).sum())
    exitant = (f"{short} of {counts.size} exitant directions have fewer than k = {k} rows (smallest {smallest})")
    incident, smallest_i = _smallest(_incident_groups(measurement))
    if smallest_i >= k:
        return "grouped-incident", (f"grouped by incident direction: {exitant}, but all {incident.size} incident "
                                    f"directions have at least k = {k} rows")
    short_i = int((incident < k).sum())
    return "random", (f"random by row: {exitant}; {short_i} of {incident.size} incident directions too "
                      f"(smallest {smallest_i})")


def fold_labels(measurement, k: int, seed: int, scheme: str = "grouped") -> np.ndarray:
    """(N,) fold index of every row, by ``scheme`` (module docstring; ``auto`` resolved by
    :func:`choose_scheme`): 0..k-1, or 0..D-1 over the D exitant directions for ``leave-one-direction-out``.

    Raises :class:`CrossValidationError` when the data are too few for the folds under that scheme."""
    if k < 2:
        raise ValueError(f"k-fold cross-validation needs k >= 2, got {k}")
    scheme, _ = choose_scheme(measurement, k, scheme)
    if measurement.n < k and scheme != "leave-one-direction-out":
        raise CrossValidationError(f"{measurement.n} rows, fewer than k = {k} folds: cross-validation not run")
    rng = np.random.default_rng(seed)
    labels = np.empty(measurement.n, dtype=np.int64)
    if scheme == "random":
        labels[rng.permutation(measurement.n)] = np.arange(measurement.n) % k
        return labels
    if scheme == "leave-one-direction-out":
        group = _exitant_groups(measurement)
        if group.size == 0 or group.max() < 1:
            raise CrossValidationError("leave-one-direction-out needs at least 2 exitant directions; these data "
                                       "have 1: use the random scheme")
        return group.astype(np.int64)
    what = "exitant" if scheme == "grouped" else "incident"
    group = _exitant_groups(measurement) if scheme == "grouped" else _incident_groups(measurement)
    offset = 0
    for g in range(int(group.max()) + 1):
        rows = np.flatnonzero(group == g)
        if rows.size < k:
            raise CrossValidationError(f"{what} direction group {g} has {rows.size} rows, fewer than k = {k} "
                                       "folds: use the random scheme")
        labels[rng.permutation(rows)] = (offset + np.arange(rows.size)) % k
        offset += rows.size  # continue dealing where the previous group stopped: fold sizes stay balanced
    return labels


def _problem_of(source):
    if isinstance(source, FitProblem):
        return source
    if callable(source) and not hasattr(source, "fit"):
        return source()
    return build_problem(source)


@dataclass(frozen=True)
class FoldJob:
    """Everything a fold refit needs (the runner's shared object, placed on the workers once): the problem, the
    fold labels and the refit settings.  A fold's result depends on this and its index only."""

    problem: FitProblem
    labels: np.ndarray
    optimum_params: dict
    refit: str
    budget: int
    seed: int
    settings: OptimizerConfig
    percentiles: tuple

    @property
    def n_folds(self) -> int:
        return int(self.labels.max()) + 1


def _local(prob, start, budget, seed, desc):
    """The local refit: LN_BOBYQA from ``start``, ``budget`` evaluations."""
    k_free = len(prob.free)
    with Progress(budget if k_free else 1, desc, unit="eval") as bar:
        result = minimize(prob, prob.to_unit(start), np.zeros(k_free), np.ones(k_free), global_algorithm=None,
                          local_algorithm=DEFAULT_LOCAL, max_evals=budget, seed=seed,
                          callback=lambda row: bar.update(1))
    return prob.from_unit(result.x), result


def fold_task(job: FoldJob, fold: int) -> dict:
    """Refit fold ``fold`` of ``job`` on its training rows and predict its held-out rows (one runner task; a
    module-level function).  Returns the fold's summary (``"summary"``) and the arrays the pooled figures
    need."""
    problem = job.problem
    test = job.labels == fold
    desc = f"cross-validation fold {fold + 1}/{job.n_folds}"
    bounds = {name: (float(lo), float(hi)) for name, lo, hi in zip(problem.free, problem.lower, problem.upper,
                                                                   strict=True)}
    neutral = job.refit == "neutral" and bool(problem.free)
    sub = FitProblem(problem.model, problem.measurement.subset(~test), problem.free,
                     problem.start if neutral else job.optimum_params, bounds, problem.metric, loss=problem.loss,
                     loss_scale=problem.loss_scale, orientation_nodes=problem.orientation_nodes)
    if neutral:
        settings = job.settings
        with Progress(settings.max_evals + settings.polish_evals, desc, unit="eval") as bar:
            result = multistart_minimize(sub, sub.to_unit(sub.start), settings, lambda row: bar.update(1))
        params = sub.from_unit(result.x)
    else:
        params, result = _local(sub, job.optimum_params, job.budget, job.seed, desc)
    sol = sub.solve(params)
    held_out = problem.design(params)[test] @ sol.coefficients
    summary = {"fold": fold, "n_train": int((~test).sum()), "n_test": int(test.sum()),
               "held_out": error_percentiles(problem.y[test], held_out, job.percentiles)["overall"],
               "train": error_percentiles(sub.y, sol.prediction, job.percentiles)["overall"],
               "evaluations": int(result.nevals), "objective": float(result.fun),
               "params": {name: float(params[name]) for name in problem.free}}
    return {"summary": summary, "held_out": held_out, "train_measured": sub.y, "train_model": sol.prediction}


def _run_folds(job: FoldJob, runner) -> tuple[list, list[str]]:
    """Every fold's :func:`fold_task` result in fold order (a failure: None) and a note per failed fold.

    No runner: the in-process loop (an error propagates).  A runner: one task per fold, ``job`` shared; a fold
    failing twice (the runner retries once) leaves None and a note."""
    folds = range(job.n_folds)
    if runner is None:
        return [fold_task(job, fold) for fold in folds], []
    from clothlab.parallel import TaskFailure

    names = [f"fold {fold + 1}/{job.n_folds}" for fold in folds]
    outcomes = runner.map(fold_task, folds, shared=job, names=names, desc="cross-validation folds")
    notes = [f"cross-validation {o.name} failed {o.attempts} times: {o.error}" for o in outcomes
             if isinstance(o, TaskFailure)]
    return [None if isinstance(o, TaskFailure) else o for o in outcomes], notes


def cross_validate(source, optimum_params: dict | None = None, *, k: int = 5, seed: int = 0,
                   max_evals: int | None = None, percentiles=(50, 80), scheme: str = "auto",
                   refit: str = "local", optimizer: OptimizerConfig | None = None, runner=None) -> dict:
    """k-fold cross-validated relative-error percentiles (fractions) of a fit.

    Parameters
    ----------
    source : a FitProblem, a zero-argument factory returning one, or a Config (built with build_problem).
    optimum_params : the full fit's optimum (``FitResult.params``); None = the problem's start values, which
        are first polished on all rows with the local optimiser (noted in the result).
    k, seed : number of folds and the seed of the split.
    scheme : ``auto`` (default), ``grouped``, ``grouped-incident``, ``leave-one-direction-out`` or ``random``.
    refit : ``local`` (this function's default, from the optimum) or ``neutral`` (the fit's search from the
        start values; ``clothlab fit`` uses ``fit.cv_refit``, default neutral), module docstring.
    max_evals : evaluations per fold refit (default 300 for local, :data:`NEUTRAL_EVALS` for neutral).
    optimizer : the fit's optimizer settings for a neutral refit (algorithms, starts, design, seed; its budget
        replaced by ``max_evals``); default :class:`clothlab.config.schema.OptimizerConfig`.
    runner : a :class:`clothlab.parallel.Runner`: each fold's refit as one task (:func:`fold_task`, the
        problem placed on the workers once), collected in fold order, so every figure equals the in-process
        loop's (None, the default: that loop).  A fold failing on both attempts makes the result ``failed``
        (the finished folds kept in ``folds``, no pooled figures), never an exception.

    Returns ``{"k", "seed", "scheme", "scheme_reason", "split", "refit", "refit_mode", "budget", "held_out":
    {"p50", "p80", "mean", "n"}, "in_sample": {...}, "train_folds": {...}, "folds": [...], "wall_time_s",
    "notes"}``.

    With no free parameter only the coefficients are re-solved per fold.  Progress: "cross-validation fold
    3/5" (:class:`clothlab.progress.Progress`), with a runner the fold tasks' done / running / failed counts.
    Raises :class:`CrossValidationError` when the data are too few for the folds (checked before any refit).
    """
    if refit not in REFITS:
        raise ValueError(f"unknown cross-validation refit {refit!r}; expected one of {', '.join(REFITS)}")
    started = time.perf_counter()
    problem = _problem_of(source)
    m = problem.measurement
    scheme, reason = choose_scheme(m, k, scheme)
    labels = fold_labels(m, k, seed, scheme)
    n_folds = int(labels.max()) + 1
    budget = int(max_evals if max_evals is not None else NEUTRAL_EVALS if refit == "neutral" else LOCAL_EVALS)
    notes = []
    settings = replace(optimizer or OptimizerConfig(), max_evals=max(budget, 2), polish=budget // 3,
                       box_check=False)
    settings = replace(settings, starts=min(settings.starts, settings.max_evals))
    if optimum_params is None:
        optimum_params, _ = _local(problem, problem.start, budget, seed, "cross-validation, polish of the start")
        notes.append(f"no optimum given: the start values were polished on all rows ({DEFAULT_LOCAL}, "
                     f"{budget} evaluations) first")
    optimum_params = {name: optimum_params[name] for name in problem.start}
    full = problem.solve(optimum_params)
    job = FoldJob(problem, labels, optimum_params, refit, budget, seed, settings, tuple(percentiles))
    results, failures = _run_folds(job, runner)
    if not problem.free:
        how = "each fold: linear coefficients re-solved on the training rows (no free parameter)"
    elif refit == "neutral":
        how = (f"each fold: the fit's search from the start values, not from the full fit's optimum ({settings.design} "
               f"design, {settings.starts} start(s), {budget} evaluations + polish {settings.polish_evals}) on the "
               "training rows; linear coefficients re-solved on the training rows")
    else:
        how = (f"each fold: local optimiser only ({DEFAULT_LOCAL}, {budget} evaluations) from the full fit's "
               "optimum on the training rows (held-out errors may be optimistic); linear coefficients re-solved "
               "on the training rows")
    out = {"k": n_folds, "seed": seed, "scheme": scheme, "scheme_reason": reason, "split": SPLITS[scheme],
           "refit": how, "refit_mode": refit, "budget": budget}
    if failures:
        done = [r["summary"] for r in results if r is not None]
        failed = f"{len(failures)} of {n_folds} fold refits failed twice; first: {failures[0]}"
        return {**out, "failed": failed, "folds": done, "wall_time_s": time.perf_counter() - started,
                "notes": [*notes, *failures]}
    held_out = np.full_like(problem.y, np.nan)
    for fold, r in enumerate(results):
        held_out[labels == fold] = r["held_out"]
    train_measured = np.concatenate([r["train_measured"] for r in results])
    train_model = np.concatenate([r["train_model"] for r in results])
    return {
        **out,
        "held_out": error_percentiles(problem.y, held_out, percentiles)["overall"],
        "in_sample": error_percentiles(problem.y, full.prediction, percentiles)["overall"],
        "train_folds": error_percentiles(train_measured, train_model, percentiles)["overall"],
        "folds": [r["summary"] for r in results],
        "wall_time_s": time.perf_counter() - started,
        "notes": notes,
    }
