"""Posterior sampling: the likelihood against an independent computation, seeded reproducibility, resume after
an interrupt (same chain), atomic checkpoints, coverage of the 95 % intervals on the noisy simulated sets,
identifiability flags, the log-normal noise scale, predictive bands and the JSON / corner outputs."""

from __future__ import annotations

import json
import logging
import os
import signal
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import nnls

from clothlab.config import load_config
from clothlab.errors import InputError
from clothlab.fit.optimize import minimize
from clothlab.fit.posterior import NOISE_NAME, _Likelihood, run_posterior
from clothlab.fit.problem import FitProblem
from clothlab.fit.runner import build_problem
from clothlab.studies.posterior import coverage_study

ROOT = Path(__file__).resolve().parents[1]
FABRICS = ("cotton-denim", "silk-shantung", "silk-charmeuse", "cotton-twill", "wool-gabardine", "polyester-lining")
FAST = {"walkers": 8, "steps": 60, "max_steps": 60, "check_every": 20, "progress": False}


@cache
def _full(fabric: str):
    return build_problem(load_config(ROOT / "measurements" / fabric / "fabric.yaml"))


def _problem(fabric="polyester-lining", free=("warp.umax", "beta"), every=3, sigma_scale=1.0, drop_sigma=False):
    """A cheap problem: every ``every``-th row of the noisy set, a few free parameters, the rest at the truth."""
    full = _full(fabric)
    m = full.measurement.subset(np.arange(full.measurement.n)[::every])
    if drop_sigma:
        m = replace(m, sigma=None)
    elif sigma_scale != 1.0:
        m = replace(m, sigma=m.sigma * sigma_scale)
    truth = {k: m.provenance["parameters"][k] for k in full.start}
    bounds = {n: (lo, hi) for n, lo, hi in zip(full.free, full.lower, full.upper, strict=True)}
    return FitProblem(full.model, m, free, truth, bounds, "relative"), truth


def _optimum(problem, start):
    """A local optimum of the fit objective near ``start`` (what the posterior starts from in practice)."""
    k = len(problem.free)
    res = minimize(problem, problem.to_unit(start), np.zeros(k), np.ones(k), global_algorithm=None,
                   local_algorithm="LN_BOBYQA", max_evals=150)
    return problem.from_unit(res.x)


def test_gaussian_log_likelihood_matches_an_independent_computation():
    problem, truth = _problem()
    like = _Likelihood(problem)
    X = np.array([problem.to_unit(truth), problem.to_unit({**truth, "warp.umax": 25.0, "beta": 5.0})])
    got = like(X)
    m = problem.measurement
    for x, value in zip(X, got, strict=True):
        A = problem.design(problem.from_unit(x))
        expected = 0.0
        for c in range(m.values.shape[1]):  # scipy's NNLS on the sigma-weighted system, channel by channel
            w = 1.0 / m.sigma[:, c]
            coef, _ = nnls(A * w[:, None], m.values[:, c] * w)
            expected -= 0.5 * np.sum(((m.values[:, c] - A @ coef) * w) ** 2)
        assert value == pytest.approx(expected, rel=1e-9)
    assert got[0] > got[1]
    outside = X[:1].copy()
    outside[0, 0] = 1.0 + 1e-9
    assert like(outside)[0] == -np.inf


def _scalar_log_likelihood(problem, params, noise_s=None):
    """The log-likelihood of one walker computed on its own: the design from the one-set quadrature loop
    (yarn_specular), scipy's NNLS per channel, the literal Gaussian / log-normal sum."""
    from clothlab.models.irawan.model import yarn_specular

    p = problem.model.resolve(params)
    wi, wo = problem.wi, problem.wo
    front = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    A = np.stack([np.where(front, 1.0 / np.pi, 0.0)] + [yarn_specular(wi, wo, p, kind, problem.model.quadrature)
                                                        for kind in ("warp", "weft")], axis=1)
    y, sigma = problem.y, problem.measurement.sigma
    total = 0.0
    for c in range(y.shape[1]):
        w = 1.0 / (sigma[:, c] if noise_s is None else y[:, c])
        coef, _ = nnls(A * w[:, None], y[:, c] * w)
        if noise_s is None:
            total -= 0.5 * np.sum(((y[:, c] - A @ coef) * w) ** 2)
        else:
            r = np.log(np.maximum(A @ coef, 1e-6 * y[:, c]) / y[:, c])
            total -= 0.5 * np.sum(r**2) / noise_s**2 + r.size * np.log(noise_s)
    return total


@pytest.mark.parametrize("fabric, free", [("polyester-lining", ("warp.umax", "weft.kappa", "beta")),
                                          ("cotton-denim", ("warp.psi", "weft.umax", "alpha"))])
@pytest.mark.parametrize("drop_sigma", [False, True])
def test_batched_likelihood_equals_the_scalar_path(fabric, free, drop_sigma):
    """All walkers in one call (one model call, one NNLS call) give each walker's log-likelihood computed on
    its own (per-set quadrature loop, scipy NNLS, literal sum) to 1e-12 relative."""
    from clothlab.fit.metrics import LOG_FLOOR

    assert LOG_FLOOR == 1e-6  # the floor written into _scalar_log_likelihood
    problem, truth = _problem(fabric, free, every=5, drop_sigma=drop_sigma)
    like = _Likelihood(problem)
    rng = np.random.default_rng(11)
    X = np.clip(np.append(problem.to_unit(truth), 0.4)[None, :like.ndim]
                + 0.05 * rng.standard_normal((6, like.ndim)), 0.0, 1.0)
    got = like(X)
    for x, value in zip(X, got, strict=True):
        s = like.noise_scale(x[-1]) if drop_sigma else None
        expected = _scalar_log_likelihood(problem, problem.from_unit(x[:like.k]), s)
        assert value == pytest.approx(expected, rel=1e-12)
    assert len(set(got.tolist())) == len(got)  # distinct walkers, distinct values (the test can fail)


def test_lognormal_likelihood_and_noise_scale():
    """Without sigma the noise scale s is sampled; its posterior median is the rms log residual (its MLE)."""
    problem, truth = _problem(drop_sigma=True)
    like = _Likelihood(problem)
    assert like.ndim == 3 and like.names[-1] == NOISE_NAME
    A = problem.design(truth)
    y = problem.y
    coef = np.stack([nnls(A / y[:, [c]], np.ones(len(y)))[0] for c in range(y.shape[1])], axis=1)
    r = np.log((A @ coef) / y)
    s = 0.05
    x_s = (np.log(s) - np.log(1e-4)) / (np.log(2.0) - np.log(1e-4))
    value = like(np.append(problem.to_unit(truth), x_s)[None])[0]
    assert value == pytest.approx(-0.5 * np.sum(r**2) / s**2 - r.size * np.log(s), rel=1e-9)

    post = run_posterior(problem, _optimum(problem, truth), seed=2, **FAST)
    rms = float(np.sqrt(np.mean(r**2)))
    assert post.percentiles()[NOISE_NAME]["median"] == pytest.approx(rms, rel=0.1)
    assert NOISE_NAME in post.to_json()["parameters"]


def test_same_seed_same_chain_other_seed_other_chain():
    problem, truth = _problem()
    a = run_posterior(problem, truth, seed=5, **FAST)
    b = run_posterior(problem, truth, seed=5, **FAST)
    c = run_posterior(problem, truth, seed=6, **FAST)
    assert a.chain.shape == (60, 8, 2)
    np.testing.assert_array_equal(a.chain, b.chain)
    np.testing.assert_array_equal(a.log_prob, b.log_prob)
    assert not np.array_equal(a.chain, c.chain)
    assert np.isfinite(a.log_prob).all()
    assert 0.0 < np.mean(a.acceptance) < 1.0


@pytest.mark.parametrize("how", ["exception", "sigint"])
def test_interrupted_run_resumes_to_the_same_chain(tmp_path, how):
    problem, truth = _problem()
    reference = run_posterior(problem, truth, seed=7, **FAST)
    checkpoint = tmp_path / "posterior.npz"

    def interrupt(step):
        if step == 37:  # mid-chunk (checks every 20 steps)
            if how == "sigint":
                signal.raise_signal(signal.SIGINT)
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, on_step=interrupt, **FAST)
    with np.load(checkpoint) as z:
        assert z["chain"].shape == (37, 8, 2)
        np.testing.assert_array_equal(z["chain"], reference.chain[:37])
    resumed = run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    assert resumed.resumed_from == 37
    np.testing.assert_array_equal(resumed.chain, reference.chain)
    np.testing.assert_array_equal(resumed.log_prob, reference.log_prob)
    np.testing.assert_array_equal(resumed.acceptance, reference.acceptance)
    assert resumed.to_json()["parameters"] == reference.to_json()["parameters"]


def test_checkpoint_never_half_written(tmp_path, monkeypatch):
    """An interrupt while the second checkpoint is being replaced leaves the first one intact and readable."""
    problem, truth = _problem()
    checkpoint = tmp_path / "posterior.npz"
    real_replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        calls.append(dst)
        if len(calls) >= 2:  # also the save attempted on the way out
            raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    monkeypatch.setattr(os, "replace", real_replace)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["posterior.npz"]  # no temporary file left
    with np.load(checkpoint) as z:
        assert z["chain"].shape[0] == 20
    resumed = run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    np.testing.assert_array_equal(resumed.chain, run_posterior(problem, truth, seed=7, **FAST).chain)


def test_checkpoint_from_other_settings_is_refused(tmp_path):
    problem, truth = _problem()
    checkpoint = tmp_path / "posterior.npz"
    run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    with pytest.raises(InputError, match="seed"):
        run_posterior(problem, truth, seed=8, checkpoint_path=checkpoint, **FAST)
    checkpoint.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="unreadable"):
        run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)


@pytest.fixture
def warnings_logged(caplog, monkeypatch):
    """Log records of clothlab at WARNING and above, even after ``clothlab.progress.configure`` (which stops
    propagation to the root logger that caplog listens to)."""
    monkeypatch.setattr(logging.getLogger("clothlab"), "propagate", True)
    caplog.set_level(logging.WARNING, logger="clothlab")
    return caplog


def test_checkpoint_of_another_quadrature_rule_starts_afresh(tmp_path, warnings_logged):
    """The fingerprint covers the model's quadrature: a rerun with another rule (another likelihood) must not
    continue the old chain; it starts a new one, says so, and that new chain is resumable in turn."""
    from clothlab.models.irawan.model import IrawanModel, Quadrature

    problem, truth = _problem()
    checkpoint = tmp_path / "posterior.npz"
    run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    other = FitProblem(IrawanModel(problem.model.weave, Quadrature("support", 8)), problem.measurement,
                       problem.free, problem.start, dict(zip(problem.free, zip(problem.lower, problem.upper,
                                                                                strict=True), strict=True)),
                       problem.metric)
    warnings_logged.clear()
    fresh = run_posterior(other, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    assert fresh.resumed_from == 0
    message = warnings_logged.text
    assert "belongs to another fit" in message and "model" in message
    assert any("belongs to another fit" in w and "model" in w for w in fresh.warnings)
    np.testing.assert_array_equal(fresh.chain, run_posterior(other, truth, seed=7, **FAST).chain)
    assert run_posterior(other, truth, seed=7, checkpoint_path=checkpoint, **FAST).resumed_from == 60


def test_checkpoint_from_another_optimum_starts_afresh(tmp_path, warnings_logged):
    problem, truth = _problem()
    checkpoint = tmp_path / "posterior.npz"
    run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    moved = {**truth, "beta": truth["beta"] * 1.01}
    post = run_posterior(problem, moved, seed=7, checkpoint_path=checkpoint, **FAST)
    assert post.resumed_from == 0
    assert "optimum" in warnings_logged.text
    # the same optimum again: resumed (the rounding of the recorded optimum does not break an exact rerun)
    assert run_posterior(problem, moved, seed=7, checkpoint_path=checkpoint, **FAST).resumed_from == 60


def test_coverage_short():
    """95 % intervals contain the generating value for >= 90 % of the free parameters (six noisy sets, two
    free parameters each, a third of the directions, short chains started at a local optimum)."""
    covered = []
    for fabric in FABRICS:
        problem, truth = _problem(fabric, free=("warp.umax", "weft.umax"))
        post = run_posterior(problem, _optimum(problem, truth), seed=1, walkers=8, steps=150, max_steps=150,
                             check_every=50, progress=False)
        for name, q in post.percentiles().items():
            covered.append(q["p2.5"] <= truth[name] <= q["p97.5"])
    assert np.mean(covered) >= 0.9, covered


@pytest.mark.slow
def test_coverage_full_six_fabrics():
    study = coverage_study()
    assert study["fraction"] >= 0.9, study


def test_identifiability_flags():
    """Data with a million-fold sigma say nothing: the posterior spans the prior and both parameters are flagged;
    with the real sigma they are determined; an optimum at a bound is flagged as such."""
    problem, truth = _problem(sigma_scale=1e6, every=15)
    post = run_posterior(problem, truth, seed=3, walkers=8, steps=250, max_steps=250, check_every=50,
                         progress=False)
    assert set(post.not_determined()) == {"warp.umax", "beta"}
    assert any("spans" in r for r in post.identifiability()["warp.umax"])
    sharp, _ = _problem()
    post = run_posterior(sharp, truth, seed=3, **FAST)
    assert post.not_determined() == []
    at_bound = {**truth, "warp.umax": float(sharp.lower[0])}
    post = run_posterior(sharp, at_bound, seed=3, **FAST)
    assert "optimum at the lower bound" in post.identifiability()["warp.umax"]
    assert "warp.umax" in post.to_json()["not_determined"]


def test_predictive_bands_and_outputs():
    problem, truth = _problem()
    post = run_posterior(problem, truth, seed=4, **FAST)
    m = problem.measurement
    bands = post.predictive_bands(m.wi[:50], m.wo[:50], draws=40)
    assert bands["p5"].shape == (50, 3) and bands["draws"] == 40
    assert np.all(bands["p5"] <= bands["p50"]) and np.all(bands["p50"] <= bands["p95"])
    at_truth = problem.solve(truth).prediction[:50]  # the bands are narrow and centred near the truth's model
    np.testing.assert_allclose(bands["p50"], at_truth, rtol=0.02, atol=1e-6)
    summary = post.to_json()
    text = json.dumps(summary, allow_nan=False)
    assert "uniform" in summary["prior"] and "profiled" in summary["coefficients"]
    entry = summary["parameters"]["beta"]
    assert entry["p2.5"] <= entry["p16"] <= entry["median"] <= entry["p84"] <= entry["p97.5"]
    assert entry["truth"] == truth["beta"] and "truth_in_95" in entry
    corr = np.array(summary["correlation"]["matrix"])
    np.testing.assert_allclose(np.diag(corr), 1.0)
    np.testing.assert_allclose(corr, corr.T)
    assert summary["convergence"]["walkers"] == 8 and '"tau"' in text
    fig = post.corner_figure()
    import matplotlib.pyplot as plt

    assert len(fig.axes) == 4
    plt.close(fig)


@pytest.mark.parametrize("changed", ["values", "sigma", "incident", "exitant"])
def test_checkpoint_of_other_data_starts_afresh(tmp_path, warnings_logged, changed):
    """The fingerprint covers every data array of the likelihood: the measured values, their sigma and both
    directions.  The same rows with one of them changed (values and sigma scaled by 1.01, an azimuth turned
    by 10 deg) define another target, so a rerun must not continue the old chain (issue 25: a fingerprint
    omitting wo survived)."""
    problem, truth = _problem()
    m = problem.measurement
    checkpoint = tmp_path / "posterior.npz"
    run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    other = {"values": {"values": m.values * 1.01}, "sigma": {"sigma": m.sigma * 1.01},
             "incident": {"phi_i": (m.phi_i + 10.0) % 360.0}, "exitant": {"phi_o": (m.phi_o + 10.0) % 360.0}}
    moved = FitProblem(problem.model, replace(m, **other[changed]), problem.free, problem.start,
                       dict(zip(problem.free, zip(problem.lower, problem.upper, strict=True), strict=True)),
                       problem.metric)
    warnings_logged.clear()
    fresh = run_posterior(moved, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    assert fresh.resumed_from == 0
    assert "belongs to another fit (differs in: data)" in warnings_logged.text
    assert run_posterior(moved, truth, seed=7, checkpoint_path=checkpoint, **FAST).resumed_from == 60


def test_checkpoint_of_another_rule_with_the_same_nodes_or_a_slightly_moved_optimum_starts_afresh(
        tmp_path, warnings_logged):
    """The fingerprint records the quadrature rule itself (the same node count under another rule is another
    likelihood) and the optimum to 10 significant digits (an optimum moved by a relative 1e-6, as a changed fit
    budget moves it, is another starting point)."""
    from clothlab.models.irawan.model import IrawanModel, Quadrature

    problem, truth = _problem()
    assert problem.model.quadrature.rule == "trapezoid"
    checkpoint = tmp_path / "posterior.npz"
    run_posterior(problem, truth, seed=7, checkpoint_path=checkpoint, **FAST)
    gauss = FitProblem(IrawanModel(problem.model.weave, Quadrature("gauss", problem.model.quadrature.nodes)),
                       problem.measurement, problem.free, problem.start,
                       dict(zip(problem.free, zip(problem.lower, problem.upper, strict=True), strict=True)),
                       problem.metric)
    warnings_logged.clear()
    assert run_posterior(gauss, truth, seed=7, checkpoint_path=checkpoint, **FAST).resumed_from == 0
    assert "(differs in: model)" in warnings_logged.text
    moved = {**truth, "beta": truth["beta"] * (1.0 + 1e-6)}
    warnings_logged.clear()
    assert run_posterior(gauss, moved, seed=7, checkpoint_path=checkpoint, **FAST).resumed_from == 0
    assert "(differs in: optimum)" in warnings_logged.text
