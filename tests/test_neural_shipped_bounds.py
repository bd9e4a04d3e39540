"""Every shipped network against fresh labels of its own texture model, in every footprint bin of the bench
(clothlab.studies.neural_bins.accuracy_figures: fresh held-out queries, a stratified texture reference that
does not use R, fixed seeds): its relative RMSE of f must stay within the bound docs/neural.md states for
it (``neural_bins.ERROR_BOUNDS``).  Nothing is timed."""

from __future__ import annotations

import pytest

from clothlab.studies import neural_bins

NETWORKS = neural_bins.shipped_networks()


def test_every_shipped_network_has_documented_bounds_for_every_bin():
    assert {name for name, _ in NETWORKS} == set(neural_bins.ERROR_BOUNDS)
    for name, groups in neural_bins.ERROR_BOUNDS.items():
        for group, bounds in groups.items():
            assert len(bounds) == len(neural_bins.BINS), (name, group)


@pytest.mark.parametrize(("name", "path"), NETWORKS, ids=[name for name, _ in NETWORKS])
def test_shipped_network_error_in_every_bin_is_within_its_documented_bound(name, path):
    figures = neural_bins.accuracy_figures(path, **neural_bins.BOUND_CHECK)
    bounds = neural_bins.ERROR_BOUNDS[name]
    assert set(figures) == set(bounds)
    for group, values in figures.items():
        for (lo, hi), value, bound in zip(neural_bins.BINS, values, bounds[group], strict=True):
            assert value <= bound, f"{name} {group or ''} {lo:g}-{hi:g} tiles: {value:.3f} > {bound}"
