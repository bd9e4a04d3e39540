"""Error figures and fit metrics (clothlab.fit.metrics)."""

import numpy as np
import pytest

from clothlab.errors import InputError
from clothlab.fit.metrics import (
    METRICS,
    error_percentiles,
    linear_weights,
    metric_residuals,
    objective_value,
    relative_errors,
)


def test_relative_errors_by_hand():
    measured = np.array([[1.0, 2.0], [4.0, 0.5]])
    model = np.array([[1.2, 1.0], [4.0, 1.0]])
    np.testing.assert_allclose(relative_errors(measured, model), [[0.2, 0.5], [0.0, 1.0]])


def test_relative_errors_undefined_entries_are_nan():
    errors = relative_errors([1.0, 0.0, -1.0, np.nan, 2.0], [1.5, 1.0, 1.0, 1.0, np.inf])
    assert errors[0] == pytest.approx(0.5)
    assert np.isnan(errors[1:]).all()


def test_error_percentiles_against_sorted_values():
    # 101 errors 0.00, 0.01, ..., 1.00 in channel 0; the p-th percentile is p/100 exactly.
    measured = np.ones((101, 2))
    model = np.stack([1.0 + np.linspace(0.0, 1.0, 101), np.full(101, 0.5)], axis=1)
    result = error_percentiles(measured, model, percentiles=(50, 80, 95), channels=("r", "g"))
    r = result["per_channel"]["r"]
    assert (r["p50"], r["p80"], r["p95"]) == pytest.approx((0.50, 0.80, 0.95))
    assert r["mean"] == pytest.approx(0.5) and r["n"] == 101
    assert result["per_channel"]["g"]["p80"] == pytest.approx(0.5)
    pooled = np.concatenate([np.linspace(0.0, 1.0, 101), np.full(101, 0.5)])
    assert result["overall"]["p80"] == pytest.approx(np.percentile(pooled, 80))
    assert result["overall"]["n"] == 202


def test_error_percentiles_skip_undefined_and_default_names():
    measured = np.array([1.0, 1.0, 0.0, 1.0])
    model = np.array([1.1, 1.3, 5.0, 1.2])
    result = error_percentiles(measured, model, percentiles=(50,))
    assert list(result["per_channel"]) == ["c0"]
    assert result["overall"]["n"] == 3
    assert result["overall"]["p50"] == pytest.approx(0.2)


def test_error_percentiles_all_undefined_gives_nan_without_warning():
    result = error_percentiles(np.zeros((3, 1)), np.ones((3, 1)))
    assert result["overall"]["n"] == 0 and np.isnan(result["overall"]["p50"])


def test_error_percentiles_channel_name_count_checked():
    with pytest.raises(ValueError, match="channel"):
        error_percentiles(np.ones((3, 2)), np.ones((3, 2)), channels=("r",))


def test_metric_residuals_by_hand():
    measured = np.array([[1.0], [8.0]])
    model = np.array([[2.0], [1.0]])
    np.testing.assert_allclose(metric_residuals(measured, model, "relative"), [[1.0], [-0.875]])
    np.testing.assert_allclose(metric_residuals(measured, model, "log"), [[np.log(2.0)], [np.log(1 / 8)]])
    np.testing.assert_allclose(metric_residuals(measured, model, "cube-root"), [[2 ** (1 / 3) - 1], [-1.0]])


def test_log_metric_stays_finite_at_zero_model():
    r = metric_residuals(np.array([1.0, 2.0]), np.array([0.0, 2.0]), "log")
    assert np.isfinite(r).all() and r[0] < -10 and r[1] == 0.0


def test_metrics_reject_non_positive_measured_but_cube_root_accepts():
    measured = np.array([1.0, 0.0, 2.0])
    for metric in ("relative", "log"):
        with pytest.raises(ValueError, match=r"index \(1,\): 0\.0"):
            metric_residuals(measured, np.ones(3), metric)
        with pytest.raises(InputError, match="cube-root"):  # user-facing: one line from the CLI
            metric_residuals(measured, np.ones(3), metric)
        with pytest.raises(ValueError):
            linear_weights(measured, metric)
    assert np.isfinite(metric_residuals(measured, np.ones(3), "cube-root")).all()
    assert np.isfinite(linear_weights(measured, "cube-root")).all()


def test_unknown_metric_and_shape_mismatch():
    with pytest.raises(ValueError, match="relative"):
        metric_residuals(np.ones(2), np.ones(2), "L2")
    with pytest.raises(ValueError, match="shape"):
        metric_residuals(np.ones(2), np.ones(3), "relative")


def test_objective_value_is_mean_square():
    assert objective_value(np.array([[1.0, -2.0], [3.0, 0.0]])) == pytest.approx(14.0 / 4.0)


@pytest.mark.parametrize("metric", METRICS)
def test_linear_weights_are_the_first_order_metric(metric):
    """w * (model - measured) matches the metric residual for a small perturbation of the data."""
    rng = np.random.default_rng(1)
    measured = rng.uniform(0.05, 3.0, size=(50, 3))
    delta = 1e-6 * measured * rng.normal(size=measured.shape)
    residual = metric_residuals(measured, measured + delta, metric)
    linearised = linear_weights(measured, metric) * delta
    np.testing.assert_allclose(linearised, residual, rtol=1e-5)


def test_a_single_zero_value_is_named_by_file_channel_and_row():
    """A fit with the relative metric and one zero measured value: the message names the measurement file,
    the channel and the row with its angles (issue 11: was a placeless "first at index (0, 0)")."""
    from clothlab.errors import InputError
    from clothlab.fit.metrics import check_measurement_for_metric
    from clothlab.io.measurement import Measurement

    values = np.full((3, 2), 0.2)
    values[1, 1] = 0.0
    m = Measurement(theta_i=np.array([10.0, 20.0, 30.0]), phi_i=np.zeros(3), theta_o=np.array([5.0, 15.0, 25.0]),
                    phi_o=np.full(3, 180.0), values=values, channels=("grey", "nir"), source="/data/t.csv")
    check_measurement_for_metric(m, "cube-root")  # zeros are fine there
    with pytest.raises(InputError) as info:
        check_measurement_for_metric(m, "relative")
    text = str(info.value)
    assert text.startswith("/data/t.csv, field 'nir':") and "data row 2" in text and "theta_i 20" in text
