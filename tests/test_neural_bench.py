"""The ``neural`` bench section at a small size: three widths side by side, each figure positive and
consistent with the others, the cost per query the layer sizes' multiply-adds."""

from __future__ import annotations

from clothlab.studies import neural


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
