"""k-fold cross-validated error of a fit: held-out relative-error percentiles next to in-sample ones.

Two fold schemes:

* ``grouped``: the rows of **each exitant direction** are shuffled (seeded) and dealt to the k folds in turn,
  so every fold holds out about 1/k of the incident directions of every exitant direction (the paper's
  sampling is 225 incident x 7 exitant directions, sec. 4.1).  No fold loses a whole exitant direction.
  Needs at least k rows in every exitant direction.
* ``random``: all rows shuffled (seeded) and dealt to the k folds in turn, for scattered data where exitant
  directions have few rows.  Needs at least k rows.

``auto`` (the default) picks ``grouped`` when every exitant direction has at least k rows, else ``random``;
the result names the scheme and the reason.  No held-out row is used to fit anything: for each fold

* the non-linear parameters are refitted on the training rows by the **local optimiser only**
  (LN_BOBYQA, ``max_evals`` evaluations, default 300) started from the full fit's optimum - a short budget
  that measures how far the optimum moves when 1/k of the data is withheld, without re-running the global
  search (which would mostly measure the global search's own scatter and cost k times the full fit);
* the linear coefficients (kd, ks) are re-solved on the training rows (weighted NNLS, as in the fit);
* the model of that fold is evaluated on its held-out rows.

Every row is held out exactly once; the pooled held-out predictions give the cross-validated relative-error
percentiles (paper sec. 8 figures: median, 80th), reported with the in-sample ones of the full fit and the
pooled training-row errors of the fold fits.
"""

from __future__ import annotations

import time

import numpy as np

from clothlab.config.choices import CV_SCHEMES
from clothlab.fit.metrics import error_percentiles
from clothlab.fit.optimize import minimize
from clothlab.fit.problem import FitProblem, build_problem
from clothlab.progress import Progress

DEFAULT_LOCAL = "LN_BOBYQA"
SCHEMES = CV_SCHEMES
SPLITS = {
    "grouped": ("by incident direction within each exitant direction: each exitant direction's rows are "
                "shuffled and dealt to the folds in turn; every row is held out once"),
    "random": "random by row: all rows shuffled and dealt to the folds in turn; every row is held out once",
}


class CrossValidationError(ValueError):
    """Cross-validation cannot run on these data (e.g. fewer rows than folds)."""


def _exitant_groups(measurement) -> np.ndarray:
    exitant = np.stack([measurement.theta_o, measurement.phi_o], axis=1)
    return np.unique(exitant, axis=0, return_inverse=True)[1].reshape(-1)


def choose_scheme(measurement, k: int, scheme: str = "auto") -> tuple[str, str]:
    """(scheme, reason): ``auto`` resolves to ``grouped`` if every exitant direction has >= k rows, else
    ``random``."""
    if scheme not in SCHEMES:
        raise ValueError(f"unknown cross-validation scheme {scheme!r}; expected one of {', '.join(SCHEMES)}")
    counts = np.bincount(_exitant_groups(measurement)) if measurement.n else np.zeros(0, dtype=int)
    smallest = int(counts.min()) if counts.size else 0
    if scheme != "auto":
        return scheme, f"{scheme} (requested)"
    if smallest >= k:
        return "grouped", (f"grouped by exitant direction: all {counts.size} exitant directions have at least "
                           f"k = {k} rows")
    short = int((counts < k).sum())
    return "random", (f"random by row: {short} of {counts.size} exitant directions have fewer than k = {k} rows "
                      f"(smallest {smallest})")


def fold_labels(measurement, k: int, seed: int, scheme: str = "grouped") -> np.ndarray:
    """(N,) fold index 0..k-1 of every row, by ``scheme`` (``grouped``, ``random`` or ``auto``).

    Raises :class:`CrossValidationError` when the data are too few for k folds under that scheme."""
    if k < 2:
        raise ValueError(f"k-fold cross-validation needs k >= 2, got {k}")
    scheme, _ = choose_scheme(measurement, k, scheme)
    if measurement.n < k:
        raise CrossValidationError(f"{measurement.n} rows, fewer than k = {k} folds: cross-validation not run")
    rng = np.random.default_rng(seed)
    labels = np.empty(measurement.n, dtype=np.int64)
    if scheme == "random":
        labels[rng.permutation(measurement.n)] = np.arange(measurement.n) % k
        return labels
    group = _exitant_groups(measurement)
    offset = 0
    for g in range(int(group.max()) + 1):
        rows = np.flatnonzero(group == g)
        if rows.size < k:
            raise CrossValidationError(f"exitant direction group {g} has {rows.size} rows, fewer than k = {k} "
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


def cross_validate(source, optimum_params: dict | None = None, *, k: int = 5, seed: int = 0,
                   max_evals: int = 300, percentiles=(50, 80), scheme: str = "auto") -> dict:
    """k-fold cross-validated relative-error percentiles (fractions) of a fit.

    Parameters
    ----------
    source : a FitProblem, a zero-argument factory returning one, or a Config (built with build_problem).
    optimum_params : the full fit's optimum (``FitResult.params``); None = the problem's start values, which
        are first polished on all rows with the same local optimiser and budget (noted in the result).
    k, seed : number of folds and the seed of the split.
    scheme : ``auto`` (default), ``grouped`` or ``random`` (module docstring).
    max_evals : local-optimiser evaluations per fold refit.

    Returns ``{"k", "seed", "scheme", "scheme_reason", "split", "refit", "held_out": {"p50", "p80", "mean",
    "n"}, "in_sample": {...}, "train_folds": {...}, "folds": [...], "wall_time_s", "notes"}``.

    With no free parameter only the coefficients are re-solved per fold.  Progress: "cross-validation fold
    3/5" (:class:`clothlab.progress.Progress`).  Raises :class:`CrossValidationError` when the data are too
    few for k folds (checked before any refit).
    """
    started = time.perf_counter()
    problem = _problem_of(source)
    m = problem.measurement
    scheme, reason = choose_scheme(m, k, scheme)
    labels = fold_labels(m, k, seed, scheme)
    bounds = {name: (float(lo), float(hi)) for name, lo, hi in zip(problem.free, problem.lower, problem.upper,
                                                                   strict=True)}
    k_free = len(problem.free)
    notes = []

    def refit(prob, start, desc):
        with Progress(max_evals if k_free else 1, desc, unit="eval") as bar:
            result = minimize(prob, prob.to_unit(start), np.zeros(k_free), np.ones(k_free), global_algorithm=None,
                              local_algorithm=DEFAULT_LOCAL, max_evals=max_evals, seed=seed,
                              callback=lambda row: bar.update(1))
        return prob.from_unit(result.x), result

    if optimum_params is None:
        optimum_params, _ = refit(problem, problem.start, "cross-validation, polish of the start")
        notes.append(f"no optimum given: the start values were polished on all rows ({DEFAULT_LOCAL}, "
                     f"{max_evals} evaluations) first")
    optimum_params = {name: optimum_params[name] for name in problem.start}
    full = problem.solve(optimum_params)
    held_out = np.full_like(problem.y, np.nan)
    train_measured, train_model, folds = [], [], []
    for fold in range(k):
        test = labels == fold
        sub = FitProblem(problem.model, m.subset(~test), problem.free, optimum_params, bounds, problem.metric)
        params, result = refit(sub, optimum_params, f"cross-validation fold {fold + 1}/{k}")
        sol = sub.solve(params)
        design = problem.design(params)[test]
        held_out[test] = design @ sol.coefficients
        train_measured.append(sub.y)
        train_model.append(sol.prediction)
        fold_errors = error_percentiles(problem.y[test], held_out[test], percentiles)["overall"]
        train_errors = error_percentiles(sub.y, sol.prediction, percentiles)["overall"]
        folds.append({"fold": fold, "n_train": int((~test).sum()), "n_test": int(test.sum()),
                      "held_out": fold_errors, "train": train_errors, "evaluations": int(result.nevals),
                      "objective": float(result.fun),
                      "params": {name: float(params[name]) for name in problem.free}})
    return {
        "k": k, "seed": seed, "scheme": scheme, "scheme_reason": reason,
        "split": SPLITS[scheme],
        "refit": (f"each fold: local optimiser only ({DEFAULT_LOCAL}, {max_evals} evaluations) from the full "
                  "fit's optimum on the training rows; linear coefficients re-solved on the training rows"
                  if k_free else "each fold: linear coefficients re-solved on the training rows (no free parameter)"),
        "held_out": error_percentiles(problem.y, held_out, percentiles)["overall"],
        "in_sample": error_percentiles(problem.y, full.prediction, percentiles)["overall"],
        "train_folds": error_percentiles(np.concatenate(train_measured), np.concatenate(train_model),
                                         percentiles)["overall"],
        "folds": folds,
        "wall_time_s": time.perf_counter() - started,
        "notes": notes,
    }
