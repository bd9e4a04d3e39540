"""The fit report (lmfit-style): Gauss-Newton standard errors against the shipped emcee posteriors, the report's
content against the fit it describes, the same report from a saved fit directory, the short repr and the HTML,
and the progress lines of a fit (stage, start k/K, the yaml's budget)."""

from __future__ import annotations

import io
import json
import logging
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clothlab.config import PosteriorConfig, load_config
from clothlab.fit.fitreport import correlations, unit_text
from clothlab.fit.problem import build_problem
from clothlab.fit.runner import run_fit, save_fit
from clothlab.fit.store import load_fit
from clothlab.fit.uncertainty import gauss_newton

ROOT = Path(__file__).resolve().parents[1]
MEASUREMENTS, FITS = ROOT / "measurements", ROOT / "fits"


def _config(fabric="polyester-lining", *, free=None, bounds=None, cv=0, posterior=None, max_evals=300, starts=1,
            polish=60, fits=None):
    cfg = load_config(MEASUREMENTS / fabric / "fabric.yaml")
    fit = replace(cfg.fit, cv_folds=cv, posterior=posterior,
                  optimizer=replace(cfg.fit.optimizer, max_evals=max_evals, starts=starts, polish=polish))
    if free is not None:
        fit = replace(fit, free=tuple(free), bounds=bounds or {})
    cfg = replace(cfg, fit=fit)
    if fits is not None:
        cfg = replace(cfg, output=replace(cfg.output, fits=fits))
    return cfg


def _block(report: str, title: str) -> list[str]:
    lines = report.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"[[{title}]]"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[[")), len(lines))
    return lines[start + 1:end]


def _table(report: str, title: str) -> list[list[str]]:
    """The rows of one [[title]] block without a header, split on runs of two or more spaces."""
    return [re.split(r"\s{2,}", line.strip()) for line in _block(report, title)]


def _columns(report: str, title: str) -> dict[str, dict[str, str]]:
    """A [[title]] block with a header row: first cell -> {column: cell}, cut at the header's column starts
    (cells may be empty)."""
    header, *rows = _block(report, title)
    starts = [(m.start(), m.group()) for m in re.finditer(r"\S+(?: \S+)*", header)]
    out = {}
    for row in rows:
        cells = {name: row[a:b].strip() for (a, name), (b, _) in zip(starts, starts[1:] + [(len(row) + 1, "")],
                                                                      strict=True)}
        out[cells[starts[0][1]]] = cells
    return out


@pytest.mark.parametrize("fabric", ["polyester-lining", "silk-charmeuse"])
def test_gauss_newton_agrees_with_the_shipped_posterior(fabric):
    """At the shipped optimum, the Gauss-Newton standard errors and correlations match the emcee posterior of
    the same fit (posterior.json: a 4,000-step chain, independent of the linearisation) on these smooth,
    well-determined problems: standard error within 10 % of the 68 % half-width, correlations within 0.1."""
    fit = json.loads((FITS / fabric / "fit.json").read_text())
    post = json.loads((FITS / fabric / "posterior.json").read_text())
    problem = build_problem(load_config(MEASUREMENTS / fabric / "fabric.yaml"))
    gn = gauss_newton(problem, {name: entry["value"] for name, entry in fit["parameters"].items()})
    assert gn["method"] == "gauss-newton" and gn["names"] == list(problem.free)
    for name in problem.free:
        q = post["parameters"][name]
        assert gn["stderr"][name] == pytest.approx(0.5 * (q["p84"] - q["p16"]), rel=0.10), name
    order = [post["correlation"]["names"].index(n) for n in gn["names"]]
    expected = np.array(post["correlation"]["matrix"])[np.ix_(order, order)]
    np.testing.assert_allclose(np.array(gn["correlation"]["matrix"]), expected, atol=0.1)


def test_gauss_newton_standard_errors_shrink_with_repeated_data():
    """Every row measured twice: the same residuals twice over, so J^T J doubles and s^2 = sum r^2 / (n - p)
    becomes 2 sum r^2 / (2n - p): each standard error scales by sqrt((n - p) / (2n - p)), about 1 / sqrt(2)."""
    from clothlab.fit.problem import FitProblem

    problem = build_problem(_config("silk-charmeuse", free=("warp.umax", "beta")))
    truth = {k: problem.measurement.provenance["parameters"][k] for k in problem.start}
    m = problem.measurement
    twice = m.subset(np.concatenate([np.arange(m.n), np.arange(m.n)]))
    bounds = dict(zip(problem.free, zip(problem.lower, problem.upper, strict=True), strict=True))
    base = gauss_newton(problem, truth)  # all of truth: the fixed parameters too, not the problem's start
    doubled = gauss_newton(FitProblem(problem.model, twice, problem.free, truth, bounds, problem.metric), truth)
    n, p = problem.y.size, len(problem.free) + 3 * problem.y.shape[1]
    assert base["dof"] == n - p and doubled["dof"] == 2 * n - p
    for name in problem.free:
        assert doubled["stderr"][name] / base["stderr"][name] == pytest.approx(np.sqrt((n - p) / (2 * n - p)),
                                                                               rel=1e-6)
    np.testing.assert_allclose(doubled["correlation"]["matrix"], base["correlation"]["matrix"], atol=1e-9)


def test_report_describes_the_fit(tmp_path):
    result = run_fit(_config(cv=2, fits=tmp_path))
    report = result.fit_report()
    params = _columns(report, "Parameters")
    specs = result.problem.model.params
    assert set(params) == set(result.params)
    for name, row in params.items():
        assert row["value"] == f"{result.params[name]:.6g}"
        assert row["unit"] == unit_text(specs[name].unit)
        if name in result.problem.free:
            assert float(row["std. error"]) == pytest.approx(result.uncertainty["stderr"][name], rel=5e-3)
            assert row["bounds"] == f"[{specs[name].bounds[0]:.6g}, {specs[name].bounds[1]:.6g}]"
        else:
            assert row["note"] == "fixed" and row["std. error"] == ""
    assert "1" not in [row["unit"] for row in params.values()]  # dimensionless values carry no unit
    assert params["warp.umax"]["unit"] == "deg" and params["alpha"]["unit"] == ""
    assert "standard error from the Gauss-Newton approximation" in report
    coef = _columns(report, "Coefficients")
    channels = result.problem.measurement.channels
    assert set(coef) == set(result.coefficients) and list(coef["kd"])[1:] == list(channels)
    for name, row in coef.items():
        np.testing.assert_allclose([float(row[c]) for c in channels], result.coefficients[name], rtol=1e-4)
    errors = {row[0]: row for row in _table(report, "Errors")}
    assert errors["in-sample"][1] == f"{100 * result.errors['overall']['p50']:.2f} %"
    held = errors["cross-validated (2-fold, held out)"]
    assert held[1:4] == [f"{100 * result.cross_validation['held_out'][k]:.2f} %" for k in ("p50", "p80", "p95")]
    times = dict(row for row in _table(report, "Time"))
    assert times["optimisation"] == f"{result.timings['optimisation_s']:.1f} s"
    assert times["cross-validation"] == f"{result.timings['cross_validation_s']:.1f} s"
    assert times["total"] == f"{result.wall_time:.1f} s" and "posterior" not in times
    line = repr(result)
    assert "\n" not in line and len(line) < 200
    assert line.startswith("<FitResult polyester-lining: irawan, 6 free")
    assert f"{100 * result.errors['overall']['p50']:.2f} %" in line
    page = result._repr_html_()
    assert page.count("<table>") >= 5 and "<th>95th</th>" in page and "-&gt;" in page
    # read back from the fit directory: the same report
    saved = load_fit(save_fit(result))
    assert saved.fit_report() == report
    assert saved._repr_html_() == page
    assert repr(saved) == line.replace("<FitResult", "<SavedFit")


def test_report_flags_a_parameter_at_its_bound_and_lists_correlations():
    """warp.umax boxed in below its generating value (22 deg) ends at the upper bound: flagged in the table and
    in the notes.  The correlations listed are exactly the pairs above the threshold."""
    result = run_fit(_config(free=("warp.umax", "warp.kappa", "alpha", "beta"),
                             bounds={"warp.umax": (5.0, 15.0)}))
    report = result.fit_report(correl_threshold=0.0)
    params = _columns(report, "Parameters")
    assert params["warp.umax"]["note"].startswith("AT UPPER BOUND")
    assert "warp.umax ended at its upper bound" in report
    for i, name in enumerate(result.problem.free):  # every flag is the optimiser's, none other
        flag = "AT LOWER BOUND" if result.optimum.at_lower[i] else "AT UPPER BOUND" if result.optimum.at_upper[i] \
            else None
        assert (flag is None and "BOUND" not in params[name]["note"]) or params[name]["note"].startswith(flag)
    matrix = np.array(result.uncertainty["correlation"]["matrix"])
    names = result.uncertainty["names"]
    for threshold in (0.0, 0.3, 0.6, 0.9):
        listed = {tuple(row[0][2:-1].split(", ")): float(row[1])
                  for row in _table(result.fit_report(correl_threshold=threshold), "Correlations")
                  if row[0].startswith("C(")}
        expected = {(names[i], names[j]): matrix[i, j] for i in range(len(names)) for j in range(i + 1, len(names))
                    if abs(matrix[i, j]) > threshold}
        assert set(listed) == set(expected)
        for pair, r in listed.items():
            assert r == pytest.approx(expected[pair], abs=5e-4)


def test_report_with_a_posterior_reads_the_same_after_saving(tmp_path):
    cfg = _config(free=("warp.umax", "beta"), fits=tmp_path, posterior=PosteriorConfig(walkers=8, steps=40,
                                                                                       max_steps=40))
    result = run_fit(cfg)
    report = result.fit_report()
    assert "posterior median and 95 % interval (emcee, 8 walkers x 40 steps" in report
    q = result.posterior.percentiles()
    params = _columns(report, "Parameters")
    for name in ("warp.umax", "beta"):
        assert float(params[name]["median"]) == pytest.approx(q[name]["median"], rel=1e-5)
        assert params[name]["95 % interval"] == f"[{q[name]['p2.5']:.6g}, {q[name]['p97.5']:.6g}]"
    source, pairs = correlations(*result._report_sources(), threshold=-1.0)
    corr = result.posterior.correlation()
    assert source == "posterior" and pairs == [("warp.umax", "beta", pytest.approx(corr[0, 1]))]
    assert "posterior" in dict(row for row in _table(report, "Time"))
    saved = load_fit(save_fit(result))
    assert saved.posterior is not None and saved.fit_report() == report


def test_saved_fit_without_recorded_uncertainty_says_so(tmp_path):
    """A fit directory written before standard errors were recorded (no "uncertainty" in fit.json, no
    posterior) still reports, and says that no uncertainty was recorded."""
    fit = json.loads((FITS / "polyester-lining-kang" / "fit.json").read_text())
    fit.pop("uncertainty", None)
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    report = load_fit(tmp_path).fit_report()
    assert "uncertainty: none recorded" in report
    assert fit["name"] in report.splitlines()[0]


@pytest.fixture
def progress_stream():
    """clothlab.progress configured to write plain lines into a buffer; the logging state restored after."""
    import clothlab.progress as progress

    logger = logging.getLogger("clothlab")
    saved = (list(logger.handlers), logger.level, logger.propagate, dict(progress._settings))
    stream = io.StringIO()
    progress.configure(0, stream=stream)
    yield stream
    logger.handlers[:] = saved[0]
    logger.setLevel(saved[1])
    logger.propagate = saved[2]
    progress._settings.update(saved[3])


def test_progress_shows_stage_start_and_the_yaml_budget(progress_stream):
    """Not on a terminal: one plain line per stage when it ends, naming the start k/K, the stage, and the
    evaluations against the yaml's budget (max_evals split over the starts; the polish its own budget)."""
    cfg = _config(max_evals=240, starts=2, polish=50, cv=2)  # the design-free scheme: max_evals split evenly
    cfg = replace(cfg, fit=replace(cfg.fit, cv_refit="local",
                                   optimizer=replace(cfg.fit.optimizer, design="none", box_check=False)))
    result = run_fit(cfg)
    assert "\r" not in progress_stream.getvalue()
    lines = progress_stream.getvalue().splitlines()
    assert all("/120 eval" in line for line in lines if line.startswith("start "))
    lines = [line for line in lines if line.endswith("- done")]  # each stage's last line (a slow one has more)
    starts = [line for line in lines if line.startswith("start ")]
    assert [line.split(",")[0] for line in starts] == ["start 1/2", "start 2/2"]
    polish = [line for line in lines if line.startswith("polish:")]
    assert len(polish) == 1 and "/50 eval" in polish[0]
    used = int(polish[0].split(": ")[1].split("/")[0])
    assert used == sum(1 for row in result.optimum.trace if row.stage == "polish")
    assert [line.split(":")[0] for line in lines if line.startswith("cross-validation")] == \
        ["cross-validation fold 1/2", "cross-validation fold 2/2"]
