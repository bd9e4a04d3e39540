"""The texture probe input of the surrogate (``--probe-points``; clothlab.surrogate.labels.TextureProbe) and the
output cap recorded from the training labels (``encoding["output_max"]``)."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.models.registry import build_model
from clothlab.surrogate.data import DataSpec, assemble, generate
from clothlab.surrogate.encodings import material_vector
from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels, TextureProbe
from clothlab.surrogate.losses import encode_targets, is_specular
from clothlab.surrogate.serialise import save_surrogate
from clothlab.surrogate.training import TrainSpec, train
from clothlab.weave.presets import get_preset
from clothlab.weave.wvformat import format_wv

FABRIC = "cotton-twill"


@pytest.fixture(scope="module")
def model():
    return build_model("irawan", get_preset(FABRIC))


def _directions(rng, n):
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.2
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_probe_points_are_the_midpoint_rule_of_the_footprint(model):
    """n = 1 is the texture at the footprint centre; for every n the points are the n x n cell midpoints of the
    box (offsets symmetric, inside +-size/2), and their mean converges to the footprint average as n grows
    (against whole-tile-split MC-4096 labels, an independent estimator)."""
    rng = np.random.default_rng(3)
    n = 60
    wi, wo = _directions(rng, n), _directions(rng, n)
    centre, size = rng.random((n, 2)), np.full(n, 0.3)
    texture, p = model.texture(), model.default_parameters()
    centre_values = texture.components(centre[:, 0], centre[:, 1], wi, wo, p, noise=False, warn=False)
    one = TextureProbe(texture, p, 1)(wi, wo, centre, size)
    np.testing.assert_array_equal(one, np.column_stack([centre_values[k] for k in texture.component_names]))
    offsets = TextureProbe(texture, p, 3).offsets()
    np.testing.assert_allclose(np.sort(np.unique(offsets[:, 0])), [-1 / 3, 0.0, 1 / 3], atol=1e-15)
    assert offsets.shape == (9, 2)
    labels = TextureMonteCarloLabels(texture, p, samples=4096, seed=5, tile_average=ModelLabels(model, p))
    truth = labels(wi, wo, centre, size).sum(axis=1)
    errors = []
    for k in (1, 4, 16):
        mean = TextureProbe(texture, p, k)(wi, wo, centre, size).reshape(n, k * k, -1).mean(axis=1).sum(axis=1)
        errors.append(np.sqrt(np.sum((mean - truth) ** 2) / np.sum(truth ** 2)))
    assert errors[2] < errors[1] < errors[0]
    assert errors[2] < 0.1


def _tiny_data(model):
    import tempfile
    from pathlib import Path

    spec = DataSpec(centres=2, sizes=3, pairs=48, heldout_pairs=0.2, small_sizes=4)
    labels = TextureMonteCarloLabels(model.texture(), samples=16, tile_average=ModelLabels(model))
    with tempfile.TemporaryDirectory() as tmp:
        generate(Path(tmp), spec, [labels])
        data, _ = assemble(Path(tmp), spec, 1, 3)
        return np.array(data), spec


def _probing_network(directory, model, steps=150, **inputs):
    """A tiny residual network with a 2 x 2 probe (``inputs``: other TrainSpec input flags) trained on
    ``model``'s default material, saved in ``directory``: (path, surrogate, training curve, data)."""
    data, spec = _tiny_data(model)
    p = model.default_parameters()
    names = [n for n in model.params.names() if n != "orientation"]
    materials = material_vector(model.weave, p, model.params, names)[None]
    train_spec = TrainSpec(width=16, spatial=8, enc_width=16, latent=8, batch=256, steps=steps, lr=1e-2,
                           log_every=10, **{"residual": True, "probe_points": 2, **inputs})
    result = train(data, model.component_names, materials, train_spec, references=[ModelLabels(model, p)],
                   probes=[TextureProbe(model.texture(), p, 2)])
    sur = result.surrogate
    sur.encoding.update(kind="irawan", params=p, weave=model.weave.name, weave_wv=format_wv(model.weave),
                        data_spec=spec.to_dict(), parameters=names)
    return save_surrogate(sur, directory / "probe"), sur, result.curve, data


def test_a_probing_network_trains_round_trips_and_needs_its_probe(tmp_path, model):
    """With ``probe_points`` the decoder reads T of the n^2 probe values (n^2 C more inputs); the loss falls;
    saved and loaded with its texture attached (load_neural) it answers as in memory; without probes it
    refuses; kind neural at another material computes the probe itself."""
    from clothlab.models.neural.model import load_neural
    from clothlab.surrogate.serialise import load_surrogate

    path, sur, curve, data = _probing_network(tmp_path, model)
    p = model.default_parameters()
    first, last = curve[0]["loss"], np.mean([c["loss"] for c in curve[-3:]])
    assert last < 0.5 * first
    assert sur.network.arch.n_angular == 8 + 4 * 3
    probe = TextureProbe(model.texture(), p, 2)
    q = data[:64]
    args = (q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10])
    bare, sidecar = load_surrogate(path)
    assert sidecar["encoding"]["probe_points"] == 2
    reference = ModelLabels(model, p)(args[2], args[3], args[0], args[1])
    with pytest.raises(ValueError, match="texture probe"):
        bare.query(*args, reference=reference)
    loaded, _ = load_neural(path)
    np.testing.assert_array_equal(loaded.query(*args), sur.query(*args))
    # a material vector: the caller's probe values are what the network reads
    vector = sur.materials[0]
    probed = probe(args[2], args[3], args[0], args[1])
    np.testing.assert_allclose(sur.query(*args, material=vector, reference=reference, probe=probed),
                               sur.query(*args), rtol=1e-5)
    neural = build_model("neural", model.weave, weights=str(path))
    other = {**p, "alpha": 0.9 * p["alpha"]}
    out = neural.query(args[0], args[1], args[2], args[3], other)
    own = TextureProbe(model.texture(), other, 2)(args[2], args[3], args[0], args[1])
    expected = sur.query(*args, material=neural.material_vector(other),
                         reference=ModelLabels(model, other)(args[2], args[3], args[0], args[1]), probe=own)
    np.testing.assert_allclose(np.column_stack([out[k] for k in model.component_names]), expected, rtol=1e-12)


@pytest.mark.parametrize("inputs", [{}, {"residual": False, "probe_points": 0, "residual_input": True}],
                         ids=["residual-probe", "residual-input"])
def test_the_fast_fit_of_a_probing_network_descends_its_objective(tmp_path, model, inputs):
    """The fast material fit through a probing residual network (and one reading T(R) as an input): T(R) and
    the probe depend on the material, so dF/dx has, besides the encoder path, their finite differences times
    the network's input gradient.  On a float64 copy of the network the gradient agrees with central
    differences of F itself (the encoder path alone is ~0.5 % of it here), and a fit from there does not end
    above its start."""
    from clothlab.surrogate.network import SurrogateNetwork

    path, _, _, _ = _probing_network(tmp_path, model, steps=60, **inputs)
    neural = build_model("neural", model.weave, weights=str(path))
    net = neural.surrogate.network
    exact64 = SurrogateNetwork(net.arch, dtype=np.float64)
    exact64.set_params({k: v.astype(np.float64) for k, v in net.params().items()})
    neural.surrogate.network = exact64
    neural.surrogate.reset()
    rng = np.random.default_rng(8)
    wi, wo = _directions(rng, 80), _directions(rng, 80)
    p = model.default_parameters()
    truth = {**p, "alpha": 1.3 * p["alpha"], "beta": 0.8 * p["beta"]}
    c = model.components(wi, wo, truth, warn=False)
    y = sum(c[k] for k in model.component_names)
    objective = neural.material_objective(wi, wo, y, free=["alpha", "beta"], params=p)
    assert objective.reference is not None and (objective.probe is not None) == ("residual_input" not in inputs)
    x = np.array([0.35, 0.6])
    value, grad = objective.value_and_gradient(x)
    assert value == pytest.approx(objective(x), rel=1e-12)
    h = 1e-5
    numeric = np.array([(objective(x + h * e) - objective(x - h * e)) / (2 * h) for e in np.eye(2)])
    assert np.linalg.norm(grad - numeric) <= 1e-4 * np.linalg.norm(numeric)
    fitted, fit = neural.fit_material(wi, wo, y, free=["alpha", "beta"], params=p, steps=15, starts=1)
    start = neural.material_objective(wi, wo, y, free=["alpha", "beta"], params=p)(np.full(2, 0.5))
    assert np.isfinite(fit.rms) and fit.rms ** 2 <= start * (1 + 1e-9)
    assert set(fit.params) == {"alpha", "beta"} and fitted["alpha"] > 0


def test_outputs_are_capped_at_twice_the_largest_training_label(model):
    """``output_max`` is the largest T(label) of the training rows per component; a network whose outputs run
    far beyond it (here: a huge output bias) decodes to at most (exp(max + ln 2) - 1) / k, not to overflow."""
    data, _ = _tiny_data(model)
    p = model.default_parameters()
    materials = material_vector(model.weave, p, model.params, [n for n in model.params.names()
                                                             if n != "orientation"])[None]
    result = train(data, model.component_names, materials,
                   TrainSpec(width=8, spatial=8, enc_width=8, latent=8, batch=128, steps=3))
    sur = result.surrogate
    specular = is_specular(model.component_names)
    train_rows = data[data[:, 10] < 0.5]
    np.testing.assert_allclose(sur.encoding["output_max"], encode_targets(train_rows[:, 11:], specular).max(axis=0))
    sur.network.params()["ang5.b"][...] = 80.0
    sur.reset()
    q = data[:20]
    values = sur.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10])
    assert np.all(np.isfinite(values))
    top = train_rows[:, 11:].max(axis=0)
    bound = np.where(specular, 2.0 * top + 1.0 / 100.0, top + np.log(2.0))
    assert np.all(values <= bound * (1 + 1e-6))
    assert np.all(values[:, specular] >= top[specular])  # the cap, not a clip at the label range itself
