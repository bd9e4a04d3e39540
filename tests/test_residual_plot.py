"""The report's residual plot (issue 28 item 4): one panel per residual feature, the p80 tail ringed."""

import numpy as np

from clothlab.fit.residuals import BINS
from clothlab.report.scatter_plots import plot_residuals


def test_one_panel_per_feature_and_the_tail_rows_ringed():
    rng = np.random.default_rng(4)
    n = 200
    measured = rng.uniform(0.1, 1.0, n)
    error = rng.normal(0.0, 0.1, n)
    predictions = {"theta_i": rng.uniform(0, 85, n), "phi_i": rng.uniform(0, 360, n),
                   "theta_o": rng.uniform(0, 85, n), "phi_o": rng.uniform(0, 360, n),
                   "measured_grey": measured, "model_grey": measured * (1 + error)}
    fig = plot_residuals(predictions)
    axes = fig.axes
    assert len(axes) == len(BINS)
    above = int(np.sum(np.abs(error) > np.percentile(np.abs(error), 80)))  # the tail, computed here
    for ax in axes:
        ringed = [line for line in ax.get_lines() if line.get_marker() == "o"]
        assert len(ringed) == 1 and len(ringed[0].get_xdata()) == above
