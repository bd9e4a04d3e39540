"""The ``neural`` bench section at a small size: three widths side by side, each figure positive and
consistent with the others, the cost per query the layer sizes' multiply-adds; the per-bin figures of the
shipped networks (:mod:`clothlab.studies.neural_bins`) at a small size, their timed calls cold."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.studies import neural, neural_bins


def test_neural_section_times_three_widths_in_one_run():
    f = neural.neural_speed(True, queries=4096, repeats=1)
    rows = f["widths"]
    assert [(r["width"], r["spatial"]) for r in rows] == list(neural.WIDTHS)
    assert [r["chosen"] for r in rows] == [ws == neural.CHOSEN for ws in neural.WIDTHS]
    for r in rows:
        w, s = r["width"], r["spatial"]
        macs = 24 * w + w * s + (s + 8) * w + 3 * w * w + w * 3  # fusion (latent part precomputed), angular
        assert r["kflop_per_query"] == 2 * macs / 1e3
        assert r["qps"] > 0 and r["qps_per_cpu_s"] > 0 and r["qps_one_worker"] > 0
        assert r["meets_target"] == (r["qps"] >= neural.TARGET_QPS)
    text = "\n".join(neural.lines(f))
    assert "64/32" in text and "target 1 M/s" in text


# ------------------------------------------------------------------- per-bin figures (issue 23, item 1)

SMALL = {"per_bin": 12, "samples": 256, "timing": 48, "repeats": 2, "materials": 2}


def test_equal_time_mse_interpolates_log_log_and_flags_a_surrogate_cheaper_than_one_sample():
    times, mses = [1.0, 4.0, 16.0], [8.0, 2.0, 0.5]  # MSE = 8 / t: the plain MC rate
    assert neural_bins.equal_time_mse(times, mses, 2.0) == (pytest.approx(4.0), False)
    assert neural_bins.equal_time_mse(times, mses, 32.0) == (pytest.approx(0.25), False)
    assert neural_bins.equal_time_mse(times, mses, 0.5) == (8.0, True)


@pytest.fixture(scope="module")
def shantung():
    path = dict(neural_bins.shipped_networks())["silk-shantung"]
    return neural_bins.network_figures("silk-shantung", path, quick=True, sizes=SMALL)


def test_every_shipped_network_is_benched():
    from clothlab.models.neural.model import SHIPPED

    names = [name for name, _ in neural_bins.shipped_networks()]
    assert names[:-1] == sorted(p.stem for p in SHIPPED.glob("*.npz")) and names[-1] == "surface-table2"


def test_per_bin_figures_are_per_bin_with_intervals_and_both_mc_baselines(shantung):
    rows = shantung["groups"][""]
    assert [(r["size_lo"], r["size_hi"]) for r in rows] == list(neural_bins.BINS)
    for r in rows:
        lo, hi = r["surrogate_interval"]
        assert lo <= r["surrogate"] <= hi and r["queries"] == SMALL["per_bin"]
        assert r["us_per_query"] > r["inputs_us"] > 0 and r["reference_noise"] < 0.2
        plain = {m["samples"]: m["mse"] for m in r["mc_plain"]}
        split = {m["samples"]: m["mse"] for m in r["mc_split"]}
        assert set(plain) == set(neural_bins.MC_SAMPLES) and plain[256] < plain[1]
        if r["size_hi"] <= 1.0:  # no whole tile: split MC is plain MC, point for point
            assert split == plain
        else:  # the whole-tile split needs two samples
            assert set(split) == set(neural_bins.MC_SAMPLES) - {1}
        for name in ("plain", "split"):
            assert r[f"ratio_{name}"] > 0
    text = "\n".join(neural_bins.lines([shantung]))
    assert "0.03-0.06" in text and "4-5" in text and "pooled" not in text


def test_timed_queries_meet_directions_no_model_has_seen(monkeypatch):
    """Each timed call (surrogate, its R share, MC) gets directions never handed to R before, and every
    direction memo is dropped before it: no memo can serve a timed call."""
    from clothlab.models.neural.model import load_neural
    from clothlab.surrogate.data import DataSpec

    surrogate, sidecar = load_neural(dict(neural_bins.shipped_networks())["silk-shantung"])
    seen, timed, forgets = set(), {"on": False, "calls": 0}, []

    class Recorder:
        def __init__(self, inner):
            self.inner, self.model, self.params = inner, inner.model, inner.params
            self.component_names = inner.component_names

        def __call__(self, wi, wo, centre, size):
            rows = {tuple(r) for r in np.atleast_2d(wi)}
            if timed["on"]:
                assert rows.isdisjoint(seen)
                timed["calls"] += 1
            seen.update(rows)
            return self.inner(wi, wo, centre, size)

    surrogate.references = [Recorder(r) for r in surrogate.references]
    material = neural_bins.Material(surrogate, sidecar, 0)
    monkeypatch.setattr(material.model, "forget_directions", lambda: forgets.append(timed["on"]))
    real = neural_bins.cold_time

    def flagged(call, materials, blocks_for, sur, repeats):
        def wrapped(m, block):
            timed["on"] = True
            try:
                return call(m, block)
            finally:
                timed["on"] = False
        return real(wrapped, materials, blocks_for, sur, repeats)
    monkeypatch.setattr(neural_bins, "cold_time", flagged)
    neural_bins.bin_figures(surrogate, [material], DataSpec(**sidecar["encoding"]["data_spec"]), 1.0, 4.0,
                            per_bin=8, samples=64, timing=16, repeats=2, seed=5, mc_samples=(1, 2, 4))
    assert timed["calls"] >= 2 * 2 + 2 * 2  # surrogate, R share, split MC-2, MC-4: two repeats each
    assert len(forgets) >= timed["calls"] and not any(forgets)  # dropped before (outside) each timed call
