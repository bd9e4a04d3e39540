"""The nlopt driver (clothlab.fit.optimize): recovery, robustness, reproducibility, bookkeeping."""

import math

import numpy as np
import pytest

from clothlab.fit.optimize import SUPPORTED_GLOBAL, SUPPORTED_LOCAL, TraceRow, minimize

SCALE = np.array([1e-2, 10.0])  # Rosenbrock coordinates of very different scale


def scaled_rosenbrock(x):
    u = x / SCALE
    return float((1.0 - u[0]) ** 2 + 100.0 * (u[1] - u[0] ** 2) ** 2)


ROSEN_BOUNDS = (SCALE * -2.0, SCALE * 2.0)


@pytest.mark.parametrize("global_algorithm", SUPPORTED_GLOBAL + (None,))
def test_scaled_rosenbrock_minimum_recovered(global_algorithm):
    result = minimize(scaled_rosenbrock, SCALE * np.array([-1.5, 1.5]), *ROSEN_BOUNDS,
                      global_algorithm=global_algorithm, max_evals=3000)
    np.testing.assert_allclose(result.x / SCALE, [1.0, 1.0], atol=1e-4)
    assert result.fun < 1e-8
    assert result.success and result.converged
    assert result.nevals <= 3000 and result.nevals == len(result.trace)
    assert not result.at_lower.any() and not result.at_upper.any()


@pytest.mark.parametrize("local_algorithm", SUPPORTED_LOCAL)
def test_every_local_algorithm_polishes(local_algorithm):
    result = minimize(scaled_rosenbrock, SCALE * np.array([0.5, 0.5]), *ROSEN_BOUNDS,
                      global_algorithm="GN_CRS2_LM", local_algorithm=local_algorithm, max_evals=4000)
    np.testing.assert_allclose(result.x / SCALE, [1.0, 1.0], atol=1e-3)
    assert result.algorithms["local"] == local_algorithm


def _two_lobe_problem():
    """A noisy two-lobe (6-parameter) fit in log coordinates for amplitudes and widths."""
    t = np.linspace(-1.0, 1.0, 200)

    def model(p):
        log_a1, m1, log_s1, log_a2, m2, log_s2 = p
        return (np.exp(log_a1) * np.exp(-0.5 * ((t - m1) / np.exp(log_s1)) ** 2)
                + np.exp(log_a2) * np.exp(-0.5 * ((t - m2) / np.exp(log_s2)) ** 2))

    truth = np.array([np.log(2.0), -0.4, np.log(0.15), np.log(0.7), 0.3, np.log(0.3)])
    rng = np.random.default_rng(11)
    data = model(truth) * (1.0 + 0.02 * rng.normal(size=t.size))
    lower = np.array([np.log(0.01), -1.0, np.log(0.02), np.log(0.01), 0.0, np.log(0.02)])
    upper = np.array([np.log(10.0), 0.0, np.log(1.0), np.log(10.0), 1.0, np.log(1.0)])
    return model, data, truth, lower, upper


def test_noisy_lobe_fit_reaches_the_least_squares_minimum():
    from scipy.optimize import least_squares

    model, data, truth, lower, upper = _two_lobe_problem()

    def objective(p):
        return float(np.mean(((model(p) - data) / data) ** 2))

    reference = least_squares(lambda p: (model(p) - data) / data, truth, bounds=(lower, upper),
                              xtol=1e-14, ftol=1e-14, gtol=1e-14)
    f_reference = objective(reference.x)
    x0 = 0.5 * (lower + upper)
    result = minimize(objective, x0, lower, upper, max_evals=4000, seed=2)
    assert result.fun <= f_reference * (1.0 + 1e-6)
    np.testing.assert_allclose(result.x, reference.x, atol=1e-3)
    np.testing.assert_allclose(result.x, truth, atol=0.05)  # and the noise is small: near the truth


def test_same_seed_reproduces_different_seed_differs():
    def run(seed):
        return minimize(scaled_rosenbrock, SCALE * np.array([-1.5, 1.5]), *ROSEN_BOUNDS,
                        global_algorithm="GN_CRS2_LM", max_evals=600, seed=seed)

    a, b, c = run(7), run(7), run(8)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.fun == b.fun and a.seed == 7
    values = [row.value for row in a.trace]
    assert values == [row.value for row in b.trace]
    assert [row.stage for row in a.trace] == [row.stage for row in b.trace]
    assert values != [row.value for row in c.trace]


def _nan_left_of(threshold, centre):
    def f(x):
        if x[0] < threshold:
            return math.nan
        return float(np.sum((x - centre) ** 2))
    return f


@pytest.mark.parametrize("local_algorithm", ["LN_BOBYQA", "LN_COBYLA"])
def test_nan_region_does_not_stop_at_x0(local_algorithm):
    centre = np.array([0.45, 0.3, 0.5])
    f = _nan_left_of(0.4, centre)
    # local only, from a finite start next to the NaN region
    result = minimize(f, [0.5, 0.9, 0.9], [0, 0, 0], [1, 1, 1], global_algorithm=None,
                      local_algorithm=local_algorithm, max_evals=2000)
    assert any(math.isnan(row.value) for row in result.trace)  # the NaN region was visited
    np.testing.assert_allclose(result.x, centre, atol=1e-5)
    # global + local, starting inside the NaN region
    result = minimize(f, [0.1, 0.1, 0.1], [0, 0, 0], [1, 1, 1], local_algorithm=local_algorithm,
                      max_evals=2000)
    np.testing.assert_allclose(result.x, centre, atol=1e-5)
    assert result.success


def test_no_finite_value_is_reported_not_hidden():
    result = minimize(lambda x: math.nan, [0.5], [0.0], [1.0], global_algorithm=None, max_evals=50)
    assert not result.success and not result.converged
    assert math.isnan(result.fun)
    assert "no finite objective value" in result.message


class Boom(Exception):
    pass


@pytest.mark.parametrize("global_algorithm", ["GN_CRS2_LM", "G_MLSL_LDS", None])
def test_exception_in_objective_is_re_raised_unchanged(global_algorithm):
    calls = []

    def f(x):
        calls.append(x)
        if len(calls) == 10:
            raise Boom("objective failed at evaluation 10")
        return float(np.sum(x ** 2))

    with pytest.raises(Boom, match="objective failed at evaluation 10"):
        minimize(f, [0.3, 0.4], [-1, -1], [1, 1], global_algorithm=global_algorithm, max_evals=500)
    assert len(calls) == 10  # stopped at once


def test_exception_in_callback_is_re_raised():
    def callback(row):
        if row.index == 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        minimize(lambda x: float(x @ x), [0.3], [-1], [1], callback=callback, max_evals=100)


def test_trace_best_so_far_is_monotone_and_callback_sees_every_row():
    rows = []
    result = minimize(scaled_rosenbrock, SCALE * np.array([-1.5, 1.5]), *ROSEN_BOUNDS,
                      max_evals=800, callback=rows.append)
    assert rows == result.trace and all(isinstance(r, TraceRow) for r in rows)
    table = result.trace_arrays()
    np.testing.assert_array_equal(table["index"], np.arange(1, result.nevals + 1))
    assert np.all(np.diff(table["best"]) <= 0)
    np.testing.assert_array_equal(table["best"], np.minimum.accumulate(table["value"]))
    assert np.all(np.diff(table["time"]) >= 0)
    stages = list(table["stage"])
    first_local = stages.index("local")
    assert set(stages[:first_local]) == {"global"} and set(stages[first_local:]) == {"local"}
    assert stages.count("global") == 480  # global_fraction 0.6 of 800
    assert result.fun == table["value"].min()


def test_best_point_kept_when_nlopt_fails(monkeypatch):
    """nlopt raising RoundoffLimited / an error after the search must not lose the best point."""
    import nlopt

    real_opt = nlopt.opt

    def flaky(error):
        class FlakyOpt(real_opt):
            def optimize(self, x0):
                super().optimize(x0)
                raise error

        return FlakyOpt

    for error, expected in [(nlopt.RoundoffLimited(), "ROUNDOFF_LIMITED"),
                            (RuntimeError("nlopt gave up"), "ERROR (RuntimeError: nlopt gave up)")]:
        monkeypatch.setattr(nlopt, "opt", flaky(error))
        result = minimize(scaled_rosenbrock, SCALE * np.array([-1.5, 1.5]), *ROSEN_BOUNDS, max_evals=1500)
        assert result.status["global"] == expected and result.status["local"] == expected
        assert result.fun == min(row.value for row in result.trace)
        assert scaled_rosenbrock(result.x) == result.fun
        np.testing.assert_allclose(result.x / SCALE, [1.0, 1.0], atol=1e-3)
        assert result.success == (expected == "ROUNDOFF_LIMITED")


def test_x_is_clipped_to_the_bounds():
    seen = []

    def f(x):
        seen.append(x.copy())
        return float(np.sum((x - 2.0) ** 2))

    minimize(f, [0.5, 0.5], [0, 0], [1, 1], max_evals=400)
    seen = np.array(seen)
    assert seen.min() >= 0.0 and seen.max() <= 1.0


def test_at_bound_flags_when_the_optimum_is_outside_the_box():
    centre = np.array([-3.0, 0.4, 5.0])
    result = minimize(lambda x: float(np.sum((x - centre) ** 2)), [0.5, 0.5, 0.5], [0, 0, 0], [1, 1, 1],
                      max_evals=1000)
    np.testing.assert_allclose(result.x, [0.0, 0.4, 1.0], atol=1e-6)
    np.testing.assert_array_equal(result.at_lower, [True, False, False])
    np.testing.assert_array_equal(result.at_upper, [False, False, True])


def test_x0_outside_bounds_names_the_coordinate():
    with pytest.raises(ValueError, match=r"coordinate 1: x0 = 2\.0"):
        minimize(lambda x: 0.0, [0.5, 2.0], [0, 0], [1, 1])


@pytest.mark.parametrize("kwargs, fragment", [
    ({"global_algorithm": "GN_MAGIC"}, "GN_CRS2_LM"),
    ({"local_algorithm": "LD_LBFGS"}, "LN_BOBYQA"),
    ({"global_algorithm": None, "local_algorithm": None}, "at least one"),
    ({"global_fraction": 1.5}, "global_fraction"),
])
def test_bad_settings_raise(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        minimize(lambda x: 0.0, [0.5], [0], [1], **kwargs)


def test_bad_bounds_raise():
    with pytest.raises(ValueError, match="coordinate 0"):
        minimize(lambda x: 0.0, [0.5], [1.0], [0.0])
    with pytest.raises(ValueError, match="finite"):
        minimize(lambda x: 0.0, [0.5], [-np.inf], [1.0])


def test_budget_split_and_max_time():
    result = minimize(scaled_rosenbrock, SCALE * np.array([-1.5, 1.5]), *ROSEN_BOUNDS,
                      max_evals=100, global_fraction=1.0)
    assert result.nevals == 100 and result.status["local"].startswith("SKIPPED")
    assert not result.converged and "budget" in result.message

    slow_calls = []

    def slow(x):
        slow_calls.append(1)
        import time
        time.sleep(0.002)
        return float(np.sum(x ** 2))

    result = minimize(slow, [0.5, 0.5], [-1, -1], [1, 1], max_evals=10**6, max_time=0.3)
    assert result.wall_time < 1.5 and result.success


def test_an_empty_box_is_evaluated_once_without_nlopt(monkeypatch):
    """Zero coordinates (a fit of the linear coefficients only): one evaluation, reported as converged, and
    nlopt is never asked (it rejects n = 0)."""
    import sys

    monkeypatch.setitem(sys.modules, "nlopt", None)  # importing nlopt now raises ImportError
    calls, rows = [], []
    result = minimize(lambda x: calls.append(x.shape) or 0.25, [], [], [], max_evals=500, seed=3,
                      callback=rows.append)
    assert calls == [(0,)] and result.nevals == 1 and result.fun == 0.25
    assert result.x.shape == (0,) and result.at_lower.shape == result.at_upper.shape == (0,)
    assert result.success and result.converged and result.seed == 3
    assert rows == result.trace and [r.stage for r in rows] == ["nnls"] and rows[0].best == 0.25
