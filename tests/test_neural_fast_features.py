"""The compiled feature pass (clothlab.surrogate.fast_features) gives the numpy encodings' values
(Surrogate.reference_features: one-blob position and size, yarn-local features, direction features), for every
shipped per-fabric network's encoding and without yarn features, including centres outside the tile, sizes
outside the encoded range, bin-boundary ties of the periodic wrap and grazing directions."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.models.neural.model import SHIPPED, load_neural

NETWORKS = sorted(p.stem for p in SHIPPED.glob("*.npz"))


def _queries(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-3.0, 4.0, (n, 2))
    centre[:64, 0] = (np.arange(64) % 8 + 0.5) / 8 + 0.5  # u - c_j = +-0.5 exactly: the wrap's ties
    centre[64:128, 1] = np.arange(64) / 8.0  # cell and bin edges
    size = np.concatenate([[0.0, 0.01, 5.0, 7.5], rng.uniform(0.0, 6.0, n - 4)])
    theta = np.arccos(rng.uniform(0.0, 1.0, (2, n)))  # down to grazing
    phi = rng.uniform(0, 2 * np.pi, (2, n))
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    d[1, :10] = -d[0, :10] * np.array([1, 1, -1])  # wi + wo along the normal only
    return centre, size, d[0], d[1]


@pytest.mark.parametrize("name", NETWORKS)
@pytest.mark.parametrize("yarn", [True, False])
def test_compiled_features_equal_the_numpy_encodings(name, yarn):
    surrogate, _ = load_neural(SHIPPED / f"{name}.npz")
    if not yarn:
        surrogate.encoding = {**surrogate.encoding, "yarn_bins": 0}
    args = _queries(seed=len(name))
    fast = surrogate._base_features(*args)
    slow = surrogate.reference_features(*args)
    for a, b in zip(fast, slow, strict=True):
        assert a.dtype == b.dtype == surrogate.network.dtype and a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=2e-7, atol=1e-12)


def test_kernels_compile_uncached_where_no_cache_directory_is_writable(monkeypatch):
    import numba

    from clothlab.surrogate import fast_features

    real, seen = numba.njit, []

    def refusing(*args, **options):
        if args:  # numba's own use while compiling
            return real(*args, **options)
        seen.append(options.get("cache"))
        if options.get("cache"):
            raise RuntimeError("cannot cache function: no locator available for file")
        return real(**options)
    monkeypatch.setattr(numba, "njit", refusing)

    @fast_features.njit(cache=True)
    def twice(x):
        return 2.0 * x
    assert twice(1.5) == 3.0 and seen == [True, False]
