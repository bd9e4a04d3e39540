"""Fitting an isotropic measurement (a MERL table: only phi_o - phi_i measured): the model averaged over the
fabric's orientation (clothlab.fit.problem module docstring), orientation not fittable."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.errors import ConfigError
from clothlab.fit.problem import FitProblem
from clothlab.io.measurement import Measurement
from clothlab.models.registry import build_model
from clothlab.weave.presets import resolve_weave


def _directions(n, seed):
    rng = np.random.default_rng(seed)
    theta_i = np.degrees(np.arccos(rng.uniform(0.2, 1.0, n)))
    theta_o = np.degrees(np.arccos(rng.uniform(0.2, 1.0, n)))
    return theta_i, np.zeros(n), theta_o, rng.uniform(0.0, 360.0, n)


def _measurement(values, angles, isotropic=True):
    return Measurement(*angles, values=values, channels=("grey",), provenance={"isotropic": isotropic},
                       source="merl.binary")


def _unit(theta, phi):
    t, p = np.radians(theta), np.radians(phi)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)


def _averaged_by_rotation(model, params, angles, orientations):
    """Independent: the directions themselves rotated by -orientation about z (a rotation matrix written
    here), the model evaluated without an orientation parameter, the components averaged."""
    wi, wo = _unit(*angles[:2]), _unit(*angles[2:])
    total = 0.0
    for a in orientations:
        c, s = np.cos(np.radians(-a)), np.sin(np.radians(-a))
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        comps = model.components(wi @ rot.T, wo @ rot.T, params, normalised=True, warn=False)
        total = total + np.stack([comps[k] for k in model.component_names], axis=1)
    return total / len(orientations)


@pytest.fixture(scope="module")
def denim():
    return build_model("irawan", resolve_weave("preset:cotton-denim", "."), ("trapezoid", 11))


def test_design_is_the_orientation_average_of_the_model(denim):
    angles = _directions(60, 1)
    params = denim.default_parameters()
    m = _measurement(np.ones((60, 1)), angles)
    problem = FitProblem(denim, m, ("alpha",), params, orientation_nodes=16)
    orientations = (np.arange(16) + 0.5) * 180.0 / 16 - 90.0
    expected = _averaged_by_rotation(denim, params, angles, orientations)
    np.testing.assert_allclose(problem.design(params, normalised=True), expected, rtol=1e-12, atol=1e-15)
    # an anisotropic table of the same directions is not averaged
    plain = FitProblem(denim, _measurement(np.ones((60, 1)), angles, isotropic=False), ("alpha",), params)
    assert plain.orientations is None
    assert not np.allclose(plain.design(params, normalised=True), expected, rtol=1e-3)


def test_averaged_design_depends_on_the_azimuth_difference_only(denim):
    """What makes it the right model for an isotropic table: turning every direction pair about the normal
    changes the average by no more than the midpoint rule's own error (measured here with 64 nodes vs 720)."""
    theta_i, phi_i, theta_o, phi_o = _directions(80, 2)
    params = denim.default_parameters()
    design = {}
    for turn in (0.0, 23.0):
        m = _measurement(np.ones((80, 1)), (theta_i, phi_i + turn, theta_o, phi_o + turn))
        design[turn] = FitProblem(denim, m, ("alpha",), params, orientation_nodes=720).design(params)
    scale = np.abs(design[0.0]).sum(axis=1)
    assert np.max(np.abs(design[23.0] - design[0.0]).sum(axis=1) / scale) < 2e-3


def test_orientation_cannot_be_freed_for_an_isotropic_measurement(denim):
    m = _measurement(np.ones((10, 1)), _directions(10, 3))
    with pytest.raises(ConfigError, match="isotropic") as info:
        FitProblem(denim, m, ("alpha", "orientation"), denim.default_parameters())
    assert info.value.field == "fit.free" and "merl.binary" in str(info.value)


def test_fit_of_an_isotropic_table_recovers_the_material(denim):
    """Values made by the independent rotation average at alpha 0.08, beta 3 (kd, ks chosen here): the fit
    from alpha 0.03, beta 1 recovers them."""
    from clothlab.config.schema import OptimizerConfig
    from clothlab.fit.optimize import multistart_minimize

    angles = _directions(120, 4)
    truth = {**denim.default_parameters(), "alpha": 0.08, "beta": 3.0}
    comps = _averaged_by_rotation(denim, truth, angles, (np.arange(32) + 0.5) * 180.0 / 32 - 90.0)
    values = comps @ np.array([0.3, 0.5, 0.4])[: comps.shape[1]]
    start = {**truth, "alpha": 0.03, "beta": 1.0}
    problem = FitProblem(denim, _measurement(values[:, None], angles), ("alpha", "beta"), start,
                         orientation_nodes=32)
    settings = OptimizerConfig(max_evals=400, starts=1, seed=1, polish=100, box_check=False)
    result = multistart_minimize(problem, problem.to_unit(problem.start), settings)
    found = problem.from_unit(result.x)
    assert found["alpha"] == pytest.approx(0.08, rel=1e-3) and found["beta"] == pytest.approx(3.0, rel=1e-3)


def test_selection_of_an_isotropic_table_frees_no_orientation():
    from clothlab.fit.select import SelectSettings, candidates

    settings = SelectSettings(weaves=("preset:cotton-denim", "preset:silk-shantung"),
                              kinds=("irawan", "irawan+oren-nayar"), orientation_starts=3)
    assert len(candidates(settings)) == 2 * 2 * 3
    iso = candidates(settings, isotropic=True)
    assert len(iso) == 4 and all(c.orientation_start is None for c in iso)


def test_enlarged_box_and_cv_folds_keep_the_orientation_average(denim, monkeypatch):
    from clothlab.fit import crossval

    m = _measurement(np.ones((40, 1)), _directions(40, 6))
    seen = []

    class Recording(FitProblem):  # every problem made from here on records its orientation count
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            seen.append(None if self.orientations is None else len(self.orientations))

    monkeypatch.setattr(crossval, "FitProblem", Recording)
    problem = Recording(denim, m, ("alpha",), denim.default_parameters(), orientation_nodes=12)
    assert len(problem.enlarged(0.25).orientations) == 12
    crossval.cross_validate(problem, problem.start, k=2, seed=0, max_evals=4, scheme="random", refit="local")
    assert len(seen) == 3 and set(seen) == {12}  # the problem and its two fold problems
