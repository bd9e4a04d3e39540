"""Colour calibration: chart reference values, correction recovery from a synthetic camera, exposure
invariance of the root-polynomial correction, CIEDE2000 against published test data, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.colour.chart import Correction, chart_reference, delta_e_2000, fit_correction
from clothlab.errors import InputError
from clothlab.io.measurement import Measurement

colour = pytest.importorskip("colour")

#: A camera's linear response: a known channel mixing (rows sum to 1: grey stays grey).
CAMERA = np.array([[0.70, 0.25, 0.05], [0.15, 0.75, 0.10], [0.05, 0.20, 0.75]])


def _camera(reference, exposure=1.0, noise=0.001, seed=0):
    rng = np.random.default_rng(seed)
    return exposure * reference @ CAMERA.T + rng.normal(0.0, noise, reference.shape)


def test_chart_reference_xyz_matches_xyY_by_hand():
    chart = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyY = np.array(list(chart.data.values()))
    x, y, Y = xyY.T
    by_hand = np.stack([x * Y / y, Y, (1 - x - y) * Y / y], axis=1)
    np.testing.assert_allclose(chart_reference(illuminant=None, space="XYZ"), by_hand, rtol=1e-12)
    # the chart's illuminant is D50 (to 4 digits): adapting to the named D50 changes almost nothing
    np.testing.assert_allclose(chart_reference(illuminant="D50", space="XYZ"), by_hand, rtol=1e-3)
    rgb = chart_reference()
    assert rgb.shape == (24, 3)
    # the neutral row (patches 19-24) stays neutral in D65 sRGB after Bradford adaptation from D50
    neutral = rgb[18:]
    assert np.all(np.ptp(neutral, axis=1) < 0.06 * neutral.mean(axis=1))
    assert np.all(np.diff(neutral.mean(axis=1)) < 0)  # white to black
    with pytest.raises(InputError, match="illuminant"):
        chart_reference(illuminant="D50")


def test_delta_e_2000_matches_sharma_test_data():
    # Sharma, Wu & Dalal (2005) CIEDE2000 test pairs 1, 7, 17: (Lab1, Lab2, dE00)
    pairs = [((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
             ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
             ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492)]
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint
    for lab_1, lab_2, expected in pairs:
        rgb = [colour.XYZ_to_RGB(colour.Lab_to_XYZ(lab, white), "sRGB", illuminant=white,
                                 chromatic_adaptation_transform=None) for lab in (lab_1, lab_2)]
        assert float(delta_e_2000(rgb[0], rgb[1])) == pytest.approx(expected, abs=1e-3)
    assert float(delta_e_2000([0.2, 0.3, 0.4], [0.2, 0.3, 0.4])) == 0.0


def test_3x3_correction_recovers_the_chart():
    reference = chart_reference()
    measured = _camera(reference, exposure=0.8)
    correction = fit_correction(measured, reference)
    assert correction.matrix.shape == (3, 3) and correction.is_linear
    # the fitted matrix undoes exposure x mixing
    np.testing.assert_allclose(correction.matrix, np.linalg.inv(0.8 * CAMERA), atol=0.02)
    after = delta_e_2000(correction.apply(measured), reference)
    assert after.mean() < 1.0
    summary = correction.summary
    assert summary["delta_e_2000_after"]["mean"] == pytest.approx(after.mean())
    assert summary["delta_e_2000_before"]["mean"] > 5.0 and summary["delta_e_2000_after"]["max"] == after.max()
    # an image is corrected pixel by pixel like the table
    image = measured.reshape(4, 6, 3)
    np.testing.assert_allclose(correction.apply(image), correction.apply(measured).reshape(4, 6, 3))


def test_root_polynomial_handles_an_exposure_change():
    reference = chart_reference()
    correction = fit_correction(_camera(reference), reference, "Finlayson 2015", degree=2)
    assert correction.matrix.shape == (3, 6)
    for exposure in (0.25, 0.5, 2.0):
        darker = _camera(reference, exposure=exposure, noise=0.0)
        # every root-polynomial term is homogeneous of degree 1: corrected(k x) = k corrected(x)
        np.testing.assert_allclose(correction.apply(darker), exposure * correction.apply(darker / exposure),
                                   rtol=1e-10, atol=1e-12)
        assert delta_e_2000(correction.apply(darker), exposure * reference).mean() < 1.0
    # a plain polynomial (not homogeneous) fitted at exposure 1 has no such property
    vandermonde = fit_correction(_camera(reference), reference, "Vandermonde", degree=2)
    brighter = _camera(reference, exposure=2.0, noise=0.0)
    assert not np.allclose(vandermonde.apply(brighter), 2.0 * vandermonde.apply(brighter / 2.0), rtol=1e-3)


def test_apply_to_measurement_propagates_sigma():
    reference = chart_reference()
    correction = fit_correction(_camera(reference), reference)
    values = np.array([[0.1, 0.2, 0.3], [0.5, 0.4, 0.2]])
    sigma = np.array([[0.01, 0.02, 0.01], [0.0, 0.01, 0.0]])
    m = Measurement(theta_i=np.array([10.0, 20.0]), phi_i=np.zeros(2), theta_o=np.zeros(2), phi_o=np.zeros(2),
                    values=values, channels=("R", "G", "B"), sigma=sigma)
    out = correction.apply_measurement(m)
    np.testing.assert_allclose(out.values, values @ correction.matrix.T)
    np.testing.assert_allclose(out.sigma, np.sqrt(sigma**2 @ (correction.matrix.T ** 2)))
    assert out.provenance["colour_correction"]["method"] == "Cheung 2004"
    root = fit_correction(_camera(reference), reference, "Finlayson 2015", degree=2)
    jac = root.jacobian(values)
    step = 1e-5
    numeric = (root.apply(values + [0, step, 0]) - root.apply(values - [0, step, 0])) / (2 * step)
    np.testing.assert_allclose(jac[..., 1], numeric, rtol=1e-4)


def test_bad_input_is_a_clear_error():
    reference = chart_reference()
    measured = _camera(reference)
    with pytest.raises(InputError, match=r"field 'measured'.*last axis of 3"):
        fit_correction(measured[:, :2], reference)
    with pytest.raises(InputError, match=r"field 'reference'.*\(24, 3\)"):
        fit_correction(measured, reference[:20])
    bad = measured.copy()
    bad[5, 1] = np.nan
    with pytest.raises(InputError, match=r"field 'measured'.*NaN.*index \(5,\)"):
        fit_correction(bad, reference)
    with pytest.raises(InputError, match="method 'Cheung2004'"):
        fit_correction(measured, reference, "Cheung2004")
    with pytest.raises(InputError, match="root-polynomial degree"):
        fit_correction(measured, reference, "Finlayson 2015", degree=7)
    with pytest.raises(InputError, match="under-determined"):
        fit_correction(measured[:5], reference[:5], "Vandermonde", degree=2)
    correction = fit_correction(measured, reference)
    assert isinstance(correction, Correction)
    with pytest.raises(InputError, match="last axis of 3"):
        correction.apply(np.ones((4, 4)))


def test_calibrate_chart_reads_the_file_and_scores_every_patch(tmp_path):
    import json

    from clothlab.colour.calibrate import calibrate_chart

    reference = chart_reference()
    measured = _camera(reference, exposure=0.9)
    chart = tmp_path / "chart.csv"
    chart.write_text("patch,R,G,B\n" + "".join(f"p{i},{r!r},{g!r},{b!r}\n" for i, (r, g, b) in enumerate(measured)))
    calibration = calibrate_chart(chart, method="Finlayson 2015", degree=2)
    np.testing.assert_array_equal(calibration.measured, measured)  # repr round trip of the file
    # the correction is the one fitted directly to the same values
    np.testing.assert_allclose(calibration.correction.matrix,
                               fit_correction(measured, reference, "Finlayson 2015", degree=2).matrix, rtol=1e-12)
    patches = calibration.patches()
    assert [p["patch"] for p in patches] == [f"p{i}" for i in range(24)]
    after = np.array([p["delta_e_after"] for p in patches])
    before = np.array([p["delta_e_before"] for p in patches])
    summary = calibration.correction.summary
    assert after.mean() == pytest.approx(summary["delta_e_2000_after"]["mean"], rel=1e-12)
    assert before.max() == pytest.approx(summary["delta_e_2000_before"]["max"], rel=1e-12)
    assert after.mean() < 1.0 < before.mean()
    document = json.loads(json.dumps(calibration.to_dict()))
    assert document["method"] == "Finlayson 2015" and len(document["patches"]) == 24
    short = tmp_path / "short.csv"
    short.write_text("R,G,B\n" + "".join(f"{r!r},{g!r},{b!r}\n" for r, g, b in measured[:20]))
    with pytest.raises(InputError, match="20 patches"):
        calibrate_chart(short)


def test_correct_measurement_raises_out_of_gamut_values_to_the_floor_and_warns(caplog):
    from clothlab.colour.calibrate import FLOOR, correct_measurement

    correction = Correction(matrix=np.array([[1.2, -0.3, 0.0], [-0.4, 1.3, 0.0], [0.0, -0.2, 1.1]]),
                            method="Cheung 2004", options={"terms": 3})
    # a saturated red maps green below zero; the other rows stay in gamut
    values = np.array([[0.5, 0.01, 0.02], [0.2, 0.3, 0.4], [0.3, 0.3, 0.3]])
    m = Measurement(theta_i=np.array([10.0, 20.0, 30.0]), phi_i=np.zeros(3), theta_o=np.zeros(3),
                    phi_o=np.zeros(3), values=values, channels=("R", "G", "B"))
    direct = values @ correction.matrix.T
    floor = FLOOR * direct.max(axis=0)
    low = direct < floor
    assert low.sum() == 1  # the test case does what it says
    with caplog.at_level("WARNING", logger="clothlab"):
        out = correct_measurement(correction, m)
    np.testing.assert_allclose(out.values, np.where(low, floor, direct), rtol=1e-12)
    assert out.provenance["colour_correction_floored_values"] == 1
    warned = [r for r in caplog.records if r.levelname == "WARNING" and r.name.startswith("clothlab.colour")]
    assert len(warned) == 1 and "1 corrected values" in warned[0].getMessage()
    caplog.clear()
    with caplog.at_level("WARNING", logger="clothlab"):
        inside = correct_measurement(correction, Measurement(
            theta_i=m.theta_i[1:], phi_i=m.phi_i[1:], theta_o=m.theta_o[1:], phi_o=m.phi_o[1:], values=values[1:],
            channels=("R", "G", "B")))
    assert "colour_correction_floored_values" not in inside.provenance and not caplog.records
