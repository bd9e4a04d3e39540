"""Reciprocal training (``TrainSpec.reciprocal``, ``train-surrogate --reciprocal``; clothlab.surrogate.training):
rows are trained with wi and wo swapped only where the swapped pair is a trained direction-cell pair, the
label is unchanged, and a non-reciprocal model is refused (docs/neural.md, "Retrains with the converged tile
average")."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clothlab.surrogate.data import DataSpec, chunk_queries, heldout_cells, swap_trained

NAMES = ("diffuse", "specular_warp", "specular_weft")


def _cells(w: np.ndarray, d: int) -> np.ndarray:
    """Grid cell of each direction by searching the cell edges (not data.direction_cells' floor)."""
    edges = np.linspace(-1.0, 1.0, d + 1)[1:-1]
    return np.searchsorted(edges, w[:, 0], side="right") + d * np.searchsorted(edges, w[:, 1], side="right")


def test_swap_trained_marks_the_rows_whose_swapped_pair_is_not_held_out():
    spec = DataSpec(pairs=16, seed=3)
    rows = np.concatenate([chunk_queries(spec, 0, c) for c in range(spec.chunks_per_material())])
    held = heldout_cells(spec)
    ci, co = _cells(rows[:, 4:7], spec.directions), _cells(rows[:, 7:10], spec.directions)
    assert np.array_equal(held[ci, co], rows[:, 10] > 0.5)  # the edges give the generator's own cells
    expected = ~held[co, ci]
    assert np.array_equal(swap_trained(rows, spec), expected)
    assert 0.8 < expected.mean() < 0.97  # ~10 % of the swapped pairs are held out


def _reciprocal_data(n: int, spec: DataSpec) -> np.ndarray:
    """Rows of ``spec``'s queries with a label symmetric in wi and wo (a highlight in the half vector)."""
    q = np.concatenate([chunk_queries(spec, 0, c) for c in range(spec.chunks_per_material())])[:n]
    h = q[:, 4:7] + q[:, 7:10]
    hz = h[:, 2] / np.linalg.norm(h, axis=1)
    spec_val = 5.0 * np.exp(-(1.0 - hz) / 0.02) * q[:, 6] * q[:, 9]
    return np.column_stack([q, np.full(len(q), 0.3), spec_val, 0.5 * spec_val])


def test_training_sees_swapped_rows_only_on_trained_pairs_with_their_labels(monkeypatch):
    """A spy on every batch: each row seen is a training row or its swap, every seen (wi cell, wo cell) pair is
    trained, the label is the unswapped row's, and about half of the eligible rows come swapped."""
    import clothlab.surrogate.training as training

    spec = DataSpec(pairs=8, seed=1)
    data = _reciprocal_data(100_000, spec)
    seen = []
    original = training._batch

    def spy(surrogate, rows, *args):
        seen.append(np.array(rows))
        return original(surrogate, rows, *args)

    monkeypatch.setattr(training, "_batch", spy)
    ts = training.TrainSpec(width=8, spatial=8, enc_width=4, latent=4, batch=256, steps=20, reciprocal=True)
    result = training.train(data, NAMES, np.zeros((1, 2)), ts, encoding={"data_spec": spec.to_dict()})
    assert result.surrogate.encoding["reciprocal"] is True
    rows = np.concatenate(seen)
    held = heldout_cells(spec)
    assert not held[_cells(rows[:, 4:7], 8), _cells(rows[:, 7:10], 8)].any()
    by_key = {tuple(np.round(r[[1, 2, 3, 4, 5, 7, 8]], 12)): r for r in data}
    swapped = 0
    for r in rows:
        plain = by_key.get(tuple(np.round(r[[1, 2, 3, 4, 5, 7, 8]], 12)))
        if plain is None:  # a swapped row: its original has wo where it has wi
            plain = by_key[tuple(np.round(np.r_[r[1:4], r[7:9], r[4:6]], 12))]
            np.testing.assert_array_equal(r[7:10], plain[4:7])
            swapped += 1
        np.testing.assert_array_equal(r[11:], plain[11:])
    eligible = np.mean(~held[_cells(data[:, 7:10], 8), _cells(data[:, 4:7], 8)][data[:, 10] < 0.5])
    assert abs(swapped / len(rows) - 0.5 * eligible) < 0.05


def test_check_reciprocal_refuses_a_model_that_is_not_and_passes_the_irawan_model():
    from clothlab.models.registry import build_model
    from clothlab.surrogate.labels import ModelLabels
    from clothlab.surrogate.training import check_reciprocal
    from clothlab.weave.presets import get_preset

    def lopsided(wi, wo, centre, size):
        return np.column_stack([wi[:, 2], wo[:, 2] ** 2, np.ones(len(wi))])

    with pytest.raises(ValueError, match="reflectance model of material 0 changes"):
        check_reciprocal([lopsided], "reflectance model")
    model = build_model("irawan", get_preset("cotton-twill"))
    check_reciprocal([ModelLabels(model, model.resolve({}))], "reflectance model")


def test_cli_reciprocal_reaches_the_spec_and_the_sidecar(tmp_path):
    from clothlab.cli.main import main

    out = tmp_path / "run"
    assert main(["train-surrogate", "preset:silk-shantung", "-o", str(out), "--budget", "0.02", "--labels", "model",
                 "--pairs", "4", "--width", "8", "--spatial", "8", "-q", "--residual", "--reciprocal"]) == 0
    assert json.loads((out / "surrogate.json").read_text())["encoding"]["reciprocal"] is True
    assert json.loads((out / "training.json").read_text())["train_spec"]["reciprocal"] is True
