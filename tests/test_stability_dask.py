"""Selection stability on Dask workers (issue 28 items 3 and 8, clothlab.fit.stability): the (subsample,
candidate) fits as Dask tasks give the tallies, winners and verdicts of the in-process loop, bit for bit."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from clothlab.config import apply_overrides, load_config
from clothlab.fit.select import CandidateTask, SelectSettings, candidates, fit_candidate, rank
from clothlab.fit.stability import stability

EXAMPLE = Path(__file__).parent.parent / "measurements" / "scattered-twill" / "fabric.yaml"
SETTINGS = SelectSettings(weaves=("preset:wool-gabardine", "preset:cotton-denim"), kinds=("irawan",),
                          orientation_starts=1, max_evals=40, cv_folds=2, stability=3, losses=())


def _stability(runner=None):
    from clothlab.io.loader import load_measurement

    cfg = apply_overrides(load_config(EXAMPLE), max_evals=60)
    cfg = replace(cfg, fit=replace(cfg.fit, posterior=None, cv_folds=0))
    m = load_measurement(cfg.measurement.path)

    def make_task(b, c, rows):
        return CandidateTask(cfg, c, SETTINGS.max_evals, SETTINGS.cv_folds, rows)

    return stability(m, SETTINGS.stability, seed=1, candidate_list=candidates(SETTINGS), make_task=make_task,
                     run_task=fit_candidate, rank=rank, runner=runner, periods={"irawan": 180.0})


@pytest.mark.slow
def test_stability_on_dask_workers_is_the_in_process_one():
    pytest.importorskip("distributed")
    from clothlab.parallel import make_runner

    here = _stability()
    runner = make_runner(workers=2)
    try:
        there = _stability(runner)
    finally:
        runner.close()
    assert here["fits"] == there["fits"] == 3 * 2 and len(here["winners"]) == 3
    strip = {"wall_time_s"}
    assert {k: v for k, v in there.items() if k not in strip} == {k: v for k, v in here.items() if k not in strip}
