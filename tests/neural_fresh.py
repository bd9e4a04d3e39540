"""Shared check of shipped multi-material networks against fresh labels (tests/test_neural_*.py)."""

from __future__ import annotations

import numpy as np


def relative_rmse(pred: np.ndarray, label: np.ndarray) -> float:
    """Relative RMSE of f, the components summed (unit coefficients)."""
    f, g = pred.sum(axis=1), label.sum(axis=1)
    return float(np.sqrt(np.sum((f - g) ** 2) / np.sum(g ** 2)))


def assert_agrees_with_fresh_labels(surrogate, sidecar: dict, material: int, model, params: dict, recorded) -> None:
    """Fresh whole-tile-split MC-256 labels of ``model`` at ``params`` (seed 11; the training labels used
    another seed) on 150 held-out-pair queries of ``material`` per range: relative RMSE of f at 0.12-1 and
    1-5 tiles within 1.5x the largest error ``recorded`` (sidecar metric bins) has in that range."""
    from clothlab.surrogate.data import DataSpec, heldout_queries
    from clothlab.surrogate.labels import ModelLabels, TextureMonteCarloLabels

    labels = TextureMonteCarloLabels(model.texture(seed=0), params, samples=256, seed=11,
                                     tile_average=ModelLabels(model, params))
    spec = DataSpec(**sidecar["encoding"]["data_spec"])
    for lo, hi in ((0.12, 1.0), (1.0, 5.0)):
        q = heldout_queries(spec, 150, seed=5, sizes=(lo, hi), material=material)
        wi, wo, centre, size = q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3]
        fresh = labels(wi, wo, centre, size)
        pred = surrogate.query(centre, size, wi, wo, material=material)
        bound = max(b["relative_rmse"] for b in recorded if b["size_lo"] >= lo - 1e-9 and b["size_hi"] <= hi + 1e-9)
        assert relative_rmse(pred, fresh) <= 1.5 * bound, (lo, hi)
