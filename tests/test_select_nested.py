"""Nested cross-validation of model selection (issue 28 item 2, clothlab.fit.nested)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clothlab.config import apply_overrides, load_config
from clothlab.fit.nested import agreement, nested_cross_validation, outer_labels
from clothlab.fit.select import CandidateTask, SelectSettings, candidates, fit_candidate, rank

EXAMPLE = Path(__file__).parent.parent / "measurements" / "scattered-twill" / "fabric.yaml"
SETTINGS = SelectSettings(weaves=("preset:wool-gabardine", "preset:cotton-denim"), kinds=("irawan",),
                          orientation_starts=1, max_evals=40, cv_folds=2, nested=3, losses=())


WINNER = {"candidate": "x", "cv_mean": 0.1, "cv_p50": 0.08, "cv_p80": 0.15}


def _make_task(cfg):
    return lambda fold, c, train, held: CandidateTask(cfg, c, SETTINGS.max_evals, SETTINGS.cv_folds, train,
                                                      held_out=held, outer_fold=fold)


def _nested(cfg, m, runner=None):
    return nested_cross_validation(cfg, m, 3, candidate_list=candidates(SETTINGS), make_task=_make_task(cfg),
                                   run_task=fit_candidate, rank=rank, runner=runner, full_winner=WINNER)


def _config():
    cfg = apply_overrides(load_config(EXAMPLE), max_evals=60)
    return replace(cfg, fit=replace(cfg.fit, posterior=None, cv_folds=0))


@pytest.fixture(scope="module")
def nested():
    from clothlab.io.loader import load_measurement

    cfg = _config()
    m = load_measurement(cfg.measurement.path)
    return cfg, m, _nested(cfg, m)


def test_every_row_is_held_out_once_and_each_fold_has_a_winner(nested):
    cfg, m, out = nested
    labels, _, _ = outer_labels(cfg, m, 3)
    assert out["rows_held_out"] == out["rows"] == m.n
    assert sum(f["n_test"] for f in out["folds"]) == m.n
    assert [f["n_test"] for f in out["folds"]] == [int((labels == k).sum()) for k in range(3)]
    assert out["fits"] == 3 * 2 and out["candidates_per_fold"] == 2
    assert all(f["winner"] in ("wool-gabardine irawan #1", "cotton-denim irawan #1") for f in out["folds"])
    assert out["selection_score"] == {"mean": 0.1, "p50": 0.08, "p80": 0.15}
    assert 0.0 < out["held_out"]["p50"] < out["held_out"]["p80"] < 1.0
    json.dumps(out)  # fit.json material


def test_outer_held_out_prediction_does_not_see_the_held_out_values(nested):
    """Changing the values of fold 0's held-out rows changes none of fold 0's predictions of them (the
    selection and the winner's fit used the other rows only)."""
    from clothlab.fit.nested import nested_tasks

    cfg, m, _ = nested
    labels, _, _ = outer_labels(cfg, m, 3)
    test = labels == 0
    changed = replace(m, values=np.where(test[:, None], m.values * 3.0 + 0.01, m.values))
    cands = candidates(SETTINGS)
    for a, b in zip(nested_tasks(m, labels, cands, _make_task(cfg))[:2],
                    nested_tasks(changed, labels, cands, _make_task(cfg))[:2], strict=True):
        ra, rb = fit_candidate(a), fit_candidate(b)
        np.testing.assert_array_equal(ra.held_out, rb.held_out)
        assert ra.row["cv_mean"] == rb.row["cv_mean"]


def test_a_runner_gives_the_in_process_figures_bit_for_bit(nested):
    from clothlab.parallel.runner import InProcessRunner

    cfg, m, out = nested
    with InProcessRunner() as runner:
        again = _nested(cfg, m, runner=runner)
    strip = {"wall_time_s"}
    assert {k: v for k, v in again.items() if k not in strip} == {k: v for k, v in out.items() if k not in strip}


def test_agreement_says_when_outer_winners_differ():
    same = agreement(["a #1"] * 3, [("w", "k")] * 3, full="a #1")
    assert same["winners_agree"] and "same candidate" in same["agreement"]
    differ = agreement(["a #1", "b #1", "a #1"], [("w", "k"), ("v", "k"), ("w", "k")])
    assert not differ["winners_agree"] and "DIFFERENT" in differ["agreement"]
    assert "a #1 (2 of 3)" in differ["agreement"] and "the weave is not determined" in differ["agreement"]
    family = agreement(["a #1", "a #2"], [("w", "k"), ("w", "k")])
    assert "same weave and kind" in family["agreement"]


def test_cli_refuses_one_outer_fold(capsys):
    from clothlab.cli.main import main

    code = main(["fit", "--select", str(EXAMPLE), "--nested", "1", "-o", "/tmp/clothlab-nested-x"])
    assert code == 2 and "--nested" in capsys.readouterr().err


def test_cross_validation_counts_the_directions_the_report_counts():
    """CUReT gives one direction as 11.24997 and 11.25003 deg: CV and the report both count 144 exitant
    directions on the shared corduroy table (they counted 154 and 144)."""
    from clothlab.fit.crossval import DIRECTION_DECIMALS, _exitant_groups
    from clothlab.io.loader import load_measurement
    from clothlab.report.data import EXITANT_DECIMALS, exitant_groups

    assert DIRECTION_DECIMALS == EXITANT_DECIMALS
    from clothlab.io.measurement import Measurement

    t = np.array([11.24996901, 11.25002631, 22.5, 22.5])
    p = np.array([0.0, 0.0, 180.00001985, 180.0])
    synthetic = Measurement(t, p, t, p, np.ones((4, 1)), ("grey",))
    assert int(_exitant_groups(synthetic).max()) + 1 == 2 == len(exitant_groups({"theta_o": t, "phi_o": p}))
    path = Path("/work/shared/data/curet/corduroy.csv")
    if not path.is_file():
        pytest.skip("shared CUReT data not present")
    m = load_measurement(path)
    table = {"theta_o": m.theta_o, "phi_o": m.phi_o}
    assert int(_exitant_groups(m).max()) + 1 == len(exitant_groups(table))


def test_report_header_names_the_fabric_not_the_winning_preset():
    from clothlab.report import html

    fit = {"name": "corduroy", "config": {"name": "corduroy"}, "model": {"weave": "preset:silk-shantung"},
           "selection": {"candidates": []}}
    assert html._header_fabric(fit) == "corduroy (selected weave preset:silk-shantung)"
    assert html._header_fabric({"name": "x", "model": {"weave": "preset:silk-shantung"}}) == "silk-shantung"


def test_the_winner_refit_is_never_worse_than_its_row(tmp_path):
    from clothlab.fit.select import select

    cfg = _config()
    settings = replace(SETTINGS, nested=0, cv_folds=0)
    s = select(cfg, settings, fits_dir=tmp_path)
    assert s.refit["not_worse"] and s.refit["refit_objective"] <= s.ranked[0].row["objective"]
    assert "refit" in s.summary() and s.summary()["refit"]["candidate_objective"] == s.ranked[0].row["objective"]


@pytest.mark.slow
def test_nested_selection_on_dask_workers_is_the_in_process_one(tmp_path, nested):
    """`fit --select --nested K --workers 2`: the (outer fold, candidate) fits as Dask tasks give the same
    outer figures, winners and held-out predictions bit for bit."""
    pytest.importorskip("distributed")
    from clothlab.parallel import make_runner

    cfg, m, out = nested
    runner = make_runner(workers=2)
    try:
        again = _nested(cfg, m, runner=runner)
    finally:
        runner.close()
    strip = {"wall_time_s"}
    assert {k: v for k, v in again.items() if k not in strip} == {k: v for k, v in out.items() if k not in strip}
