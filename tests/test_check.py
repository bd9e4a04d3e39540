"""clothlab check and the stiff-fit study: the stability claims and that the detectors detect."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clothlab import check
from clothlab.stiff import conditioning


def test_fast_check_finds_no_non_finite_negative_or_non_reciprocal_value(tmp_path):
    result = check.run_check(full=False, json_path=tmp_path / "check.json", seed=3)
    t = result["totals"]
    assert t["configurations"] > 50_000
    assert t["non_finite"] == t["negative"] == t["reciprocity"] == t["exceptions"] == 0
    assert t["back_facing_nonzero"] == 0
    assert (tmp_path / "check.json").is_file()
    rows = {(r["sweep"], r["rule"]): r for r in result["continuity"]}
    # the unsmoothed filament cutoff |u| = umax is a true discontinuity (numerics.md): it must be found
    assert rows[("umax, filament delta 0 (unsmoothed cutoff)", "support-8")]["jumps"] > 0
    # R(u) is continuous in kappa (spine.py): no jump with the support rule
    assert rows[("kappa, staple", "support-8")]["jumps"] == 0
    assert rows[("kappa, filament", "support-8")]["jumps"] == 0


def test_sweep_counts_injected_problems(monkeypatch):
    """The counters see a NaN, a negative value and an asymmetric value when the model produces them."""
    wi = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, 0.6, 0.8]])
    wo = np.array([[0.0, 0.6, 0.8], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])

    def fake(a, b, params, rule):
        out = np.array([1.0, -2.0, np.nan])
        return out if a is wi else np.array([1.0 + 1e-6, -2.0, np.nan])

    monkeypatch.setattr(check, "_evaluate", fake)
    counts = check.sweep_extremes([{"x": 1}], wi, wo, ("trapezoid", 11))
    assert counts["configurations"] == 3
    assert counts["non_finite"] == 1 and counts["negative"] == 1
    assert counts["reciprocity"] == 2  # the 1e-6 change and the NaN
    assert counts["examples"]


def test_kappa_parabola_makes_r_hat_zero():
    for umax in (5.0, 30.0, 80.0):
        k = check.kappa_parabola(umax)
        assert abs(1.0 + k * (1.0 + 1.0 / math.tan(math.radians(umax)))) < 1e-12


def test_conditioning_of_known_matrices():
    diag = np.diag([10.0, 2.0, 0.5])
    c = conditioning(diag, ["a", "b", "c"])
    assert c["condition"] == pytest.approx(20.0)
    assert c["collinear_pairs"] == []
    assert c["weakest_parameters"] == ["c"]
    rng = np.random.default_rng(0)
    base = rng.standard_normal((50, 2))
    jac = np.column_stack([base[:, 0], base[:, 1], 2.0 * base[:, 0] + 1e-4 * rng.standard_normal(50)])
    c = conditioning(jac, ["a", "b", "c"])
    assert [(p[0], p[1]) for p in c["collinear_pairs"]] == [("a", "c")]
    assert c["condition"] > 1e3
    assert set(c["weakest_parameters"]) == {"a", "c"}


@pytest.mark.slow
def test_full_check_and_stiff_fits():
    result = check.run_check(full=True, seed=0)
    t = result["totals"]
    assert t["configurations"] >= 2_000_000  # >= 10^6 per rule, two rules
    assert t["non_finite"] == t["negative"] == t["reciprocity"] == t["exceptions"] == 0
    polyester = next(c for c in result["stiff"]["cases"] if c["preset"] == "polyester-lining")
    assert polyester["fits"][0]["recovered"]
