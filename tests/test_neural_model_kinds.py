"""``kind: neural`` for a network of any target kind: the shipped surface family network
(``families/surface-twill-3x3-alpha-beta``, a residual network over ``kind: surface`` varying warp.alpha x
warp.beta) as a model (surface parameters and components), its fast material fit through the encoder with
R of the exact model at every trial (gradient checked against finite differences of the whole objective),
the exact refinement, ``clothlab fit`` / ``eval`` / ``report`` on a fabric.yaml naming it, and the
ConfigErrors of bad weights."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from clothlab.errors import ConfigError, ParameterError

FAMILY = "families/surface-twill-3x3-alpha-beta.npz"
UNSEEN = {"warp.alpha": 0.1778279410038923, "warp.beta": 0.5}  # a held-out midpoint of the grid
COEFFICIENTS = {"diffuse_warp": 0.3, "diffuse_weft": 0.2, "specular_warp": 0.5, "specular_weft": 0.4}


@pytest.fixture(scope="module")
def weights():
    from clothlab.models.neural.model import SHIPPED

    return SHIPPED / FAMILY


@pytest.fixture(scope="module")
def neural(weights):
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    return build_model("neural", resolve_weave("pattern:twill-3x3", "."), weights=str(weights))


def _directions(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-0.8, 0.8, (6 * n, 2))
    xy = xy[np.sum(xy ** 2, axis=1) < 0.8][:2 * n]
    d = np.column_stack([xy, np.sqrt(1 - np.sum(xy ** 2, axis=1))])
    return d[:n], d[n:]


def _relative_rms(a: dict, b: dict) -> float:
    f, g = sum(a.values()), sum(b.values())
    return float(np.sqrt(np.sum((f - g) ** 2) / np.sum(g ** 2)))


def test_surface_network_is_a_model_of_the_surface_parameters_and_components(neural):
    from clothlab.models.surface.model import SurfaceModel

    assert neural.target == "surface"
    assert neural.params.names() == SurfaceModel.params.names()
    assert neural.component_names == SurfaceModel.component_names
    assert neural.default_free == ("warp.alpha", "warp.beta")  # the --vary grid's parameters
    assert neural.texture().component_names == SurfaceModel.component_names
    with pytest.raises(ParameterError):
        neural.resolve({"alpha": 0.1})  # an IM name


@pytest.mark.parametrize("material", [0, 9, {"warp.alpha": 0.25, "warp.beta": 0.8}])
def test_far_view_follows_the_exact_surface_model(neural, material):
    """Far view (4.5 tiles) of a residual network: within 3 % of the exact surface model (the sidecar's far
    view is 0.8 % on held-out pairs) for a trained grid material (row 0), an unseen midpoint (row 9) and a
    material off the grid (through the encoder, R at its parameters)."""
    q = neural.sidecar["encoding"]["materials_params"][material] if isinstance(material, int) else material
    params = {**neural.resolve({}), **q}
    row = neural._material(params)
    assert (row == material) if isinstance(material, int) else not isinstance(row, int)
    wi, wo = _directions(150)
    exact = neural.exact_model().components(wi, wo, params)
    assert _relative_rms(neural.components(wi, wo, params), exact) <= 0.03


def test_material_objective_gradient_matches_finite_differences_of_the_objective(neural):
    """dF/dx (network backward pass through the encoder + central differences of T(R)) against central
    differences of the whole profile objective F (the network runs float32: step 2e-3, 2 % agreement)."""
    wi, wo = _directions(120)
    c = neural.exact_model().components(wi, wo, {**neural.resolve({}), **UNSEEN})
    y = sum(v * c[k] for k, v in COEFFICIENTS.items())
    objective = neural.material_objective(wi, wo, y, params=neural.resolve({}))
    for x in (np.array([0.35, 0.4]), np.array([0.7, 0.65])):
        value, grad = objective.value_and_gradient(x)
        assert value == pytest.approx(objective(x), rel=1e-6)
        h = 2e-3
        fd = np.array([(objective(x + h * e) - objective(x - h * e)) / (2 * h) for e in np.eye(2)])
        np.testing.assert_allclose(grad, fd, rtol=0.02, atol=1e-3 * np.max(np.abs(fd)))


def test_fast_fit_with_residual_weights_then_exact_refinement_recovers_an_unseen_material(neural):
    """Noise-free far-view data of the unseen grid midpoint (alpha 0.178, beta 0.5) simulated by the exact
    surface model: the fast fit through the encoder (with R at each trial) improves on its start (defaults
    alpha 0.5, beta 1) in residual and in both parameters; the exact refinement recovers them to 1e-5."""
    from clothlab.surrogate.encodings import normalised_parameters

    wi, wo = _directions(120)
    start = neural.resolve({})
    c = neural.exact_model().components(wi, wo, {**start, **UNSEEN})
    y = sum(v * c[k] for k, v in COEFFICIENTS.items())
    objective = neural.material_objective(wi, wo, y, params=start)
    start_rms = np.sqrt(objective(normalised_parameters(start, neural.params, ["warp.alpha", "warp.beta"])))
    fitted, result = neural.fit_material(wi, wo, y, params=start, steps=30, starts=2, refine=True)
    fast = result.fast
    assert fast["rms"] < 0.2 * start_rms
    for k, v in UNSEEN.items():
        assert abs(fast["params"][k] - v) < 0.25 * abs(start[k] - v), k
        assert fitted[k] == pytest.approx(v, rel=1e-5, abs=1e-6)
    for k, v in COEFFICIENTS.items():
        assert result.coefficients[k] == pytest.approx(v, rel=1e-4)


# ------------------------------------------------------------------------------------------ configuration
def _yaml(tmp_path, body: str):
    path = tmp_path / "fabric.yaml"
    path.write_text("name: n\nmeasurement: {path: table.csv}\n" + body)
    (tmp_path / "table.csv").write_text("theta_i,phi_i,theta_o,phi_o,value\n30,0,30,180,0.1\n")
    return path


def test_config_reads_the_network_target_parameters_and_resolves_weights_relative_to_the_yaml(tmp_path, weights):
    import shutil

    from clothlab.config import load_config

    (tmp_path / "nets").mkdir()
    for ext in (".npz", ".json"):
        shutil.copy(weights.with_suffix(ext), tmp_path / "nets" / f"family{ext}")
    cfg = load_config(_yaml(tmp_path, "model:\n  kind: neural\n  weave: pattern:twill-3x3\n"
                                      "  options: {weights: nets/family.npz}\n  params: {warp.alpha: 0.3}\n"))
    assert cfg.model.options["weights"] == str(tmp_path / "nets" / "family.npz")
    assert cfg.fit.free == ("warp.alpha", "warp.beta") and cfg.model.params == {"warp.alpha": 0.3}
    with pytest.raises(ConfigError) as err:  # an IM parameter for a surface network
        load_config(_yaml(tmp_path, "model:\n  kind: neural\n  weave: pattern:twill-3x3\n"
                                    "  options: {weights: nets/family.npz}\n  params: {alpha: 0.3}\n"))
    assert err.value.field == "model.params.alpha" and "warp.alpha" in err.value.detail
    with pytest.raises(ConfigError) as err:  # a surface parameter for the shipped (IM) preset network
        load_config(_yaml(tmp_path, "model:\n  kind: neural\n  weave: preset:silk-shantung\n"
                                    "  params: {warp.alpha: 0.3}\n"))
    assert err.value.field == "model.params.warp.alpha"


def test_bad_weights_are_config_errors_naming_the_option(tmp_path):
    from clothlab.config import load_config
    from clothlab.models.registry import build_model
    from clothlab.weave.presets import resolve_weave

    body = "model:\n  kind: neural\n  weave: pattern:twill-3x3\n  options: {weights: %s}\n"
    with pytest.raises(ConfigError) as err:
        load_config(_yaml(tmp_path, body % "missing.npz"))
    assert err.value.field == "model.options.weights" and "not found" in err.value.detail
    (tmp_path / "fake.npz").write_bytes(b"not an npz")
    (tmp_path / "fake.json").write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(ConfigError) as err:
        load_config(_yaml(tmp_path, body % "fake.npz"))
    assert err.value.field == "model.options.weights" and "not a surrogate" in err.value.detail
    weave = resolve_weave("pattern:twill-3x3", ".")
    for path in (tmp_path / "missing.npz", tmp_path / "fake.npz"):
        with pytest.raises(ConfigError) as err:
            build_model("neural", weave, weights=str(path))
        assert err.value.field == "model.options.weights"
    with pytest.raises(ConfigError):
        load_config(_yaml(tmp_path, "model:\n  kind: neural\n  weave: pattern:twill-3x3\n  options: {refine: 1}\n"))


# ------------------------------------------------------------------------------------- fit, eval, report
def test_clothlab_fit_eval_report_on_a_neural_surface_fabric(tmp_path, weights, neural):
    """``clothlab fit`` of a kind-neural fabric.yaml (weights relative to it, ``refine: true``) on a table of
    the unseen material simulated by the exact surface model (60 direction pairs, unit-free colours): the
    encoder fit and the exact refinement both recorded, the refined parameters the truth; ``clothlab eval``
    with u, v, footprint columns answers with the network (equal to its query), ``clothlab report`` puts
    the fit on the comparison page."""
    import shutil

    from clothlab.cli.main import main
    from clothlab.frames import spherical_to_vector
    from clothlab.io.measurement import Measurement
    from clothlab.io.table import write_table
    from clothlab.models.components import coefficient_name
    from clothlab.report.build import build_comparison

    for ext in (".npz", ".json"):
        shutil.copy(weights.with_suffix(ext), tmp_path / f"family{ext}")
    rng = np.random.default_rng(3)
    n = 60
    angles = np.column_stack([rng.uniform(5, 70, n), rng.uniform(0, 360, n), rng.uniform(5, 70, n),
                              rng.uniform(0, 360, n)])
    wi, wo = spherical_to_vector(angles[:, 0], angles[:, 1]), spherical_to_vector(angles[:, 2], angles[:, 3])
    c = neural.exact_model().components(wi, wo, {**neural.resolve({}), **UNSEEN})
    values = sum(v * c[k] for k, v in COEFFICIENTS.items())
    write_table(Measurement(*angles.T, values[:, None], ("value",)), tmp_path / "table.csv")
    (tmp_path / "fabric.yaml").write_text(
        "name: neural-surface\nmeasurement: {path: table.csv}\nmodel:\n  kind: neural\n  weave: pattern:twill-3x3\n"
        "  options: {weights: family.npz, refine: true}\n"
        "fit:\n  optimizer: {global: GN_CRS2_LM, local: LN_BOBYQA, max_evals: 40, starts: 1, seed: 1}\n"
        "output: {fits: fits, reports: reports}\n")
    assert main(["fit", str(tmp_path / "fabric.yaml"), "-q"]) == 0
    fit = json.loads((tmp_path / "fits" / "neural-surface" / "fit.json").read_text())
    assert fit["model"]["kind"] == "neural" and fit["refinement"]["kind"] == "surface"
    assert fit["refinement"]["refined"]["objective_exact"] <= fit["refinement"]["encoder"]["objective_exact"]
    for k, v in UNSEEN.items():
        assert fit["parameters"][k]["value"] == pytest.approx(v, rel=1e-3, abs=1e-3)
    directions = tmp_path / "directions.csv"
    directions.write_text("theta_i,phi_i,theta_o,phi_o,u,v,footprint\n30,0,30,180,0.3,0.4,0.05\n45,90,20,270,0.7,0.1,2\n")
    out = tmp_path / "eval.csv"
    assert main(["eval", str(tmp_path / "fits" / "neural-surface"), str(directions), "--components", "-o",
                 str(out)]) == 0
    rows = np.genfromtxt(out, delimiter=",", names=True)
    params = {**neural.resolve({}), **{k: fit["parameters"][k]["value"] for k in UNSEEN}}
    d = spherical_to_vector(np.array([30.0, 45.0]), np.array([0.0, 90.0]))
    e = spherical_to_vector(np.array([30.0, 20.0]), np.array([180.0, 270.0]))
    q = neural.query(np.array([[0.3, 0.4], [0.7, 0.1]]), np.array([0.05, 2.0]), d, e, params)
    expected = sum(fit["coefficients"][coefficient_name(k)]["value"] * v for k, v in q.items())
    np.testing.assert_allclose(rows["value"], expected, rtol=1e-6)
    shipped = Path(__file__).resolve().parents[1] / "fits" / "surface-twill"
    page = build_comparison([tmp_path / "fits" / "neural-surface", shipped], tmp_path / "reports")
    summary = json.loads((page / "summary.json").read_text())
    row = next(r for r in summary["rows"] if r["name"] == "neural-surface")
    assert row["model"] == "neural" and row["setting"] == "weights=family.npz, refine=True"
    assert row["parameters"]["warp.alpha"]["value"] == pytest.approx(UNSEEN["warp.alpha"], rel=1e-3)
    assert "neural-surface" in (page / "index.html").read_text()
