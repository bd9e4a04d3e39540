"""The execution layer without a cluster: the light import, the missing-extra error, the Runner's order, retry
and failure reports, batch planning (skip done, refuse another configuration), chunked sweeps equal to the
sequential sweep, and the posterior's pool giving the in-process chain bit for bit.  The LocalCluster runs are
in tests/test_parallel_cluster.py."""

from __future__ import annotations

import json
import logging
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clothlab.cli import main
from clothlab.errors import ClothlabError, ResultExistsError
from clothlab.parallel import DASK_EXTRA, InProcessRunner, TaskFailure, make_runner, raise_failures

ROOT = Path(__file__).resolve().parents[1]


def make_project(root: Path, fabrics=("polyester-lining", "silk-charmeuse"), max_evals=40) -> list[Path]:
    """measurements/<fabric>/fabric.yaml copies of the examples with a tiny budget (no CV, no posterior)
    writing to root/fits; returns the yaml paths."""
    out = []
    for fabric in fabrics:
        d = root / "measurements" / fabric
        d.mkdir(parents=True)
        shutil.copy(ROOT / "measurements" / fabric / "noisy.csv", d / "noisy.csv")
        text = (ROOT / "measurements" / fabric / "fabric.yaml").read_text()
        text, n = re.subn(r"max_evals: \d+, starts: \d+", f"max_evals: {max_evals}, starts: 1, polish: 0", text)
        assert n == 1
        text = "\n".join(line for line in text.splitlines() if not line.startswith(("  cv_folds:", "  posterior:")))
        text = re.sub(r"output: \{.*\}", "output: {fits: ../../fits, reports: ../../reports}", text)
        (d / "fabric.yaml").write_text(text)
        out.append(d / "fabric.yaml")
    return out


def test_import_and_help_import_no_dask():
    code = ("import sys, clothlab, clothlab.cli, clothlab.parallel; from clothlab.cli.main import build_parser; "
            "build_parser(); print([m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    code = ("import sys, contextlib, io\nfrom clothlab.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
            "print([m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_without_the_extra_workers_exits_2_with_one_line(tmp_path):
    """Dask made unimportable: ``--workers 2`` stops with exit 2 and one line naming the extra."""
    configs = make_project(tmp_path)
    code = ("import sys\nsys.modules['distributed'] = None\nsys.modules['dask'] = None\n"
            "from clothlab.cli import main\nsys.exit(main(sys.argv[1:]))")
    for argv in (["check", "--workers", "2"], ["fit", *map(str, configs), "--workers", "2"],
                 ["fit", str(configs[0]), "--cv", "2", "--workers", "2"]):
        out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120)
        assert out.returncode == 2, out.stderr
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("clothlab: error:") and DASK_EXTRA in lines[0], out.stderr
    assert not (tmp_path / "fits").exists()  # nothing ran


def test_option_mistakes_are_one_line_errors(monkeypatch):
    with pytest.raises(ClothlabError, match="not both"):
        make_runner(workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ClothlabError, match="at least 1"):
        make_runner(workers=0)
    assert isinstance(make_runner(environ={}), InProcessRunner)


def test_an_unreachable_scheduler_is_a_one_line_error_naming_it(monkeypatch):
    pytest.importorskip("distributed")
    import socket

    import clothlab.parallel.runner as runner

    with socket.socket() as s:  # a loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(ClothlabError, match=f"cannot reach the Dask scheduler at tcp://127.0.0.1:{port}"):
        make_runner(scheduler=f"tcp://127.0.0.1:{port}")


def _flaky(state_dir, x):
    """Fails the first time it sees ``x`` (a marker file remembers), then returns x * x; x = 3 always fails."""
    if x == 3:
        raise ValueError("three is never fine")
    marker = Path(state_dir) / f"seen-{x}"
    if x % 2 == 0 and not marker.exists():
        marker.touch()
        raise RuntimeError(f"first attempt at {x}")
    return x * x


def test_runner_keeps_order_retries_once_and_reports_failures(tmp_path, caplog):
    seen = []
    with caplog.at_level(logging.WARNING, logger="clothlab"):
        out = InProcessRunner().map(_flaky, range(5), shared=str(tmp_path), names=[f"t{i}" for i in range(5)],
                                    on_result=lambda i, v: seen.append(i))
    assert out[:3] == [0, 1, 4] and out[4] == 16
    assert isinstance(out[3], TaskFailure) and out[3].name == "t3" and out[3].attempts == 2
    assert "three is never fine" in out[3].error and "ValueError" in out[3].traceback
    assert sorted(seen) == [0, 1, 2, 3, 4]
    log = caplog.text
    assert "task t0 failed (RuntimeError: first attempt at 0); retrying it" in log
    assert "task t3 failed 2 times, giving up" in log and "task t1 failed" not in log
    with pytest.raises(ClothlabError, match="1 of 5 squares failed; first: t3: ValueError"):
        raise_failures(out, "squares")


def test_runner_lets_an_interrupt_through():
    def stop(i, value):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        InProcessRunner().map(abs, [1, 2, 3], on_result=stop)


# ------------------------------------------------------------------------------------------------- batch fits
def test_batch_plans_skips_done_and_refuses_another_configuration(tmp_path, capsys):
    from clothlab.config import apply_overrides, load_config
    from clothlab.fit.batch import expand_config_paths, plan_batch

    configs = make_project(tmp_path)
    assert expand_config_paths([tmp_path / "measurements"]) == sorted(configs)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ClothlabError, match="no fabric.yaml"):
        expand_config_paths([tmp_path / "empty"])
    assert main(["fit", str(tmp_path / "measurements"), "-q"]) == 0
    out = capsys.readouterr().out
    assert "2 fits: 2 fitted, 0 already done, 0 failed" in out
    saved = {c: json.loads((tmp_path / "fits" / c.parent.name / "fit.json").read_text()) for c in configs}
    # rerun: both done (same configuration hash), nothing rewritten
    assert main(["fit", *map(str, configs), "-q"]) == 0
    assert "2 fits: 0 fitted, 2 already done, 0 failed" in capsys.readouterr().out
    for c in configs:
        assert json.loads((tmp_path / "fits" / c.parent.name / "fit.json").read_text()) == saved[c]
    # another seed is another configuration: refused before any work without --force
    cfgs = [apply_overrides(load_config(c), seed=9) for c in configs]
    with pytest.raises(ResultExistsError, match="another configuration"):
        plan_batch(cfgs)
    items, skipped = plan_batch(cfgs, force=True)
    assert [i.name for i in items] == ["polyester-lining", "silk-charmeuse"] and skipped == []


def test_batch_reports_a_failed_fit_and_keeps_the_others(tmp_path, capsys, monkeypatch):
    import clothlab.fit.batch as batch

    configs = make_project(tmp_path)
    real = batch.fit_task

    def failing(item):
        if item.name == "silk-charmeuse":
            raise RuntimeError("simulated crash")
        return real(item)

    monkeypatch.setattr(batch, "fit_task", failing)
    assert main(["fit", *map(str, configs), "-q"]) == 1  # a failed fit: exit 1
    captured = capsys.readouterr()
    assert re.search(r"silk-charmeuse\s+FAILED .*RuntimeError: simulated crash", captured.out)
    assert ("clothlab: warning: batch fits: task silk-charmeuse failed (RuntimeError: simulated crash); "
            "retrying it (attempt 2 of 2)") in captured.err
    assert (tmp_path / "fits" / "polyester-lining" / "fit.json").is_file()
    assert not (tmp_path / "fits" / "silk-charmeuse").exists()
    assert not list((tmp_path / "fits").glob(".*"))  # no temporary or lock left behind


def test_one_fit_starts_a_runner_for_its_cv_folds_only_when_it_has_some(tmp_path, monkeypatch):
    """`clothlab fit one.yaml --workers 2`: no cluster for a fit without CV folds or posterior; with `--cv 2`
    one, and the folds run on it as tasks."""
    pytest.importorskip("distributed")
    import clothlab.cli.options as options

    [config] = make_project(tmp_path, ("polyester-lining",))
    config.write_text(config.read_text().replace("  metric: relative\n", "  metric: relative\n  cv_refit: local\n"))
    made = []

    class Recording(InProcessRunner):
        def map(self, fn, items, **kwargs):
            made.append(kwargs.get("desc"))
            return super().map(fn, items, **kwargs)

    monkeypatch.setattr(options, "runner_of", lambda args: made.append("runner") or Recording())
    assert main(["fit", str(config), "--workers", "2", "-q"]) == 0
    assert made == []
    assert main(["fit", str(config), "--workers", "2", "--cv", "2", "--force", "-q"]) == 0
    assert made == ["runner", "cross-validation folds"]
    cv = json.loads((tmp_path / "fits" / "polyester-lining" / "fit.json").read_text())["cross_validation"]
    assert cv["k"] == 2 and cv["held_out"]["n"] > 0 and [f["fold"] for f in cv["folds"]] == [0, 1]


# ------------------------------------------------------------------------------------------------- sweeps
def test_chunked_sweep_equals_the_sequential_sweep_and_reuses_its_files(tmp_path, monkeypatch):
    from clothlab.studies import stability as check

    rng = np.random.default_rng(4)
    wi, wo = check.check_directions(12, rng)
    sets = check.grid_parameter_sets(fast=True)[:10] + check.random_parameter_sets(7, rng)
    rule = ("trapezoid", 11)
    whole = check.sweep_extremes(sets, wi, wo, rule)
    monkeypatch.setattr(check, "CHUNK_SETS", 4)
    merged = check.sweep_chunked([("t", rule, "all", sets)], wi, wo, InProcessRunner(), tmp_path)
    assert merged == {"t": {"all": whole}}
    files = sorted(tmp_path.glob("*.npz"))
    assert len(files) == 5  # ceil(17 / 4) chunk files

    class Refusing(InProcessRunner):
        def map(self, fn, items, **kwargs):
            assert list(items) == []  # every chunk is on disk: nothing to compute
            return []

    assert check.sweep_chunked([("t", rule, "all", sets)], wi, wo, Refusing(), tmp_path) == merged


def test_check_findings_do_not_depend_on_the_runner():
    """`clothlab check --workers N` path (chunks and continuity sweeps as tasks): the same findings as the
    in-process run (fast subset; the full sweep on a cluster is in tests/test_parallel_cluster.py, slow)."""
    from clothlab.studies.stability import run_check

    here = run_check(full=False, seed=1)
    tasks = run_check(full=False, seed=1, runner=InProcessRunner())
    here.pop("wall_time_s"), tasks.pop("wall_time_s")
    assert tasks == here and here["totals"]["configurations"] > 0


def test_merge_keeps_the_first_examples_in_order():
    from clothlab.studies.stability import merge_sweeps

    part = {"configurations": 3, "non_finite": 1, "negative": 0, "back_facing_nonzero": 0, "reciprocity": 0,
            "worst_reciprocity_rel": 0.5}
    a = {**part, "examples": [1, 2, 3]}
    b = {**part, "worst_reciprocity_rel": 0.7, "exceptions": 1, "examples": [4, 5, 6]}
    merged = merge_sweeps([a, b], max_examples=5)
    assert merged["examples"] == [1, 2, 3, 4, 5] and merged["worst_reciprocity_rel"] == 0.7
    assert merged["configurations"] == 6 and merged["exceptions"] == 1
    assert "exceptions" not in merge_sweeps([a, a])


# ------------------------------------------------------------------------------------------------- posterior
def test_posterior_through_the_pool_is_the_in_process_chain():
    from test_posterior import FAST, _problem

    from clothlab.fit.posterior import run_posterior

    problem, truth = _problem()
    reference = run_posterior(problem, truth, seed=5, **FAST)

    class Counting(InProcessRunner):
        workers = 3
        calls = 0

        def map(self, fn, items, **kwargs):
            items = list(items)
            Counting.calls += 1
            assert len(items) == 3  # one chunk per worker slot
            return super().map(fn, items, **kwargs)

    pooled = run_posterior(problem, truth, seed=5, runner=Counting(), pool=True, **FAST)
    assert Counting.calls == 2 * 60  # two ensemble halves per step, all through the pool
    np.testing.assert_array_equal(pooled.chain, reference.chain)
    np.testing.assert_array_equal(pooled.log_prob, reference.log_prob)
