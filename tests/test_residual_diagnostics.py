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


def test_the_half_vector_azimuth_by_hand():
    # (40, 30) -> (40, 30): h = wi, azimuth 30; (60, 0) -> (60, 180): h the normal (azimuth 0 by atan2(0, 0))
    f = features([40.0, 20.0], [30.0, 200.0], [40.0, 20.0], [30.0, 200.0])
    np.testing.assert_allclose(f["azimuth_h"], [30.0, 200.0], atol=1e-9)


def test_half_turn_pairs_of_a_tilted_lambertian_give_the_floor_of_its_cosines():
    """A Lambertian sample tilted by 3 deg toward +x, reduced with the nominal irradiance (clothlab.models.
    baselines.tilt, eq. 1): f = rho / pi cos(theta_i') / cos(theta_i).  In-plane rows (a, 0; b, 0) and their
    half-turned reciprocal (b, 180; a, 180) are found as pairs, and the floor |f1 - f2| / (f1 + f2) follows from
    the cosines computed here by hand (cos theta' = cos(theta -+ tau) in the plane of the tilt)."""
    from clothlab.fit.residuals import half_turn_pairs

    tau = 3.0
    polar = np.array([0.0, 11.25, 22.5, 33.75, 45.0, 56.25, 67.5, 78.75])
    a, b = np.meshgrid(polar, polar, indexing="ij")
    keep = a > b
    a, b = a[keep], b[keep]
    ti = np.concatenate([a, b])
    pi_ = np.concatenate([np.zeros_like(a), np.full_like(b, 180.0)])
    to = np.concatenate([b, a])
    po = pi_.copy()

    def lambert(theta_i, phi_i):  # the incident direction at azimuth 0 is tau closer to the tilted normal
        true = theta_i - tau * np.where(phi_i == 0.0, 1.0, -1.0) * (theta_i > 0)
        true = np.where(theta_i > 0, true, tau)
        return 0.3 / np.pi * np.cos(np.radians(true)) / np.cos(np.radians(theta_i))

    values = lambert(ti, pi_)
    out = half_turn_pairs(ti, pi_, to, po, values)
    assert out["pairs"] == len(a)
    f1, f2 = lambert(a, np.zeros_like(a)), lambert(b, np.full_like(b, 180.0))
    np.testing.assert_allclose(out["floor_median"], np.median(np.abs(f1 - f2) / (f1 + f2)), rtol=1e-12)
    # the darker rows are those lit from azimuth 180 (tilted away): their half vectors lean toward 180 deg
    assert abs(abs(out["darker_azimuth"]) - 180.0) < 1.0
    # an untilted (symmetric) table: every pair agrees, the floor is 0
    assert half_turn_pairs(ti, pi_, to, po, np.full(len(ti), 0.1))["floor_median"] == 0.0
