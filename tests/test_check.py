"""clothlab check and the stiff-fit study: the stability claims and that the detectors detect."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from clothlab.studies import stability as check
from clothlab.studies.stiff import FAST_POSTERIOR, conditioning, run_case, stiff_cases, stiff_lines


def test_fast_check_finds_no_non_finite_negative_or_non_reciprocal_value(tmp_path):
    lines = []
    code = check.run_check_command(full=False, seed=3, data_dir=None, output=tmp_path / "report",
                                   json_path=tmp_path / "check.json", emit=lines.append)
    assert code == 0
    result = json.loads((tmp_path / "check.json").read_text())
    t = result["totals"]
    assert t["configurations"] > 50_000
    assert t["non_finite"] == t["negative"] == t["reciprocity"] == t["exceptions"] == 0
    assert t["back_facing_nonzero"] == 0
    assert result["verdict"]["passed"] and check.exit_code(result) == 0
    assert (tmp_path / "report" / "index.html").is_file()
    assert any(line.startswith("verdict: PASS") for line in lines)
    assert f"  total: {t['configurations']:,d} configurations; non-finite 0, negative 0" in "\n".join(lines)
    rows = {(r["sweep"], r["rule"]): r for r in result["continuity"]}
    # the unsmoothed filament cutoff |u| = umax is a true discontinuity: it must be found
    assert rows[("umax, filament delta 0 (unsmoothed cutoff)", "support-8")]["jumps"] > 0
    # the spine radius R(u) is continuous in kappa (sec. 5.4): no jump with the support rule
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


@pytest.mark.parametrize("key", ["non_finite", "negative", "reciprocity", "exceptions"])
def test_verdict_fails_on_any_finding(key):
    clean = {"configurations": 10, "non_finite": 0, "negative": 0, "back_facing_nonzero": 0, "reciprocity": 0,
             "exceptions": 0}
    assert check.verdict(clean) == {**check.verdict(clean), "passed": True, "failures": {}}
    assert check.exit_code({"totals": clean}) == 0
    v = check.verdict({**clean, key: 3})
    assert not v["passed"] and v["failures"] == {key: 3}
    assert check.exit_code({"totals": {**clean, key: 3}}) == 1


def test_run_check_exit_code_is_1_when_the_sweep_finds_a_problem(monkeypatch):
    """run_check records the verdict of its sweep; one non-finite value makes ``clothlab check`` exit 1; the lines
    of each part are emitted as the part finishes, in order."""
    real = check.sweep_extremes

    def one_nan(parameter_sets, wi, wo, rule, max_examples=5):
        counts = real(parameter_sets[:2], wi, wo, rule, max_examples)
        return {**counts, "non_finite": counts["non_finite"] + (rule == check.RULES_CHECKED[0])}

    monkeypatch.setattr(check, "sweep_extremes", one_nan)
    monkeypatch.setattr(check, "continuity_study", lambda *a, **k: [])
    monkeypatch.setattr(check, "psi_threshold_jump", lambda *a, **k: [])
    parts = []
    result = check.run_check(full=False, seed=1, on_part=lambda name, partial: parts.append((name, set(partial))))
    assert [name for name, _ in parts] == ["start", "extremes", "continuity", "psi_threshold", "verdict"]
    assert "totals" in parts[1][1] and "continuity" not in parts[1][1]  # called when the part is done, not later
    assert result["totals"]["non_finite"] == 2  # grid and random part of the first rule
    assert result["verdict"] == {**result["verdict"], "passed": False, "failures": {"non_finite": 2}}
    assert check.exit_code(result) == 1
    lines = []
    assert check.run_check_command(full=False, seed=1, data_dir=None, output=None, json_path=None,
                                   emit=lines.append) == 1
    assert "verdict: FAIL (non-finite 2)" in lines
    assert lines[0].startswith("clothlab check (fast subset, seed 1)")
    assert lines == check.check_lines(result)[:len(lines) - 1] + [lines[-1]]  # same text, only the time differs


def test_one_stiff_case_quickly():
    """A stiff case end to end with small budgets: the outcome fields the report shows are all there and sane."""
    case = run_case(stiff_cases()[1], perturbed=1, max_evals=300, posterior=FAST_POSTERIOR)
    free = case["free"]
    assert len(free) == 6
    assert math.isfinite(case["condition"]) and case["condition"] >= 1.0
    assert math.isfinite(case["at_truth"]["condition"])
    assert isinstance(case["recovered_default"], bool) and case["recovered_default"] == case["fits"][0]["recovered"]
    assert len(case["recovered_perturbed"]) == 1 and all(isinstance(r, bool) for r in case["recovered_perturbed"])
    post = case["posterior"]
    assert post["names"] == free  # Gaussian likelihood (simulated sigma): no noise coordinate
    corr = np.array(post["correlation"])
    assert corr.shape == (6, 6) and np.isfinite(corr).all()
    np.testing.assert_array_equal(corr, corr.T)
    assert np.all(np.abs(corr) <= 1.0) and np.all(np.diag(corr) == 1.0)
    strengths = [abs(p["r"]) for p in post["strongest_pairs"]]
    assert len(strengths) >= 3 and strengths == sorted(strengths, reverse=True)
    assert post["steps"] == FAST_POSTERIOR["steps"] and post["walkers"] == FAST_POSTERIOR["walkers"]
    assert case["strongest_correlations"] == post["strongest_text"]
    text = "\n".join(stiff_lines({"seed": 0, "cases": [case]}))
    assert case["name"] in text and post["strongest_text"] in text


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
    assert check.exit_code(result) == 0
    polyester = next(c for c in result["stiff"]["cases"] if c["preset"] == "polyester-lining")
    assert polyester["fits"][0]["recovered"]
    for case in result["stiff"]["cases"]:
        corr = np.array(case["posterior"]["correlation"])
        np.testing.assert_array_equal(corr, corr.T)
