"""k-fold cross-validation: the split keeps every exitant direction in every fold, held-out predictions are
computed from training rows only, and held-out errors are not below in-sample ones."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

from clothlab.config import load_config
from clothlab.fit.crossval import cross_validate, fold_labels
from clothlab.fit.metrics import relative_errors
from clothlab.fit.problem import FitProblem
from clothlab.fit.runner import build_problem

ROOT = Path(__file__).resolve().parents[1]


def _problem(free=("warp.umax", "beta"), every=3):
    full = build_problem(load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml"))
    m = full.measurement.subset(np.arange(full.measurement.n)[::every])
    truth = {k: m.provenance["parameters"][k] for k in full.start}
    return FitProblem(full.model, m, free, truth, None, "relative"), truth


def test_fold_labels_split_incident_directions_within_each_exitant_direction():
    problem, _ = _problem(every=1)
    m = problem.measurement
    labels = fold_labels(m, 5, seed=3)
    np.testing.assert_array_equal(labels, fold_labels(m, 5, seed=3))
    assert not np.array_equal(labels, fold_labels(m, 5, seed=4))
    assert set(labels.tolist()) == set(range(5))
    exitant = sorted(set(zip(m.theta_o.tolist(), m.phi_o.tolist(), strict=True)))
    assert len(exitant) == 7
    for to, po in exitant:
        rows = (m.theta_o == to) & (m.phi_o == po)
        counts = np.bincount(labels[rows], minlength=5)
        assert counts.max() - counts.min() <= 1  # ~1/5 of this exitant direction's incident directions per fold
    sizes = np.bincount(labels)
    assert sizes.max() - sizes.min() <= 1
    with pytest.raises(ValueError, match="k >= 2"):
        fold_labels(m, 1, seed=0)


def test_held_out_rows_are_predicted_from_training_rows_only():
    """With a 1-evaluation refit the parameters stay at the optimum; the held-out model is then the training-row
    NNLS coefficients (scipy, weights 1/y) applied to the held-out design."""
    problem, truth = _problem()
    out = cross_validate(problem, truth, k=4, seed=2, max_evals=1, percentiles=(50, 80))
    labels = fold_labels(problem.measurement, 4, seed=2)
    y = problem.y
    A = problem.design(truth)
    held = np.empty_like(y)
    for fold in range(4):
        train, test = labels != fold, labels == fold
        for c in range(y.shape[1]):
            w = 1.0 / y[train, c]
            coef, _ = nnls(A[train] * w[:, None], y[train, c] * w)
            held[test, c] = A[test] @ coef
    errors = relative_errors(y, held)
    assert out["held_out"]["p50"] == pytest.approx(np.percentile(errors, 50), rel=1e-9)
    assert out["held_out"]["p80"] == pytest.approx(np.percentile(errors, 80), rel=1e-9)
    assert out["held_out"]["n"] == y.size
    assert [f["n_test"] for f in out["folds"]] == np.bincount(labels).tolist()


def test_held_out_errors_not_below_in_sample():
    """Averaged over the folds, data not used in the fit are predicted no better than data that were."""
    problem, _ = _problem(free=("warp.umax", "weft.umax", "warp.kappa", "weft.kappa", "alpha", "beta"), every=7)
    m = problem.measurement
    truth = m.provenance["parameters"]
    out = cross_validate(problem, None, k=5, seed=0, max_evals=150)
    assert out["notes"]  # no optimum given: it was polished first, and said so
    for key in ("mean", "p50"):
        assert out["held_out"][key] >= out["train_folds"][key]
        assert out["held_out"][key] >= out["in_sample"][key]
    assert set(out["folds"][0]["params"]) == set(problem.free)
    assert abs(out["folds"][0]["params"]["warp.umax"] - truth["warp.umax"]) < 2.0
    assert "exitant" in out["split"] and "local optimiser only" in out["refit"]


def test_config_source_and_noisy_without_sigma():
    """A Config is accepted as the source; sigma plays no role in the cross-validated relative error."""
    cfg = load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml")
    cfg = replace(cfg, fit=replace(cfg.fit, free=("beta",)))
    out = cross_validate(cfg, None, k=2, seed=0, max_evals=20)
    assert out["k"] == 2 and len(out["folds"]) == 2
    assert out["held_out"]["n"] == 1575 * 3
