"""Residual diagnostics (issue 28 item 4, clothlab.fit.residuals): a known missing term shows where it is."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.fit.residuals import diagnostics, features, summary_sentence

RNG = np.random.default_rng(5)
N = 600
TI, PI, TO, PO = RNG.uniform(0, 88, N), RNG.uniform(0, 360, N), RNG.uniform(0, 88, N), RNG.uniform(0, 360, N)


def test_features_by_hand():
    f = features([30.0, 0.0], [0.0, 0.0], [30.0, 40.0], [180.0, 90.0])
    # mirror of (30, 0) is (30, 180): specular distance 0, phase 60, half vector the normal
    assert f["specular"][0] == pytest.approx(0.0, abs=1e-6) and f["phase"][0] == pytest.approx(60.0)
    assert f["theta_h"][0] == pytest.approx(0.0, abs=1e-6)
    assert f["phase"][1] == pytest.approx(40.0) and f["theta_h"][1] == pytest.approx(20.0)


def test_a_missing_grazing_term_puts_the_tail_at_grazing_exitant_angles():
    """Truth = a smooth BRDF times (1 + 0.6 at theta_o > 75 deg), 2 % noise; the model lacks the grazing term:
    the 75-90 deg exitant bin is biased low (model too dark) and holds the p80 tail."""
    truth = 0.3 * (1.0 + 0.6 * (TO > 75.0))
    measured = truth * np.exp(0.02 * RNG.standard_normal(N))
    model = np.full(N, 0.3)
    d = diagnostics(TI, PI, TO, PO, measured, model)
    grazing = d["features"]["theta_o"]["bins"][-1]
    assert grazing["median_r"] == pytest.approx(1 / 1.6 - 1, abs=0.03)
    # every grazing row is in the tail (the top 20 %): enrichment at its maximum 1 / 0.2
    assert grazing["enrichment"] == pytest.approx(5.0, abs=0.3)
    assert all(b["enrichment"] < 1.0 for b in d["features"]["theta_o"]["bins"][:-1])  # below their share
    assert "exitant polar angle 75-90 deg" in summary_sentence(d)
    assert all(w["theta_o"] > 75.0 for w in d["worst"])


def test_pure_noise_has_no_concentrated_tail():
    measured = 0.3 * np.exp(0.05 * RNG.standard_normal(N))
    d = diagnostics(TI, PI, TO, PO, measured, np.full(N, 0.3))
    strong = [b for f in d["features"].values() for b in f["bins"] if b["n"] >= 40 and b["enrichment"] > 1.5]
    assert strong == []
