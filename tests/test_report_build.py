"""clothlab.report on synthetic fit directories (tests/test_report.py writes them from numpy only)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_report import CHANNELS, write_synthetic_fit_dir

from clothlab.errors import InputError, ResultExistsError
from clothlab.report import build as report_build
from clothlab.report.build import build_comparison, build_report
from clothlab.report.data import read_csv_table

PNG = b"\x89PNG\r\n\x1a\n"


def _independent_percentiles(fit_dir):
    table = read_csv_table(fit_dir / "predictions.csv")
    rel = np.concatenate([np.abs(table[f"model_{c}"] - table[f"measured_{c}"]) / table[f"measured_{c}"]
                          for c in CHANNELS])
    return {q: float(np.percentile(rel, q)) for q in (50, 80, 95)}


def test_report_page_figures_and_summary(tmp_path):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits")
    out = build_report(fit_dir, tmp_path / "reports")
    html = (out / "index.html").read_text()
    for word in ("warp.umax", "warp.kappa", "SIMULATED", "ks_warp"):
        assert word in html
    expected = _independent_percentiles(fit_dir)
    for q in (50, 80):
        assert f"{100 * expected[q]:.1f}" in html, q
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) >= 4
    for png in pngs:
        data = png.read_bytes()
        assert data[:8] == PNG and len(data) > 1000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["errors"]["overall"]["p50"] == pytest.approx(expected[50], rel=1e-9)
    assert "&lt;check&gt;" in html and "<check>" not in html  # warnings are escaped


def test_report_refuses_overwrite_and_force_replaces(tmp_path):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits")
    out = build_report(fit_dir, tmp_path / "reports")
    (out / "marker").write_text("old")
    with pytest.raises(ResultExistsError):
        build_report(fit_dir, tmp_path / "reports")
    assert (out / "marker").exists()
    build_report(fit_dir, tmp_path / "reports", force=True)
    assert not (out / "marker").exists() and (out / "index.html").is_file()


def test_failure_midway_leaves_nothing_half_written(tmp_path, monkeypatch):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits")

    def boom(*args, **kwargs):
        raise RuntimeError("plotting failed")

    monkeypatch.setattr(report_build.plots, "plot_fit_trace", boom)
    with pytest.raises(RuntimeError, match="plotting failed"):
        build_report(fit_dir, tmp_path / "reports")
    reports = tmp_path / "reports"
    assert not reports.exists() or not any(reports.iterdir())


def test_comparison_lists_every_fit_and_the_paper_figures(tmp_path):
    dirs = [write_synthetic_fit_dir(tmp_path / "fits", name=n, fabric=f, seed=i)
            for i, (n, f) in enumerate([("a-denim", "cotton-denim"), ("b-twill", "cotton-twill")])]
    out = build_comparison(dirs, tmp_path / "reports")
    html = (out / "index.html").read_text()
    assert "a-denim" in html and "b-twill" in html
    assert "18" in html and "34" in html  # the paper's denim median / 80th percentile (sec. 8)


def test_missing_or_corrupt_fit_json_is_named(tmp_path):
    fit_dir = write_synthetic_fit_dir(tmp_path / "fits")
    (fit_dir / "fit.json").write_text("{not json")
    with pytest.raises(InputError, match="fit.json"):
        build_report(fit_dir, tmp_path / "reports")
    (fit_dir / "fit.json").unlink()
    with pytest.raises(InputError, match="fit.json"):
        build_report(fit_dir, tmp_path / "reports")


# ---------------------------------------------------------------------------------------------------------
# figures drawn in two processes


def _figure_job(name, seed, log=None, fail=False):
    def build():
        import matplotlib.figure

        if log is not None:
            with open(log, "a") as f:
                f.write(f"{name} {__import__('os').getpid()}\n")
        if fail:
            raise ValueError(f"figure {name} cannot be drawn")
        fig = matplotlib.figure.Figure(figsize=(3, 2))
        ax = fig.add_subplot()
        ax.plot(np.random.default_rng(seed).random(50))
        ax.set_title(name)
        return fig
    return name, build


def _jobs(log=None, fail=()):
    names = ["hemispheres", "corner", "slices", "parameters", "trace", "error_histogram"]
    return [_figure_job(n, i, log, n in fail) for i, n in enumerate(names)]


def test_two_process_figures_are_the_one_process_figures(tmp_path):
    body = """
(root / "one").mkdir(); (root / "two").mkdir()
one = build.render_figures(_jobs(), root / "one", processes=1)
seen = []
two = build.render_figures(_jobs(root / "pids.txt"), root / "two", processes=2, meanwhile=seen.append)
result = {"one": one, "two": two, "seen": seen, "pid": os.getpid()}
"""
    out = _in_fresh_interpreter(tmp_path, body)
    assert out["one"] == out["two"] == {n: f"{n}.png" for n, _ in _jobs()} and out["seen"] == [out["two"]]
    for name in out["two"]:
        assert (tmp_path / "one" / f"{name}.png").read_bytes() == (tmp_path / "two" / f"{name}.png").read_bytes()
    pids = {line.split()[1] for line in (tmp_path / "pids.txt").read_text().splitlines()}
    assert len(pids) == 2 and str(out["pid"]) in pids  # half of them drawn by a child
    assert not out["left"]  # and no child is left behind


def _in_fresh_interpreter(tmp_path, body: str) -> dict:
    """Run ``body`` (which sets ``result``) in a new Python with this file's helpers: the fork needs a caller
    without other Python threads, and only a fresh process can tell that no child is left behind (earlier
    tests of this session may have left threads and children)."""
    import subprocess
    import sys

    code = f"""
import json, os, sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from pathlib import Path
from test_report_build import _jobs
from clothlab.report import build
root = Path({str(tmp_path)!r})
{body}
try:
    os.waitpid(-1, os.WNOHANG)
    result["left"] = True
except ChildProcessError:
    result["left"] = False
print(json.dumps(result))
"""
    return json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                     check=True).stdout)


@pytest.mark.parametrize("fail", ["hemispheres", "corner"])
def test_a_figure_that_fails_raises_here_whichever_process_drew_it(tmp_path, fail):
    body = f"""
result = {{}}
try:
    build.render_figures(_jobs(fail=({fail!r},)), root, processes=2)
except ValueError as exc:
    result["error"] = str(exc)
"""
    out = _in_fresh_interpreter(tmp_path, body)
    assert out["error"] == f"figure {fail} cannot be drawn" and not out["left"]


def test_with_another_python_thread_every_figure_is_drawn_here(tmp_path):
    import os
    import threading

    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        log = tmp_path / "pids.txt"
        report_build.render_figures(_jobs(log), tmp_path, processes=2)
    finally:
        stop.set()
        thread.join()
    assert {line.split()[1] for line in log.read_text().splitlines()} == {str(os.getpid())}


# ---------------------------------------------------------------------------------------------------------
# large fit directories: the vectorised CSV read and the exitant grouping


@pytest.mark.parametrize("bad", ["1_0", "1e", "+-1", "nan", "inf", "", "0x10", "1" * 5000, "\u0661", "1e400"])
def test_one_bad_cell_in_a_large_table_is_named_by_line_and_column(tmp_path, bad):
    from clothlab.report.data import read_csv_table

    rng = np.random.default_rng(4)
    values = rng.uniform(-1e3, 1e3, (5000, 3))
    lines = ["a,b,c"] + [",".join(repr(float(v)) for v in row) for row in values]
    good = tmp_path / "good.csv"
    good.write_text("\n".join(lines) + "\n")
    table = read_csv_table(good)
    for i, name in enumerate("abc"):
        np.testing.assert_array_equal(table[name], values[:, i])  # repr round-trips exactly
    lines[3001] = lines[3001].split(",")[0] + f",{bad}," + lines[3001].split(",")[2]
    broken = tmp_path / "broken.csv"
    broken.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as info:
        read_csv_table(broken)
    assert info.value.line == 3002 and info.value.field == "b" and str(broken) in str(info.value)


def test_exitant_groups_are_the_rows_of_each_direction():
    from clothlab.report.data import exitant_groups

    rng = np.random.default_rng(5)
    theta, phi = rng.choice([10.0, 30.0, 50.5], 400), rng.choice([0.0, 90.0, 180.0, 270.0], 400)
    groups = exitant_groups({"theta_o": theta, "phi_o": phi})
    assert [(t, p) for t, p, _ in groups] == sorted({(t, p) for t, p in zip(theta, phi, strict=True)})
    for t, p, rows in groups:
        np.testing.assert_array_equal(rows, np.flatnonzero((theta == t) & (phi == p)))
