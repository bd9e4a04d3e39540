"""Tested the way a cluster runs: a Dask LocalCluster of 2 worker processes on loopback, started and torn down
here; a worker killed (SIGKILL) mid-run; every result still present, in order, identical to the sequential
run, and nothing half-written.  The fast tests use plain tasks and cross-validation folds of a small problem;
the fits and the sweep are marked slow (fresh worker processes load the compiled kernels, ~10 s each on a
loaded 2-core machine)."""

from __future__ import annotations

import json
import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

from test_parallel import make_project  # noqa: E402

from clothlab.parallel import SCHEDULER_ENV, InProcessRunner, TaskFailure, make_runner  # noqa: E402


def _port_open(address: str) -> bool:
    host, port = address.removeprefix("tcp://").rsplit(":", 1)
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((host, int(port))) == 0


@pytest.fixture
def cluster():
    """A 2-process LocalCluster; afterwards its scheduler port is closed and its worker processes are gone."""
    import psutil

    runner = make_runner(workers=2)
    address = runner.client.scheduler.address
    pids = []
    try:
        yield runner, pids
    finally:
        pids += runner.client.run(os.getpid).values() if runner.client.status == "running" else []
        runner.close()
    deadline = time.monotonic() + 10
    while (_port_open(address) or any(psutil.pid_exists(p) for p in pids)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _port_open(address), f"scheduler port {address} left open"
    assert not [p for p in pids if psutil.pid_exists(p)], "worker processes left running"


def _kill_a_busy_worker(client) -> int | None:
    """SIGKILL one worker that is processing a task; its pid (None if no task is running)."""
    for address, keys in client.processing().items():
        if keys:
            pid = client.run(os.getpid, workers=[address])[address]
            os.kill(pid, signal.SIGKILL)
            return pid
    return None


def _square_slowly(x):
    time.sleep(0.3)
    return x * x


def test_a_killed_worker_s_task_is_retried_by_name_and_every_result_lands(cluster, caplog):
    import logging

    runner, pids = cluster
    assert runner.workers == 2 and runner.client.scheduler.address.startswith("tcp://127.0.0.1:")
    killed = []

    def first(i, value):
        if not killed:
            killed.append(_kill_a_busy_worker(runner.client))

    started = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="clothlab"):
        out = runner.map(_square_slowly, range(8), names=[f"sq{i}" for i in range(8)], on_result=first)
    assert killed and killed[0] is not None
    assert out == [x * x for x in range(8)]  # all present, in submission order
    assert "KilledWorker" in caplog.text and "retrying it (attempt 2 of 2)" in caplog.text
    assert time.monotonic() - started < 60
    # the same cluster as an existing one: by --scheduler and by $DASK_SCHEDULER_ADDRESS
    address = runner.client.scheduler.address
    for other in (make_runner(scheduler=address), make_runner(environ={SCHEDULER_ENV: address})):
        with other:
            assert other.description == f"Dask cluster at {address}" and other.cluster is None
            assert other.map(abs, [-1, -2, 3]) == [1, 2, 3]
    assert runner.map(abs, [-4]) == [4]  # closing the other clients left the cluster running


def _flaky_fold(job, item):
    """A cross-validation fold task whose first attempt at fold 2 fails (a marker file remembers)."""
    from clothlab.fit.crossval import fold_task

    marker_dir, fold = item
    marker = Path(marker_dir) / f"fold-{fold}"
    if fold == 1 and not marker.exists():
        marker.touch()
        raise RuntimeError("first attempt at fold 2")
    return fold_task(job, fold)


def test_cross_validation_folds_on_the_cluster_match_the_in_process_loop(tmp_path, cluster, caplog):
    """One task per fold on 2 worker processes (issue 13 item 2), the first attempt at fold 2 failing: it is
    retried by name, and every figure of the CV dict (held-out, in-sample and training percentiles, each fold's
    parameters, objective and evaluations) equals the in-process loop's bit for bit, for both refits."""
    import logging

    from test_crossval import _problem, _without_wall_time

    from clothlab.config.schema import OptimizerConfig
    from clothlab.fit.crossval import cross_validate, fold_task

    runner, _ = cluster
    problem, truth = _problem(free=("warp.umax", "beta"), every=5)
    opt = OptimizerConfig(max_evals=60, starts=2, seed=3)
    real_map = runner.map
    for refit in ("local", "neutral"):
        markers = tmp_path / refit
        markers.mkdir()

        def map_flaky(fn, items, **kwargs):
            assert fn is fold_task
            return real_map(_flaky_fold, [(str(markers), fold) for fold in items], **kwargs)  # noqa: B023

        loop = cross_validate(problem, truth, k=4, seed=2, max_evals=40, refit=refit, optimizer=opt)
        runner.map = map_flaky
        try:
            with caplog.at_level(logging.WARNING, logger="clothlab"):
                there = cross_validate(problem, truth, k=4, seed=2, max_evals=40, refit=refit, optimizer=opt,
                                       runner=runner)
        finally:
            del runner.map
        assert (markers / "fold-1").exists()
        assert _without_wall_time(there) == _without_wall_time(loop)
    assert caplog.text.count("task fold 2/4 failed (RuntimeError: first attempt at fold 2); retrying it") == 2


@pytest.mark.slow
def test_batch_and_sweep_survive_a_killed_worker_and_match_the_sequential_run(tmp_path, cluster, caplog):
    import logging

    from clothlab.config import load_config
    from clothlab.fit.batch import plan_batch, run_batch
    from clothlab.studies import stability as check

    runner, pids = cluster
    configs = make_project(tmp_path / "seq", ("cotton-twill", "polyester-lining", "silk-charmeuse"))
    items, _ = plan_batch([load_config(c) for c in configs])
    sequential = run_batch(items, InProcessRunner())
    configs = make_project(tmp_path / "par", ("cotton-twill", "polyester-lining", "silk-charmeuse"))
    items, _ = plan_batch([load_config(c) for c in configs])
    killed = []

    def first(row):
        if not killed:
            killed.append(_kill_a_busy_worker(runner.client))

    with caplog.at_level(logging.WARNING, logger="clothlab"):
        parallel = run_batch(items, runner, on_row=first)
    assert killed and killed[0] is not None
    assert "KilledWorker" in caplog.text
    assert [r["status"] for r in parallel] == ["fitted"] * 3
    for a, b in zip(sequential, parallel, strict=True):
        assert a["name"] == b["name"] and a["params"] == b["params"]  # bit for bit
        fa = json.loads((tmp_path / "seq" / "fits" / a["name"] / "fit.json").read_text())
        fb = json.loads((tmp_path / "par" / "fits" / b["name"] / "fit.json").read_text())
        assert fa["coefficients"] == fb["coefficients"] and fa["errors"] == fb["errors"]
    assert not list((tmp_path / "par" / "fits").glob(".*"))  # no half-written temporary or lock left

    # a small sweep in chunks on the cluster, a worker killed after the first chunk: the sequential counts
    rng = np.random.default_rng(3)
    wi, wo = check.check_directions(16, rng)
    sets = check.random_parameter_sets(40, rng)
    rule = ("support", 8)
    whole = check.sweep_extremes(sets, wi, wo, rule)
    check.CHUNK_SETS, saved = 5, check.CHUNK_SETS
    try:
        real_map = runner.map

        def map_killing(fn, items, **kwargs):
            done = kwargs.pop("on_result")
            hit = []

            def on_result(i, value):
                if not hit:
                    hit.append(_kill_a_busy_worker(runner.client))
                done(i, value)

            return real_map(fn, items, on_result=on_result, **kwargs)

        runner.map = map_killing
        merged = check.sweep_chunked([("s", rule, "random", sets)], wi, wo, runner, tmp_path / "chunks")
    finally:
        check.CHUNK_SETS = saved
        del runner.map
    assert merged == {"s": {"random": whole}}
    assert not any(isinstance(r, TaskFailure) for r in parallel)


@pytest.mark.slow
def test_posterior_through_the_dask_pool_is_the_in_process_chain(cluster):
    from test_posterior import FAST, _problem

    from clothlab.fit.posterior import run_posterior

    runner, _ = cluster
    problem, truth = _problem()
    reference = run_posterior(problem, truth, seed=5, **FAST)
    pooled = run_posterior(problem, truth, seed=5, runner=runner, pool=True, **FAST)
    np.testing.assert_array_equal(pooled.chain, reference.chain)
    np.testing.assert_array_equal(pooled.log_prob, reference.log_prob)
    auto = run_posterior(problem, truth, seed=5, runner=runner, pool="auto", **FAST)
    np.testing.assert_array_equal(auto.chain, reference.chain)


@pytest.mark.slow
def test_model_selection_candidates_as_tasks_match_the_in_process_loop(tmp_path, cluster):
    """`clothlab select --workers 2`: one task per candidate; the ranking, every candidate's objective and
    orientation, and the winner's parameters equal the in-process loop's (issue 13 item 2)."""
    from dataclasses import replace

    from clothlab.config import apply_overrides, load_config
    from clothlab.fit.select import SelectSettings, select

    runner, _ = cluster
    example = Path(__file__).parent.parent / "measurements" / "scattered-twill" / "fabric.yaml"
    cfg = apply_overrides(load_config(example), max_evals=80)
    cfg = replace(cfg, fit=replace(cfg.fit, posterior=None, cv_folds=0))
    settings = SelectSettings(weaves=("preset:wool-gabardine", "preset:cotton-denim"), kinds=("irawan",),
                              orientation_starts=1, max_evals=60, cv_folds=0, losses=())
    here = select(cfg, settings, fits_dir=tmp_path / "a")
    there = select(cfg, settings, fits_dir=tmp_path / "b", runner=runner)
    assert [r.row["candidate"] for r in here.ranked] == [r.row["candidate"] for r in there.ranked]
    for a, b in zip(here.ranked, there.ranked, strict=True):
        assert a.row["objective"] == b.row["objective"] and a.params == b.params
    assert here.winner.params == there.winner.params


def test_surrogate_training_chunks_on_dask_are_the_in_process_files(tmp_path, cluster):
    """The surrogate's labelling chunks as Dask tasks (issue 13 item 4): byte-identical .npy files, whatever
    the number of workers or the order the chunks finish in."""
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.surrogate.data import DataSpec, generate
    from clothlab.surrogate.labels import ModelLabels
    from clothlab.weave.presets import get_preset

    runner, _ = cluster
    spec = DataSpec(centres=2, sizes=2, pairs=4)
    labels = [ModelLabels(IrawanModel(get_preset("silk-shantung")))]
    generate(tmp_path / "seq", spec, labels)
    assert generate(tmp_path / "dask", spec, labels, runner=runner) == spec.chunks_per_material()
    files = sorted((tmp_path / "seq").glob("chunk-*.npy"))
    assert files and all(f.read_bytes() == (tmp_path / "dask" / f.name).read_bytes() for f in files)
