"""The noise floor from repeated and reciprocal direction pairs (issue 28 item 7, clothlab.fit.noise_floor):
on simulated tables with known noise the scatter is recovered within 20 %, and a table without pairs says so."""

from __future__ import annotations

import numpy as np
import pytest

from clothlab.fit.noise_floor import above_floor, direction_pairs, floor_sentence, noise_floor
from clothlab.models.registry import build_model
from clothlab.simulate.gonio import NoiseModel, paper_sampling, simulate
from clothlab.weave.presets import get_preset

RNG = np.random.default_rng(11)


def _random_sampling(n):
    return (RNG.uniform(0, 75, n), RNG.uniform(0, 360, n), RNG.uniform(0, 75, n), RNG.uniform(0, 360, n))


def _table(model, params, coef, sampling, seed, sigma):
    m = simulate(model, params, coef, channels=("grey",), noise=NoiseModel(multiplicative=sigma, seed=seed),
                 sampling=sampling)
    return m.theta_i, m.phi_i, m.theta_o, m.phi_o, m.values


@pytest.mark.parametrize("sigma", [0.02, 0.05, 0.10])
def test_repeats_of_a_simulated_cloth_table_recover_the_noise(sigma):
    """The IM model (wool-gabardine) measured twice at the paper's 1575 directions, independent 'sigma'
    multiplicative noise each time: the estimate is within 20 % of sigma."""
    model = build_model("irawan", get_preset("wool-gabardine"))
    sampling = paper_sampling()
    a = _table(model, {}, {"kd": [0.3], "ks_warp": [0.2], "ks_weft": [0.2]}, sampling, 1, sigma)
    b = _table(model, {}, {"kd": [0.3], "ks_warp": [0.2], "ks_weft": [0.2]}, sampling, 2, sigma)
    cols = [np.concatenate([x, y]) for x, y in zip(a, b, strict=True)]
    out = noise_floor(*cols)
    assert out["repeats"] >= 1575 and out["reciprocal"] >= 0
    assert abs(out["sigma"] - sigma) < 0.2 * sigma
    assert out["floor"]["p50"] == pytest.approx(0.6745 * out["sigma"], rel=1e-4)


def test_reciprocal_pairs_recover_the_noise():
    """A reciprocal model (Lambert) measured at random (w_i, w_o) and at the swapped (w_o, w_i): 5 % noise
    recovered within 20 % from the reciprocal pairs alone."""
    model = build_model("lambert", get_preset("wool-gabardine"))
    ti, pi_, to, po = _random_sampling(400)
    a = _table(model, {}, {"kd": [0.4]}, (ti, pi_, to, po), 3, 0.05)
    b = _table(model, {}, {"kd": [0.4]}, (to, po, ti, pi_), 4, 0.05)
    cols = [np.concatenate([x, y]) for x, y in zip(a, b, strict=True)]
    out = noise_floor(*cols)
    assert out["repeats"] == 0 and out["reciprocal"] >= 400
    assert abs(out["sigma"] - 0.05) < 0.01


def test_a_table_without_pairs_says_so():
    ti, pi_, to, po = _random_sampling(200)
    out = noise_floor(ti, pi_, to, po, RNG.uniform(0.1, 1.0, 200))
    assert out["pairs"] == 0 and "sigma" not in out and "cannot be estimated" in out["note"]
    assert floor_sentence(out, {"p50": 0.05}, "held out") == out["note"]
    assert above_floor(out, {"p50": 0.05}) is None


def test_pairs_need_both_directions_within_the_tolerance():
    """Row 1 repeats row 0 at 0.3 deg, row 2 is 1 deg away in theta_o (no pair), row 3 is row 0 swapped."""
    rep, rec = direction_pairs([30.0, 30.3, 30.0, 40.0], [10.0, 10.0, 10.0, 200.0], [40.0, 40.0, 41.0, 30.0],
                               [200.0, 200.0, 200.0, 10.0])
    assert rep == [(0, 1)] and rec == [(0, 3), (1, 3)]


def test_the_ratio_over_the_floor():
    floor = {"sigma": 0.02, "n_differences": 10, "repeats": 10, "reciprocal": 0,
             "floor": {"p50": 0.6745 * 0.02, "p80": 1.2816 * 0.02}}
    ratio = above_floor(floor, {"p50": 0.0539, "p80": 0.1025})
    assert ratio["p50"] == pytest.approx(0.0539 / 0.01349, rel=1e-6)
    assert "4.0 x above the noise floor" in floor_sentence(floor, {"p50": 0.0539, "p80": 0.1025}, "held out")


def test_report_section_puts_the_floor_next_to_the_nested_error():
    from clothlab.report import html

    floor = {"sigma": 0.02, "n_differences": 10, "repeats": 10, "reciprocal": 0, "rule": "r",
             "floor": {"p50": 0.01349, "p80": 0.02563}}
    fit = {"selection": {"nested": {"held_out": {"p50": 0.0539, "p80": 0.1025}}}}
    text = "".join(html._noise_floor_section(fit, floor, {"overall": {"p50": 0.01, "p80": 0.02}}))
    assert "4.0 x above the noise floor" in text and "nested CV" in text
    none = "".join(html._noise_floor_section({}, {"pairs": 0, "note": "no repeated or reciprocal pairs"}, {}))
    assert "no repeated or reciprocal" in none
