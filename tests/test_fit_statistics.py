"""lmfit's statistics block (issue 25 item 7) in fit_report() and on the report page: chi-square, reduced
chi-square, AIC, BIC, n and k, against an independent computation from the residuals (lmfit's definitions:
chisqr = sum r^2, redchi = chisqr / (n - k), AIC = n ln(chisqr / n) + 2 k, BIC = n ln(chisqr / n) + k ln n)."""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clothlab.config import load_config
from clothlab.fit.fitreport import statistics
from clothlab.fit.metrics import fit_statistics, information_criteria
from clothlab.fit.runner import run_fit
from clothlab.fit.store import fit_summary, load_fit

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "fits" / "polyester-lining"


def _lmfit_statistics(residuals: np.ndarray, k: int) -> dict:
    """The four figures as lmfit's MinimizerResult computes them, from the residual vector."""
    n = residuals.size
    chisqr = float(np.sum(residuals**2))
    neg2_log_likelihood = n * math.log(chisqr / n)
    return {"n": n, "k": k, "chi_square": chisqr, "reduced_chi_square": chisqr / (n - k),
            "aic": neg2_log_likelihood + 2 * k, "bic": neg2_log_likelihood + math.log(n) * k}


def _block(report: str, title: str) -> dict[str, str]:
    lines = report.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"[[{title}]]"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[[")), len(lines))
    return dict(re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in lines[start + 1:end])


def _assert_matches(stats: dict, expected: dict, rel: float) -> None:
    assert (stats["n"], stats["k"]) == (expected["n"], expected["k"])
    for key in ("chi_square", "reduced_chi_square"):
        assert stats[key] == pytest.approx(expected[key], rel=rel)
    for key in ("aic", "bic"):  # large negative numbers: compare to the figures' absolute precision
        assert stats[key] == pytest.approx(expected[key], abs=rel * expected["n"])


def test_shipped_fit_statistics_from_its_predictions_table():
    """The shipped polyester-lining fit (relative metric, 6 free parameters, 9 coefficients): the block agrees
    with relative residuals recomputed from predictions.csv (values written to 10 digits), in fit_report()
    and on the report page."""
    fit = json.loads((SHIPPED / "fit.json").read_text())
    with open(SHIPPED / "predictions.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    channels = fit["measurement"]["channels"]
    measured = np.array([[float(r[f"measured_{c}"]) for c in channels] for r in rows])
    model = np.array([[float(r[f"model_{c}"]) for c in channels] for r in rows])
    assert fit["metric"] == "relative" and measured.shape == (1575, 3)
    expected = _lmfit_statistics((model - measured) / measured, k=6 + 9)
    stats = statistics(fit)
    _assert_matches(stats, expected, rel=1e-6)

    block = _block(load_fit(SHIPPED).fit_report(), "Statistics")
    assert block["data points (n)"] == "4725"
    assert block["variables (k)"] == "15 (6 free parameters + 9 linear coefficients)"
    assert float(block["chi-square"]) == pytest.approx(expected["chi_square"], rel=1e-5)
    assert float(block["reduced chi-square"]) == pytest.approx(expected["reduced_chi_square"], rel=1e-5)
    assert float(block["Akaike info crit (AIC)"]) == pytest.approx(expected["aic"], abs=0.5)
    assert float(block["Bayesian info crit (BIC)"]) == pytest.approx(expected["bic"], abs=0.5)

    from clothlab.report.html import render_report_html

    page = render_report_html(fit, {}, {"errors": fit["errors"]})
    assert "<h2>Fit statistics</h2>" in page
    for label, value in (("chi-square", stats["chi_square"]), ("Bayesian info crit (BIC)", stats["bic"])):
        shown = re.search(rf"<b>{re.escape(label)}</b></td><td class=\"num\">([^<]+)<", page).group(1)
        assert float(shown) == pytest.approx(value, rel=1e-5)


def test_fresh_fit_statistics_under_the_cube_root_metric():
    """A fresh fit (cube-root metric, one free parameter): chi-square is the sum of squared cube-root residuals of
    the fit's own prediction, k = 1 + the coefficients, and the selection table's AIC / BIC are the same numbers."""
    cfg = load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml")
    cfg = replace(cfg, fit=replace(cfg.fit, free=("beta",), metric="cube-root", cv_folds=0, posterior=None,
                                   optimizer=replace(cfg.fit.optimizer, max_evals=40, starts=1, polish=10)))
    result = run_fit(cfg)
    y, model = result.problem.y, result.solution.prediction
    k = 1 + int(np.asarray(result.solution.coefficients).size)
    expected = _lmfit_statistics(np.cbrt(model) - np.cbrt(y), k)
    stats = statistics(fit_summary(result))
    _assert_matches(stats, expected, rel=1e-9)
    assert (stats["aic"], stats["bic"]) == information_criteria(float(result.optimum.fun), y.size, k)
    block = _block(result.fit_report(), "Statistics")
    assert block["variables (k)"].startswith(f"{k} (1 free parameters + {k - 1} linear coefficients)")


def test_degenerate_counts():
    """No more values than numbers estimated: no reduced chi-square; an exact fit: AIC and BIC -inf."""
    assert math.isnan(fit_statistics(0.5, 3, 3)["reduced_chi_square"])
    assert fit_statistics(0.0, 10, 2)["aic"] == -math.inf
    assert statistics({"parameters": {}, "measurement": {}}) is None
