"""Training data, encodings, training, serialisation and the ``train-surrogate`` command of the numpy
surrogate (Chen, Wang & Wang 2024, sec. 4-5, Table 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clothlab.errors import InputError
from clothlab.models.registry import build_model
from clothlab.surrogate.data import (
    MIN_SIZE,
    MIN_Z,
    DataSpec,
    assemble,
    chunk_queries,
    generate,
    heldout_cells,
    heldout_queries,
)
from clothlab.surrogate.encodings import (
    material_vector,
    normalised_parameters,
    one_blob,
    pattern_descriptor,
    size_coordinate,
)
from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels
from clothlab.surrogate.serialise import load_surrogate, save_surrogate
from clothlab.surrogate.training import TrainSpec, train
from clothlab.weave.patterns import get_pattern
from clothlab.weave.presets import get_preset

FABRIC = "silk-shantung"


@pytest.fixture(scope="module")
def model():
    return build_model("irawan", get_preset(FABRIC))


def material_names(model):
    """The encoder's parameters: every declared one but orientation (applied outside the network)."""
    return [n for n in model.params.names() if n != "orientation"]


def test_one_blob_is_the_gaussian_kernel_at_the_bin_centres_and_wraps():
    t = np.array([0.3, 0.99])
    centres = (np.arange(8) + 0.5) / 8
    np.testing.assert_allclose(one_blob(t)[0], np.exp(-0.5 * ((0.3 - centres) * 8) ** 2))
    np.testing.assert_allclose(one_blob(np.array([0.99]), periodic=True), one_blob(np.array([-0.01]), periodic=True))
    assert one_blob(np.array([0.99]), periodic=True)[0, 0] > one_blob(np.array([0.99]))[0, 0]
    assert size_coordinate(0.0) == 0.0 and size_coordinate(5.0) == pytest.approx(1.0)


def test_normalised_parameters_map_the_fit_bounds_to_0_and_1(model):
    table = model.params
    lo = {n: table[n].bounds[0] for n in table.names()}
    hi = {n: table[n].bounds[1] for n in table.names()}
    np.testing.assert_allclose(normalised_parameters(lo, table, table.names()), 0.0, atol=1e-12)
    np.testing.assert_allclose(normalised_parameters(hi, table, table.names()), 1.0)
    lo_b, hi_b = table["beta"].bounds  # log-declared: the geometric midpoint is 0.5
    assert normalised_parameters({"beta": np.sqrt(lo_b * hi_b)}, table, ["beta"])[0] == pytest.approx(0.5)


def test_pattern_descriptor_dc_term_is_the_warp_weft_balance():
    for name in ("silk-shantung", "polyester-lining", "cotton-denim"):
        weave = get_preset(name)
        d = pattern_descriptor(weave)
        assert d[0] == pytest.approx(weave.cell_share("warp") - weave.cell_share("weft"), abs=1e-12)
        assert d.size == 1 + 2 * (2 + 2 * 5)


def test_chunks_follow_table_2_and_are_independent_and_reproducible():
    spec = DataSpec(pairs=8, seed=3)
    a = chunk_queries(spec, 1, 5)
    np.testing.assert_array_equal(a, chunk_queries(spec, 1, 5))
    assert not np.array_equal(a[:, 1:], chunk_queries(spec, 1, 6)[:, 1:])
    assert a.shape[0] == spec.rows_per_chunk() == 2 * 10 * 8
    cell = (5 % 8, 5 // 8)  # the centre lies in its grid cell
    assert cell[0] / 8 <= a[0, 1] < (cell[0] + 1) / 8 and cell[1] / 8 <= a[0, 2] < (cell[1] + 1) / 8
    sizes = np.unique(a[:, 3])
    assert np.sum(sizes < 1.0) == 10 and np.sum(sizes > 1.0) == 10 and sizes.min() >= MIN_SIZE and sizes.max() < 5
    assert sorted(np.floor(sizes[sizes > 1.0] * 10 / 4 - 2.5).astype(int)) == list(range(10))  # strata
    for w in (a[:, 4:7], a[:, 7:10]):
        np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0)
        assert np.all(w[:, 2] >= MIN_Z)
    frac = heldout_cells(DataSpec(heldout_pairs=0.1)).mean()
    assert 0.07 < frac < 0.13
    held = heldout_queries(DataSpec(heldout_pairs=0.1), 300, sizes=(0.5, 2.0))
    cell = lambda w: np.floor((w[:, 0] + 1) * 4) + 8 * np.floor((w[:, 1] + 1) * 4)  # noqa: E731
    cells = heldout_cells(DataSpec(heldout_pairs=0.1))
    assert len(held) == 300 and np.all(cells[cell(held[:, 4:7]).astype(int), cell(held[:, 7:10]).astype(int)])
    assert np.all((held[:, 3] >= 0.5) & (held[:, 3] < 2.0)) and len(np.unique(held[:, 4])) == 300


def test_generation_resumes_to_the_same_data_and_is_memory_mapped(tmp_path, model):
    spec = DataSpec(centres=2, sizes=2, pairs=4)
    labels = [ModelLabels(model)]
    calls = iter(range(100))
    assert generate(tmp_path / "a", spec, labels, stop=lambda: next(calls) >= 2) == 2
    assert generate(tmp_path / "a", spec, labels) == 2
    generate(tmp_path / "b", spec, labels)
    a, sha_a = assemble(tmp_path / "a", spec, 1, 3)
    b, sha_b = assemble(tmp_path / "b", spec, 1, 3)
    assert isinstance(a, np.memmap) and sha_a == sha_b
    np.testing.assert_array_equal(a, b)
    q = a[:, :11]
    comps = model.components(q[:, 4:7], q[:, 7:10])
    np.testing.assert_allclose(a[:, 12], comps["specular_warp"])


def test_generation_on_a_runner_writes_the_same_chunks(tmp_path, model):
    """Chunks labelled as Runner tasks (issue 13 item 4) are the in-process files byte for byte, and the
    budget still stops between rounds."""
    from clothlab.parallel import InProcessRunner

    spec = DataSpec(centres=2, sizes=2, pairs=4)
    labels = [ModelLabels(model), ModelLabels(model)]
    assert generate(tmp_path / "a", spec, labels) == 2 * spec.chunks_per_material()
    with InProcessRunner() as runner:
        assert generate(tmp_path / "b", spec, labels, runner=runner, stop=lambda: True) == 0
        assert generate(tmp_path / "b", spec, labels, runner=runner) == 2 * spec.chunks_per_material()
    for a in sorted((tmp_path / "a").glob("chunk-*.npy")):
        assert a.read_bytes() == (tmp_path / "b" / a.name).read_bytes()


def test_monte_carlo_labels_of_whole_tiles_approach_the_reflectance_model(model):
    """A box of 2 x 2 tiles averages the texture exactly over whole tiles: the reflectance model (the
    texture model's tile-average identity), up to the MC error of the estimate."""
    texture = model.texture()
    n = 6
    wi = np.tile([0.3, 0.2, np.sqrt(1 - 0.13)], (n, 1))
    wo = np.tile([-0.25, -0.1, np.sqrt(1 - 0.0725)], (n, 1))
    centre = np.random.default_rng(0).random((n, 2))
    mc = TextureMonteCarloLabels(texture, samples=4096)(wi, wo, centre, np.full(n, 2.0))
    ref = ModelLabels(model)(wi, wo, centre, np.full(n, 2.0))
    np.testing.assert_allclose(mc.mean(axis=0), ref[0], rtol=0.05)


def _tiny_run(model, steps=150):
    spec = DataSpec(centres=2, sizes=3, pairs=64, heldout_pairs=0.2)
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        generate(Path(tmp), spec, [ModelLabels(model)])
        data, _ = assemble(Path(tmp), spec, 1, 3)
        data = np.array(data)
    materials = material_vector(model.weave, model.default_parameters(), model.params, material_names(model))[None]
    spec = TrainSpec(width=16, spatial=8, enc_width=16, latent=8, batch=256, steps=steps, lr=1e-2, log_every=10)
    return data, train(data, model.component_names, materials, spec)


def test_tiny_training_reduces_the_loss_and_saved_weights_agree(tmp_path, model):
    data, result = _tiny_run(model)
    first, last = result.curve[0]["loss"], np.mean([c["loss"] for c in result.curve[-3:]])
    assert last < 0.3 * first
    assert result.metrics["rows"]["heldout_pairs"] > 0
    path = save_surrogate(result.surrogate, tmp_path / "s", data_hash="abc", metrics=result.metrics)
    loaded, sidecar = load_surrogate(path)
    assert sidecar["data_sha256"] == "abc" and sidecar["components"] == list(model.component_names)
    q = data[:50]
    np.testing.assert_array_equal(loaded.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10]),
                                  result.surrogate.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10]))
    sidecar["architecture"]["width"] = 17
    path.with_suffix(".json").write_text(json.dumps(sidecar))
    with pytest.raises(InputError, match="architecture"):
        load_surrogate(path)


def test_cli_trains_writes_its_files_refuses_to_overwrite_and_resumes(tmp_path, capsys):
    from clothlab.cli.main import main

    out = tmp_path / "run"
    args = ["train-surrogate", f"preset:{FABRIC}", "-o", str(out), "--budget", "0.02", "--labels", "model",
            "--pairs", "4", "--width", "8", "--spatial", "8", "-q"]
    assert main(args) == 0
    for name in ("surrogate.npz", "surrogate.json", "training.json", "loss.png", "heldout.png", "checkpoint.npz"):
        assert (out / name).is_file(), name
    first = json.loads((out / "training.json").read_text())["metrics"]["steps"]
    capsys.readouterr()
    assert main(args) == 2
    assert "--resume" in capsys.readouterr().err
    assert main([*args[:5], "0.04", *args[6:], "--resume"]) == 0
    assert json.loads((out / "training.json").read_text())["metrics"]["steps"] > first
    capsys.readouterr()
    assert main([*args, "--resume", "--width", "12"]) == 2  # another architecture: one line, no traceback
    assert "--width" in capsys.readouterr().err
    assert main([*args, "--resume", "--pairs", "5"]) == 2
    assert "--pairs" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------- kind: neural


@pytest.fixture(scope="module")
def weights(tmp_path_factory, model):
    _, result = _tiny_run(model, steps=60)
    result.surrogate.encoding.update(parameters=material_names(model), params=model.default_parameters(),
                                     weave=model.weave.name, data_spec=DataSpec(centres=2, sizes=3).to_dict())
    return save_surrogate(result.surrogate, tmp_path_factory.mktemp("neural") / "s")


def test_neural_kind_answers_through_the_surrogate(weights, model):
    from clothlab.errors import ConfigError
    from clothlab.models.neural.model import FAR_SIZE

    neural = build_model("neural", model.weave, weights=str(weights))
    surrogate, _ = load_surrogate(weights)
    rng = np.random.default_rng(5)
    wi = np.column_stack([rng.uniform(-0.5, 0.5, (7, 2)), np.full(7, 0.7)])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = wi * [-1, -1, 1]
    far = surrogate.query(np.full((7, 2), 0.5), np.full(7, FAR_SIZE), wi, wo)
    comps = neural.components(wi, wo)
    np.testing.assert_array_equal(np.column_stack([comps[n] for n in neural.component_names]), far)
    u, v = rng.random(7), rng.random(7)
    tex = neural.texture().components(u, v, wi, wo, footprint=0.3)
    near = surrogate.query(np.column_stack([u, v]), np.full(7, 0.3), wi, wo)
    np.testing.assert_array_equal(tex["specular_warp"], near[:, 1])
    other = neural.components(wi, wo, {"alpha": 0.3})  # another material: through the encoder
    assert not np.allclose(other["specular_warp"], comps["specular_warp"])
    np.testing.assert_array_equal(neural.components(wi, wo, {"alpha": 0.3})["specular_warp"], other["specular_warp"])
    with pytest.raises(ConfigError, match="model.options.weights"):
        build_model("neural", get_pattern("plain"))  # a weave without shipped weights


def test_whole_tile_split_is_exact_for_whole_tiles_and_agrees_with_plain_mc(model):
    """A box of side s = n + f: the n x n whole-tile part is the reflectance model (the tile-average
    identity), the rest sampled; at s = 2 the estimate is the reflectance model exactly, at s = 1.5 it agrees
    with a dense-grid average of the box written out here."""
    texture = model.texture()
    split = TextureMonteCarloLabels(texture, samples=64, tile_average=ModelLabels(model))
    wi = np.array([[0.3, 0.2, np.sqrt(1 - 0.13)]])
    wo = np.array([[-0.25, -0.1, np.sqrt(1 - 0.0725)]])
    centre = np.array([[0.37, 0.61]])
    np.testing.assert_allclose(split(wi, wo, centre, np.array([2.0])), ModelLabels(model)(wi, wo, centre, [2.0]),
                               rtol=1e-12)
    g = (np.arange(600) + 0.5) / 600 * 1.5
    u, v = np.meshgrid(centre[0, 0] - 0.75 + g, centre[0, 1] - 0.75 + g)
    dense = texture.components(u.ravel(), v.ravel(), wi, wo, noise=False)
    grid = np.array([dense[n].mean() for n in model.component_names])
    estimates = np.array([TextureMonteCarloLabels(texture, samples=256, seed=s, tile_average=ModelLabels(model))(
        wi, wo, centre, np.array([1.5]))[0] for s in range(8)])
    np.testing.assert_allclose(estimates.mean(axis=0), grid, rtol=0.03)


def test_equal_time_comparison_with_monte_carlo(weights, monkeypatch):
    """The bench's surrogate-vs-MC table: MC error falls with its sample count, times grow with it, and the
    equal-time row is the first MC row at least as slow as the surrogate."""
    import clothlab.models.neural.model as neural_model
    from clothlab.studies import neural

    monkeypatch.setattr(neural_model, "SHIPPED", weights.parent)
    f = neural.surrogate_vs_mc(True, fabric=weights.stem, queries=40)
    rows = {r["method"]: r for r in f["rows"]}
    assert f["queries"] > 10 and set(rows) == {"surrogate", *(f"MC {k}" for k in neural.MC_SAMPLES)}
    assert rows["MC 256"]["size >= 0.12"] < 0.2 * rows["MC 1"]["size >= 0.12"]
    assert rows["MC 256"]["us_per_query"] > rows["MC 1"]["us_per_query"]
    slower = [r for r in f["rows"][1:] if r["us_per_query"] >= rows["surrogate"]["us_per_query"]]
    assert f["equal_time_mc"] == (slower[0] if slower else f["rows"][-1])["method"]
    assert "equal time" in "\n".join(neural.lines({"chunk": 1, "queries": 1, "widths": [], "versus_mc": f}))


def _heldout_queries(sidecar, lo, hi, n, seed=0):
    return heldout_queries(DataSpec(**sidecar["encoding"]["data_spec"]), n, seed, (lo, hi))


def _shipped():
    from clothlab.models.neural.model import SHIPPED
    from clothlab.weave.presets import PRESET_NAMES

    return [name for name in PRESET_NAMES if (SHIPPED / f"{name}.npz").exists()]


@pytest.mark.parametrize("fabric", _shipped())
def test_shipped_weights_agree_with_fresh_labels_and_the_far_view(fabric):
    """Each shipped network on held-out direction pairs: relative RMSE of f against fresh (whole-tile split)
    MC labels for footprints of 1-5 tiles, and within 5 % of the reflectance model for footprints of 4 tiles
    and more (docs/neural.md has the figures by bin).  A residual network (g = T(R) + net) at whole-tile
    footprints of 3 and 4 tiles is the reflectance model within its measured far-view error."""
    reference = build_model("irawan", get_preset(fabric))
    neural = build_model("neural", get_preset(fabric))  # the shipped weights
    q = _heldout_queries(neural.sidecar, 1.0, 5.0, 60)
    fresh = TextureMonteCarloLabels(reference.texture(), samples=256, seed=3, tile_average=ModelLabels(reference))(
        q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3]).sum(axis=1)
    pred = sum(neural.query(q[:, 1:3], q[:, 3], q[:, 4:7], q[:, 7:10]).values())
    assert np.sqrt(np.sum((pred - fresh) ** 2) / np.sum(fresh ** 2)) <= 0.12
    far = _heldout_queries(neural.sidecar, 4.0, 5.0, 200, seed=1)
    wi, wo = far[:, 4:7], far[:, 7:10]
    reflectance = sum(reference.components(wi, wo, warn=False).values())

    def off(values) -> float:
        return float(np.sqrt(np.sum((values - reflectance) ** 2) / np.sum(reflectance ** 2)))

    assert off(sum(neural.components(wi, wo).values())) <= 0.05
    if neural.surrogate.residual:
        measured = neural.sidecar["metrics"]["far_view"]["relative_rms_vs_reflectance"]
        for tiles in (3.0, 4.0):
            values = sum(neural.query(far[:, 1:3], np.full(len(far), tiles), wi, wo).values())
            assert off(values) <= 1.5 * measured, tiles


# ------------------------------------------------------------------------------ residual over the model


def _tiny_mc_data(model, seed=0):
    """A tiny Table 2 data set labelled by whole-tile-split MC-16 of the texture (cheap, footprint-dependent)."""
    import tempfile
    from pathlib import Path

    spec = DataSpec(centres=2, sizes=3, pairs=48, heldout_pairs=0.2, seed=seed)
    labels = TextureMonteCarloLabels(model.texture(), samples=16, tile_average=ModelLabels(model))
    with tempfile.TemporaryDirectory() as tmp:
        generate(Path(tmp), spec, [labels])
        data, _ = assemble(Path(tmp), spec, 1, 3)
        return np.array(data), spec


def test_tiny_residual_network_trains_and_beats_the_plain_one_at_large_footprints(model):
    """g = T(R) + net (eqs. 9-11 on T(label)): the loss falls, and at the same steps the residual network's
    held-out error from 1 tile up is below the plain network's (R is the whole-tile average)."""
    data, _ = _tiny_mc_data(model)
    materials = material_vector(model.weave, model.default_parameters(), model.params, material_names(model))[None]
    errors = {}
    for residual in (False, True):
        spec = TrainSpec(width=16, spatial=8, enc_width=16, latent=8, batch=256, steps=120, lr=1e-2, log_every=10,
                         residual=residual)
        result = train(data, model.component_names, materials, spec, references=[ModelLabels(model)])
        assert result.surrogate.encoding["residual"] is residual
        if residual:
            first, last = result.curve[0]["loss"], np.mean([c["loss"] for c in result.curve[-3:]])
            assert last < 0.5 * first
        big = [b for b in result.metrics["heldout_pairs"] if b["size_lo"] >= 1.0]
        errors[residual] = np.sqrt(np.mean([b["relative_rmse"] ** 2 for b in big]))
    assert errors[True] < errors[False]


def test_residual_surrogate_is_the_reflectance_model_plus_its_outputs_and_round_trips(tmp_path, model):
    """At inference g = T(R) + net, decoded; with zero output weights the surrogate is R exactly (a whole-
    tile footprint's average); the sidecar records the option, and without the model the surrogate refuses."""
    from clothlab.models.neural.model import load_neural
    from clothlab.weave.wvformat import format_wv

    data, spec = _tiny_mc_data(model)
    materials = material_vector(model.weave, model.default_parameters(), model.params, material_names(model))[None]
    result = train(data, model.component_names, materials,
                   TrainSpec(width=8, spatial=8, enc_width=8, latent=8, batch=128, steps=5, residual=True,
                             residual_input=True), references=[ModelLabels(model)])
    sur = result.surrogate
    sur.network.params()["ang5.W"][...] = 0.0
    sur.network.params()["ang5.b"][...] = 0.0
    sur.reset()
    q = data[:40]
    args = (q[:, 1:3], np.full(40, 2.0), q[:, 4:7], q[:, 7:10])
    np.testing.assert_allclose(sur.query(*args), ModelLabels(model)(q[:, 4:7], q[:, 7:10], q[:, 1:3], args[1]),
                               rtol=1e-12, atol=1e-15)
    sur.encoding.update(kind="irawan", params=model.default_parameters(), weave=model.weave.name,
                        weave_wv=format_wv(model.weave),
                        data_spec=spec.to_dict())
    path = save_surrogate(sur, tmp_path / "r")
    bare, sidecar = load_surrogate(path)
    assert sidecar["encoding"]["residual"] and sidecar["encoding"]["residual_input"]
    assert sidecar["architecture"]["n_angular"] == 8 + 3  # direction features + T(R)
    with pytest.raises(ValueError, match="reflectance model"):
        bare.query(*args)
    loaded, _ = load_neural(path)
    np.testing.assert_array_equal(loaded.query(*args), sur.query(*args))
    neural = build_model("neural", model.weave, weights=str(path))
    other = {"alpha": 0.2}  # another material: the model's R at those parameters, then the (zero) correction
    np.testing.assert_allclose(np.column_stack(list(neural.components(q[:, 4:7], q[:, 7:10], other).values())),
                               np.column_stack(list(model.components(q[:, 4:7], q[:, 7:10], other).values())),
                               rtol=1e-12, atol=1e-15)


def test_residual_loss_gradient_matches_central_differences_with_the_reference_input(model):
    """Eq. 11 of g = T(R) + net against T(label), with T(R) also an input: the training path's d loss / d
    parameters (targets T(label) - T(R), backward unchanged) against float64 central differences."""
    from clothlab.surrogate.losses import column_weights, encode_targets, is_specular, loss_and_gradient
    from clothlab.surrogate.network import SurrogateNetwork
    from clothlab.surrogate.training import _batch, make_surrogate, transformed_references

    data, _ = _tiny_mc_data(model)
    rows = data[:12]
    materials = material_vector(model.weave, model.default_parameters(), model.params, material_names(model))[None]
    spec = TrainSpec(width=5, spatial=4, enc_width=4, latent=3, residual=True, residual_input=True)
    sur = make_surrogate(spec, materials, model.component_names, {}, [ModelLabels(model)])
    sur.network = SurrogateNetwork(sur.network.arch, seed=2, dtype=np.float64)
    rng = np.random.default_rng(0)
    for p in sur.network.params().values():
        p += 0.1 * rng.standard_normal(p.shape)
    specular = is_specular(model.component_names)
    weights = column_weights(specular)
    t_ref = transformed_references(sur, rows).astype(np.float64)
    index, spatial, angular, targets = _batch(sur, rows, specular, t_ref)
    spatial, angular, targets = (np.asarray(a, dtype=np.float64) for a in (spatial, angular, targets))
    t_label = encode_targets(rows[:, 11:], specular)

    def loss() -> float:  # written out: sum_c lambda_c mean_b (T(R) + net - T(label))^2
        g = t_ref + sur.network.forward(sur.materials, index, spatial, angular)
        return float(np.sum(weights * np.mean((g - t_label) ** 2, axis=0)))

    out = sur.network.forward(sur.materials, index, spatial, angular, train=True)
    value, d_out = loss_and_gradient(out, targets, weights)
    assert value == pytest.approx(loss(), rel=1e-10)
    sur.network.backward(d_out)
    grads = {k: v.copy() for k, v in sur.network.grads().items()}
    h = 1e-6
    for name, p in sur.network.params().items():
        numeric = np.zeros_like(p)
        for i in np.ndindex(p.shape):
            keep = p[i]
            p[i] = keep + h
            up = loss()
            p[i] = keep - h
            down = loss()
            p[i] = keep
            numeric[i] = (up - down) / (2 * h)
        assert np.linalg.norm(grads[name] - numeric) <= 1e-5 * max(np.linalg.norm(numeric), 1e-12), name


def test_bootstrap_interval_of_the_relative_rmse_brackets_it_and_shows_a_heavy_tail():
    """relative_rmse_interval: seeded, contains the point estimate, narrows ~1 / sqrt(n) for homogeneous
    errors, and is wide when one query carries most of the error (the small-footprint bins' case)."""
    from clothlab.surrogate.training import relative_rmse_interval

    rng = np.random.default_rng(0)

    def rel(p, t):
        return np.sqrt(np.sum((p - t) ** 2) / np.sum(t ** 2))

    widths = []
    for n in (400, 6400):
        truth = rng.uniform(0.5, 1.5, n)
        pred = truth * (1 + 0.2 * rng.normal(size=n))
        lo, hi = relative_rmse_interval(pred, truth)
        assert lo < rel(pred, truth) < hi
        assert relative_rmse_interval(pred, truth) == [lo, hi]
        widths.append(hi - lo)
    assert 2.5 < widths[0] / widths[1] < 6.5  # sqrt(16) = 4
    truth = np.ones(2000)
    truth[0] = 100.0
    pred = truth * 1.05
    pred[0] = 40.0  # one highlight carries ~95 % of the squared error
    lo, hi = relative_rmse_interval(pred, truth)
    assert lo < 0.1 and hi > 0.5


def test_labelling_on_workers_is_charged_to_the_budget_as_wall_time_x_workers(tmp_path, model):
    """On a runner the label share of ``budget_s`` is wall x workers (the workers' CPU is not this process's),
    and training gets the budget minus that, not minus this process's CPU: a label source that waits (wall
    time, no CPU) on 4 workers costs the training 4x its wait."""
    import time

    from clothlab.parallel import InProcessRunner
    from clothlab.surrogate.encodings import material_vector
    from clothlab.surrogate.training import TrainSpec
    from clothlab.surrogate.training_run import run_training

    class WaitingLabels(ModelLabels):
        def __call__(self, *args):
            time.sleep(0.1)
            return super().__call__(*args)

    spec = DataSpec(centres=2, sizes=2, pairs=4)
    p = model.default_parameters()
    names = [n for n in model.params.names() if n != "orientation"]
    materials = material_vector(model.weave, p, model.params, names)[None]
    train_spec = TrainSpec(width=8, spatial=8, enc_width=8, latent=8, batch=64)
    model.components(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))  # compiled before the clock runs
    with InProcessRunner() as runner:
        runner.workers = 4
        result = run_training(tmp_path / "run", [WaitingLabels(model)], materials, spec, train_spec, budget_s=4.0,
                              plots=False, runner=runner)
    waited = 0.1 * spec.chunks_per_material()
    label_s = result.metrics["label_cpu_s"]
    assert label_s >= 4 * waited
    summary = json.loads((tmp_path / "run" / "training.json").read_text())
    assert summary["train_spec"]["budget_s"] == pytest.approx(4.0 - label_s)
