"""The global stage (clothlab.fit.optimize): space-filling start designs, spread starts, bound flags at 1e-3 of
the range, a multimodal objective solved where a local search from x0 is not, the enlarged-box check, and a
fit of the coefficients only (fit.free: [])."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

from clothlab.config import load_config
from clothlab.config.schema import OptimizerConfig
from clothlab.fit.optimize import bound_flags, design_points, multistart_minimize, spread_starts
from clothlab.fit.problem import FitProblem, build_problem

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("design", ["sobol", "lhs"])
def test_designs_stratify_every_coordinate_and_are_seeded(design):
    X = design_points(design, 3, 64, seed=5)
    assert X.shape == (64, 3) and (X >= 0).all() and (X < 1).all()
    for j in range(3):  # one point in each of the 64 cells [i/64, (i+1)/64) of every coordinate
        np.testing.assert_array_equal(np.sort(np.floor(64 * X[:, j])), np.arange(64))
    np.testing.assert_array_equal(X, design_points(design, 3, 64, seed=5))
    assert not np.array_equal(X, design_points(design, 3, 64, seed=6))


def test_spread_starts_best_first_and_apart():
    X = np.array([[0.0], [0.05], [0.5], [0.52], [0.9]])
    values = np.array([1.0, 0.5, 2.0, np.nan, 3.0])
    assert spread_starts(X, values, 3, separation=0.15) == [1, 2, 4]  # 0 is too close to 1, nan never taken


def test_bound_flags_relative_to_the_range():
    lower, upper = np.array([1.0, 0.0]), np.array([85.0, 1.0])
    lo, hi = bound_flags(np.array([84.998, 0.999]), lower, upper)  # 84.998 of 85; 99.9 % of a range
    assert hi.tolist() == [True, True] and not lo.any()
    lo, hi = bound_flags(np.array([84.9, 0.998]), lower, upper)
    assert not hi.any()
    assert bound_flags(np.array([1.0 + 0.08, 0.0]), lower, upper)[0].tolist() == [True, True]


class _Rastrigin:
    """A multimodal objective on the unit box (minimum 0 at x = 0.8 in each coordinate)."""

    free = ("a", "b")

    def __call__(self, x):
        z = 3.0 * (np.asarray(x) - 0.8)
        return float(np.sum(z * z - 3.0 * np.cos(2 * np.pi * z) + 3.0))


def test_design_starts_find_the_global_minimum_a_local_search_from_x0_misses():
    opt = OptimizerConfig(global_algorithm=None, local_algorithm="LN_BOBYQA", max_evals=2000, starts=2, polish=0,
                          design="sobol", box_check=False)
    x0 = np.array([0.1, 0.1])
    found = multistart_minimize(_Rastrigin(), x0, opt)
    alone = multistart_minimize(_Rastrigin(), x0, replace(opt, design="none"))
    assert found.fun < 1e-8 and np.allclose(found.x, 0.8, atol=1e-4)
    assert alone.fun > 1.0  # a local search from x0 stops in a side minimum
    assert found.nevals <= opt.max_evals and "sobol design" in found.message


def _small_problem(bounds):
    full = build_problem(load_config(ROOT / "measurements" / "polyester-lining" / "fabric-clean.yaml"))
    m = full.measurement.subset(np.arange(full.measurement.n)[::5])
    truth = {k: m.provenance["parameters"][k] for k in full.start}
    return FitProblem(full.model, m, ("warp.umax",), {**truth, "warp.umax": 12.0}, bounds, "relative"), truth


def test_box_check_reports_an_optimum_that_moves_and_one_that_stays():
    opt = OptimizerConfig(global_algorithm=None, max_evals=200, starts=1, polish=50)
    problem, truth = _small_problem({"warp.umax": (5.0, 18.0)})  # truth 22 lies outside
    result = multistart_minimize(problem, problem.to_unit(problem.start), opt)
    assert result.at_upper[0] and result.box_check["moved"]
    assert 18.0 < result.box_check["params"]["warp.umax"] <= 21.25 + 1e-9  # the enlarged upper bound
    assert result.box_check["bounds"]["warp.umax"] == pytest.approx([1.75, 21.25])
    assert "MOVES" in result.message
    problem, truth = _small_problem({"warp.umax": (5.0, 40.0)})
    result = multistart_minimize(problem, problem.to_unit(problem.start), opt)
    assert not result.box_check["moved"] and abs(problem.from_unit(result.x)["warp.umax"] - 22.0) < 1e-3
    off = multistart_minimize(problem, problem.to_unit(problem.start), replace(opt, box_check=False))
    assert off.box_check is None


def test_free_empty_fits_only_the_coefficients():
    from clothlab.fit.runner import run_fit

    cfg = load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml")
    cfg = replace(cfg, fit=replace(cfg.fit, free=(), bounds={}, posterior=None, cv_folds=0))
    result = run_fit(cfg)
    assert result.optimum.nevals == 1 and result.params == result.problem.start
    design, y = result.problem.design(result.params), result.problem.y
    for c in range(y.shape[1]):  # scipy's NNLS with weights 1 / y
        w = 1.0 / y[:, c]
        coef, _ = nnls(design * w[:, None], y[:, c] * w)
        np.testing.assert_allclose(result.solution.prediction[:, c], design @ coef, rtol=1e-8)


def test_valid_geometry_caps_the_default_bounds_at_the_segment_constraint():
    """cotton-twill weft (w = 2, l = 1): w sin(umax) < l (Irawan & Marschner 2012, sec. 5.3) holds for umax <
    asin(1/2) = 30 deg; with fit.valid_geometry the default upper bound 85 becomes 30 deg."""
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.simulate.gonio import simulate
    from clothlab.weave.presets import get_preset

    model = IrawanModel(get_preset("cotton-twill"))
    start = {**model.resolve({}), "weft.umax": 20.0}
    m = simulate(model, start, {"kd": np.ones(3), "ks_warp": np.ones(3), "ks_weft": np.ones(3)},
                 sampling=(np.array([30.0]), np.array([0.0]), np.array([30.0]), np.array([180.0])))
    capped = FitProblem(model, m, ("weft.umax", "warp.umax"), start, None, "relative", valid_geometry=True)
    plain = FitProblem(model, m, ("weft.umax", "warp.umax"), start, None, "relative")
    assert plain.upper.tolist() == [85.0, 85.0]
    assert capped.upper[0] == pytest.approx(30.0, abs=1e-9) and capped.upper[1] == 85.0  # warp: w 1, l 6
    assert not model.geometry_warnings({**start, "weft.umax": capped.upper[0]})
    assert model.geometry_warnings({**start, "weft.umax": capped.upper[0] + 1e-6})
    assert set(capped.geometry_caps) == {"weft.umax"}
    given = FitProblem(model, m, ("weft.umax",), start, {"weft.umax": (1.0, 60.0)}, "relative", valid_geometry=True)
    assert given.upper.tolist() == [60.0]  # bounds given explicitly are kept


def test_box_check_budget_follows_the_fit_budget():
    from clothlab.fit.optimize import BOX_CHECK_EVALS, BOX_CHECK_POINTS, box_check_budget

    assert box_check_budget(1500) == (BOX_CHECK_EVALS, BOX_CHECK_POINTS)  # the example fits' check unchanged
    for max_evals in (4, 10, 100, 600, 1000, 5000):
        evals, points = box_check_budget(max_evals)
        assert 1 <= evals <= min(BOX_CHECK_EVALS, max(1, max_evals // 5))
        assert 2 <= points <= BOX_CHECK_POINTS and points & (points - 1) == 0  # a power of 2 (Sobol)
        assert 2 * evals + points <= max(max_evals, 8)
