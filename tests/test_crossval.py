"""k-fold cross-validation: the split keeps every exitant direction in every fold, held-out predictions are
computed from training rows only, held-out errors are not below in-sample ones, scattered data fall back to a
random split, and a CV that cannot run never costs the fit."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

from clothlab.config import load_config
from clothlab.fit.crossval import CrossValidationError, choose_scheme, cross_validate, fold_labels
from clothlab.fit.metrics import relative_errors
from clothlab.fit.problem import FitProblem
from clothlab.fit.runner import build_problem
from clothlab.simulate.gonio import simulate

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


def _scattered_problem(n=40, seed=5):
    """n rows on random directions: every exitant direction has exactly one row."""
    full, truth = _problem(every=1)
    rng = np.random.default_rng(seed)
    ti, to = rng.uniform(0, 75, n), rng.uniform(0, 75, n)
    pi_, po = rng.uniform(0, 360, n), rng.uniform(0, 360, n)
    m = simulate(full.model, truth, full.measurement.provenance["coefficients"], sampling=(ti, pi_, to, po))
    return FitProblem(full.model, m, ("beta",), truth, None, "relative"), truth


def test_scattered_data_one_row_per_exitant_direction_use_the_random_scheme():
    problem, truth = _scattered_problem()
    m = problem.measurement
    assert len(set(zip(m.theta_o.tolist(), m.phi_o.tolist(), strict=True))) == m.n
    with pytest.raises(CrossValidationError, match="fewer than k = 5"):
        fold_labels(m, 5, seed=0, scheme="grouped")
    labels = fold_labels(m, 5, seed=0, scheme="random")
    assert np.bincount(labels).tolist() == [8] * 5
    out = cross_validate(problem, truth, k=5, seed=0, max_evals=10)
    assert out["scheme"] == "random" and "40 of 40 exitant directions" in out["scheme_reason"]
    assert "random" in out["split"] and out["held_out"]["n"] == m.n * 3
    assert [f["n_test"] for f in out["folds"]] == [8] * 5
    with pytest.raises(CrossValidationError, match="use the random scheme"):  # before any refit
        cross_validate(problem, truth, k=5, seed=0, max_evals=10, scheme="grouped")


def test_auto_scheme_is_grouped_on_the_paper_grid():
    problem, truth = _problem()
    assert choose_scheme(problem.measurement, 5)[0] == "grouped"
    assert choose_scheme(problem.measurement, 5, "random") == ("random", "random (requested)")
    out = cross_validate(problem, truth, k=2, seed=0, max_evals=1)
    assert out["scheme"] == "grouped" and "all 7 exitant directions" in out["scheme_reason"]
    with pytest.raises(ValueError, match="unknown cross-validation scheme"):
        choose_scheme(problem.measurement, 5, "leave-one-out")


def test_too_few_rows_for_the_folds_still_saves_the_fit(tmp_path, capsys):
    """3 rows, 5 folds: the fit is saved, fit.json and the fit report carry the note, the CLI exits 0."""
    import json

    from clothlab.cli.main import main

    source = ROOT / "measurements" / "polyester-lining" / "noisy.csv"
    lines = source.read_text().splitlines()
    header = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if not line.startswith("#")]
    (tmp_path / "tiny.csv").write_text("\n".join(header + body[:1] + body[1:200:70]) + "\n")
    config = tmp_path / "fabric.yaml"
    config.write_text("""name: tiny
measurement: {path: tiny.csv}
model:
  kind: irawan
  weave: preset:polyester-lining
  quadrature: {rule: trapezoid, nodes: 5}
  params: {warp.umax: 20, weft.umax: 20, warp.kappa: 0, weft.kappa: 0, alpha: 0.05, beta: 2}
fit:
  free: [beta]
  metric: relative
  cv_folds: 5
  optimizer: {global: GN_CRS2_LM, local: LN_BOBYQA, max_evals: 30, starts: 1, seed: 1}
output: {fits: fits, reports: reports}
""")
    assert main(["fit", str(config), "--quiet"]) == 0
    out, err = capsys.readouterr()
    fit = json.loads((tmp_path / "fits" / "tiny" / "fit.json").read_text())
    assert "3 rows, fewer than k = 5 folds" in fit["cross_validation"]["failed"]
    assert any("cross-validation (5-fold) not run" in w for w in fit["warnings"])
    warned = [line for line in err.splitlines() if "not run" in line]
    assert len(warned) == 1 and "Traceback" not in err  # one line on stderr
    assert "cross-validation (5-fold) not run" in out  # the fit report printed after the fit


def test_incident_grouping_and_leave_one_direction_out():
    """Scattered exitant directions but repeated incident ones: auto picks grouped-incident; leave-one-direction-
    out holds out every row of one exitant direction per fold."""
    full, truth = _problem(every=1)
    rng = np.random.default_rng(2)
    ti, pi_ = np.repeat(rng.uniform(0, 70, 6), 8), np.repeat(rng.uniform(0, 360, 6), 8)  # 6 incident x 8 rows
    to, po = rng.uniform(0, 70, 48), rng.uniform(0, 360, 48)
    m = simulate(full.model, truth, full.measurement.provenance["coefficients"], sampling=(ti, pi_, to, po))
    scheme, reason = choose_scheme(m, 5)
    assert scheme == "grouped-incident" and "all 6 incident directions" in reason
    labels = fold_labels(m, 5, seed=1, scheme=scheme)
    for g in np.unique(ti):
        counts = np.bincount(labels[ti == g], minlength=5)
        assert counts.max() - counts.min() <= 1
    grid, _ = _problem(every=5)
    lodo = fold_labels(grid.measurement, 5, seed=0, scheme="leave-one-direction-out")
    gm = grid.measurement
    assert lodo.max() + 1 == 7
    for fold in range(7):
        held = lodo == fold
        assert len(set(zip(gm.theta_o[held].tolist(), gm.phi_o[held].tolist(), strict=True))) == 1
        assert not ((gm.theta_o[~held] == gm.theta_o[held][0]) & (gm.phi_o[~held] == gm.phi_o[held][0])).any()


def test_neutral_refit_starts_from_the_start_values_not_the_optimum():
    """Refit from the start (umax 12 deg, truth 22): the neutral refit's search finds the truth on every fold
    although it is handed a wrong "optimum" (60 deg); a 1-evaluation local refit stays at that point."""
    from clothlab.config.schema import OptimizerConfig

    problem, truth = _problem(free=("warp.umax",), every=9)
    problem = FitProblem(problem.model, problem.measurement, problem.free, {**truth, "warp.umax": 12.0}, None,
                         "relative")
    wrong = {**truth, "warp.umax": 60.0}
    opt = OptimizerConfig(global_algorithm=None, max_evals=150, starts=1, polish=30)
    out = cross_validate(problem, wrong, k=3, seed=0, refit="neutral", optimizer=opt, max_evals=150)
    assert out["refit_mode"] == "neutral" and "from the start values" in out["refit"]
    assert all(abs(f["params"]["warp.umax"] - 22.0) < 0.2 for f in out["folds"])  # measured 22.00-22.11
    local = cross_validate(problem, wrong, k=3, seed=0, refit="local", max_evals=1)
    assert all(f["params"]["warp.umax"] == pytest.approx(60.0) for f in local["folds"])
    assert out["held_out"]["p50"] < local["held_out"]["p50"]
    with pytest.raises(ValueError, match="unknown cross-validation refit"):
        cross_validate(problem, wrong, k=3, refit="warm")


# ------------------------------------------------------------------------------------------- folds on a runner
def _without_wall_time(cv: dict) -> dict:
    return {key: value for key, value in cv.items() if key != "wall_time_s"}


def test_folds_on_a_runner_give_the_in_process_figures_and_a_failed_attempt_is_retried(monkeypatch, caplog):
    """One task per fold (in-process Runner): the same dict as the loop, bit for bit, for both refits; the
    fold tasks' progress counts are shown; a fold raising once is retried by name and nothing changes."""
    import io
    import logging

    from clothlab.config.schema import OptimizerConfig
    from clothlab.fit import crossval
    from clothlab.parallel import InProcessRunner
    from clothlab.progress import configured

    problem, truth = _problem(free=("warp.umax", "beta"), every=5)
    opt = OptimizerConfig(max_evals=60, starts=2, seed=3)
    for refit in ("local", "neutral"):
        loop = cross_validate(problem, truth, k=4, seed=2, max_evals=40, refit=refit, optimizer=opt)
        stream = io.StringIO()
        with configured(0, stream=stream):
            tasks = cross_validate(problem, truth, k=4, seed=2, max_evals=40, refit=refit, optimizer=opt,
                                   runner=InProcessRunner())
        assert _without_wall_time(tasks) == _without_wall_time(loop)
        assert "cross-validation folds: 4 done, 0 running, 0 failed" in stream.getvalue()
    real, attempts = crossval.fold_task, []

    def flaky(job, fold):
        attempts.append(fold)
        if fold == 1 and attempts.count(1) == 1:
            raise RuntimeError("worker lost")
        return real(job, fold)

    monkeypatch.setattr(crossval, "fold_task", flaky)
    with caplog.at_level(logging.WARNING, logger="clothlab"):
        retried = cross_validate(problem, truth, k=4, seed=2, max_evals=40, refit="neutral", optimizer=opt,
                                 runner=InProcessRunner())
    assert sorted(attempts) == [0, 1, 1, 2, 3]
    assert "task fold 2/4 failed (RuntimeError: worker lost); retrying it (attempt 2 of 2)" in caplog.text
    assert _without_wall_time(retried) == _without_wall_time(loop)


def test_a_fold_failing_twice_is_a_note_and_the_fit_is_saved(tmp_path, monkeypatch):
    """A fold task failing on both attempts: the fit's CV is ``failed`` with the finished folds kept, the
    warning names the fold, and the fit is saved whole."""
    import json

    from clothlab.fit import crossval
    from clothlab.fit.runner import run_fit, save_fit
    from clothlab.parallel import InProcessRunner

    cfg = load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml")
    cfg = replace(cfg, fit=replace(cfg.fit, free=("beta",), cv_folds=3, cv_refit="local", posterior=None,
                                   optimizer=replace(cfg.fit.optimizer, max_evals=30, starts=1)))
    real = crossval.fold_task

    def broken(job, fold):
        if fold == 2:
            raise RuntimeError("out of memory")
        return real(job, fold)

    monkeypatch.setattr(crossval, "fold_task", broken)
    result = run_fit(cfg, runner=InProcessRunner())
    cv = result.cross_validation
    assert cv["failed"] == "1 of 3 fold refits failed twice; first: cross-validation fold 3/3 failed 2 times: " \
                           "RuntimeError: out of memory"
    assert [f["fold"] for f in cv["folds"]] == [0, 1] and "held_out" not in cv
    assert any(w.startswith("cross-validation (3-fold) incomplete") for w in result.warnings)
    out = save_fit(result, fits_dir=tmp_path)
    saved = json.loads((out / "fit.json").read_text())
    assert saved["cross_validation"]["failed"] == cv["failed"] and saved["parameters"]["beta"]["value"] > 0


def _grid_measurement(n_exitant: int, rows_each: int):
    """A measurement of n_exitant exitant directions with rows_each distinct incident directions each (values
    are placeholders: only the directions matter to the fold split)."""
    from clothlab.io.measurement import Measurement

    n = n_exitant * rows_each
    theta_o = np.repeat(np.linspace(5.0, 65.0, n_exitant), rows_each)
    phi_o = np.repeat(np.linspace(0.0, 300.0, n_exitant), rows_each)
    theta_i = np.tile(np.linspace(10.0, 70.0, rows_each), n_exitant)
    phi_i = np.tile(np.linspace(20.0, 340.0, rows_each), n_exitant)
    return Measurement(theta_i, phi_i, theta_o, phi_o, np.ones((n, 1)), ("Y",))


def test_grouped_folds_stay_balanced_when_no_group_divides_by_k():
    """7 exitant directions of 7 rows, k = 5: each group deals 2 rows to two folds; dealing each group from where
    the previous one stopped keeps the folds at 10 or 9 rows (restarting every group at fold 0 would give
    14, 14, 7, 7, 7; issue 25: the dropped fold offset survived, the paper grid's groups divide by 5)."""
    m = _grid_measurement(7, 7)
    for seed in range(3):
        labels = fold_labels(m, 5, seed=seed, scheme="grouped")
        sizes = np.bincount(labels, minlength=5)
        assert sizes.sum() == 49 and sizes.max() - sizes.min() <= 1, sizes
        for g in range(7):
            counts = np.bincount(labels[g * 7:(g + 1) * 7], minlength=5)
            assert counts.max() - counts.min() <= 1


def test_random_folds_are_shuffled_by_the_seed():
    """The random scheme deals shuffled rows: the labels are not the rows dealt in file order (0, 1, .., k-1,
    0, ..), and another seed gives another split with the same fold sizes (issue 25: an unshuffled random
    scheme survived, the sizes alone were checked)."""
    m = _grid_measurement(40, 1)
    in_order = np.arange(m.n) % 5
    splits = [fold_labels(m, 5, seed=seed, scheme="random") for seed in range(3)]
    for labels in splits:
        assert np.bincount(labels).tolist() == [8] * 5
        assert not np.array_equal(labels, in_order)
        assert not all(np.array_equal(labels[i::5], np.full(8, labels[i])) for i in range(5))  # not a stride
    assert not np.array_equal(splits[0], splits[1]) and not np.array_equal(splits[1], splits[2])
    np.testing.assert_array_equal(splits[0], fold_labels(m, 5, seed=0, scheme="random"))


def test_exactly_k_rows_per_direction_suffice_for_the_grouped_scheme_and_k_minus_1_do_not():
    """The boundary of the grouped scheme: 5 rows in every exitant direction make 5 folds (each row of a direction
    in its own fold) and ``auto`` chooses it; 4 rows are refused by name and ``auto`` falls back."""
    enough = _grid_measurement(7, 5)
    assert choose_scheme(enough, 5)[0] == "grouped"
    labels = fold_labels(enough, 5, seed=0, scheme="grouped")
    for g in range(7):
        assert sorted(labels[g * 5:(g + 1) * 5].tolist()) == [0, 1, 2, 3, 4]
    short = _grid_measurement(7, 4)
    with pytest.raises(CrossValidationError, match="has 4 rows, fewer than k = 5 folds"):
        fold_labels(short, 5, seed=0, scheme="grouped")
    assert choose_scheme(short, 5)[0] == "grouped-incident"
