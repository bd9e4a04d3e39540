"""Fitting: recovery of the generating parameters from the simulated paper-fabric sets, noise-level errors,
the objective's building blocks, and the saved fit directory."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from clothlab.config import load_config
from clothlab.fit.metrics import error_percentiles
from clothlab.fit.runner import build_problem, run_fit, save_fit

ROOT = Path(__file__).resolve().parents[1]
MEASUREMENTS = ROOT / "measurements"
FABRICS = ("cotton-denim", "silk-shantung", "silk-charmeuse", "cotton-twill", "wool-gabardine", "polyester-lining")

# Tolerances of the recovery test (umax within 1 deg, psi within 2 deg, beta within 5 %).
TOLERANCE = {"umax": 1.0, "psi": 2.0, "kappa": 0.1, "alpha": 0.1, "beta": 0.05}
# The cotton-twill weft violates the segment constraint of sec. 5.3 (2 sin 36 deg > 1): its spine is the
# degenerate R = 0 limit and its specular is weak (ks 0.02 under a 0.05 warp); its umax is determined only to
# a few degrees by 1,575 directions (measured: 34.2 deg for 36 with 4 x 1,500 evaluations, 36.9 with 8 x 750).
LOOSER = {("cotton-twill", "weft.umax"): 3.0}


def _close(fabric, name, fitted, truth):
    kind = name.split(".")[-1]
    tol = LOOSER.get((fabric, name), TOLERANCE[kind])
    if kind in ("alpha", "beta"):
        return abs(fitted - truth) <= tol * abs(truth)
    return abs(fitted - truth) <= tol


def _config(fabric, variant="clean", **optimizer):
    cfg = load_config(MEASUREMENTS / fabric / ("fabric-clean.yaml" if variant == "clean" else "fabric.yaml"))
    cfg = replace(cfg, fit=replace(cfg.fit, cv_folds=0, posterior=None))  # CV and posteriors are tested apart
    if optimizer:
        cfg = replace(cfg, fit=replace(cfg.fit, optimizer=replace(cfg.fit.optimizer, **optimizer)))
    return cfg


def test_truth_is_a_zero_of_the_objective():
    """At the generating parameters the noise-free data are reproduced exactly (coefficients via NNLS)."""
    for fabric in FABRICS:
        problem = build_problem(_config(fabric))
        truth = problem.measurement.provenance["parameters"]
        solution = problem.solve({k: truth[k] for k in problem.start})
        assert solution.objective < 1e-20, fabric


@pytest.mark.parametrize("fabric", ["polyester-lining", "wool-gabardine"])
def test_recovery_fast(fabric):
    """Default start (the declarations' generic values, not the truth) -> generating parameters."""
    result = run_fit(_config(fabric, max_evals=2000, starts=2))
    truth = result.problem.measurement.provenance["parameters"]
    for name in result.problem.free:
        assert _close(fabric, name, result.params[name], truth[name]), (name, result.params[name], truth[name])
    assert result.errors["overall"]["p50"] < 0.01


@pytest.mark.slow
@pytest.mark.parametrize("fabric", FABRICS)
def test_recovery_all_six(fabric):
    """The full recovery study: each noise-free set, its shipped fabric-clean.yaml, default start."""
    result = run_fit(_config(fabric))
    truth = result.problem.measurement.provenance["parameters"]
    colours = result.problem.measurement.provenance["coefficients"]
    for name in result.problem.free:
        assert _close(fabric, name, result.params[name], truth[name]), (name, result.params[name], truth[name])
    assert result.errors["overall"]["p50"] < 0.01
    for name, expected in colours.items():
        np.testing.assert_allclose(result.coefficients[name], expected, rtol=0.1, atol=2e-3)


def test_noisy_fit_error_matches_the_noise_level():
    """On the noisy set the fitted model is as close to the data as the generating model is (noise level)."""
    fabric = "polyester-lining"
    result = run_fit(_config(fabric, "noisy", max_evals=2000, starts=2))
    noisy = result.problem.measurement
    clean = build_problem(_config(fabric)).measurement
    noise_level = error_percentiles(noisy.values, clean.values)["overall"]["p50"]
    fitted = result.errors["overall"]["p50"]
    # 5 % log-normal noise: median |relative error| ~ 0.6745 * 0.05 = 3.4 % (+ the additive part).
    assert 0.025 < noise_level < 0.06
    assert 0.9 * noise_level <= fitted <= 1.05 * noise_level


def test_coefficients_are_albedos_of_the_generator():
    fabric = "silk-charmeuse"
    problem = build_problem(_config(fabric))
    truth = problem.measurement.provenance["parameters"]
    solution = problem.solve({k: truth[k] for k in problem.start}, normalised=True)
    colours = problem.measurement.provenance["coefficients"]
    for i, name in enumerate(("kd", "ks_warp", "ks_weft")):
        np.testing.assert_allclose(solution.coefficients[i], colours[name], rtol=1e-9)


def test_unit_box_round_trip():
    problem = build_problem(_config("cotton-denim"))
    x = np.array([0.1, 0.9, 0.5, 0.0, 1.0, 0.37])
    np.testing.assert_allclose(problem.to_unit(problem.from_unit(x)), x, atol=1e-12)
    beta = problem.from_unit(x)["beta"]
    lo, hi = problem.model.params["beta"].bounds
    assert beta == pytest.approx(math.exp(math.log(lo) + 0.37 * (math.log(hi) - math.log(lo))))


def test_saved_fit_directory(tmp_path):
    cfg = replace(_config("polyester-lining", max_evals=300, starts=1), output=replace(
        load_config(MEASUREMENTS / "polyester-lining" / "fabric.yaml").output, fits=tmp_path))
    result = run_fit(cfg)
    out = save_fit(result)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["fabric.yaml", "fit.json", "predictions.csv", "slices.csv", "trace.csv", "weave.wv"]
    fit = json.loads((out / "fit.json").read_text())
    for key in ("parameters", "coefficients", "errors", "evaluations", "wall_time_s", "seed", "versions",
                "config_hash"):
        assert key in fit
    assert fit["parameters"]["warp.umax"]["truth"] == 22.0
    assert fit["parameters"]["warp.umax"]["free"] and not fit["parameters"]["warp.l"]["free"]
    assert fit["evaluations"] == result.optimum.nevals
    # the stages are timed apart: the optimisation alone is what the comparison table shows as fit time
    assert 0.0 < fit["timings"]["optimisation_s"] <= fit["timings"]["total_s"] == fit["wall_time_s"]
    assert fit["model"] == {"kind": "irawan", "weave": "preset:polyester-lining",
                            "quadrature": {"rule": "trapezoid", "nodes": 11}, "options": {"filament_arc": "full"}}
    # an existing result is not overwritten without force, and stays intact
    before = (out / "fit.json").read_bytes()
    from clothlab.errors import ResultExistsError

    with pytest.raises(ResultExistsError):
        save_fit(result)
    assert (out / "fit.json").read_bytes() == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_polish_restarts_a_stopped_local_search_and_never_ends_worse():
    from clothlab.fit.optimize import minimize
    from clothlab.fit.runner import polish

    cfg = _config("cotton-denim", variant="noisy", polish=800)
    problem = build_problem(cfg)
    k = len(problem.free)
    stopped = minimize(problem, problem.to_unit(problem.start), np.zeros(k), np.ones(k), global_algorithm=None,
                       local_algorithm="LN_BOBYQA", max_evals=60, seed=1)
    polished = polish(problem, stopped, cfg.fit.optimizer)
    assert polished.fun < stopped.fun * 0.9  # a 60-evaluation BOBYQA run is far from the optimum
    assert polished.fun == pytest.approx(problem(polished.x), rel=1e-12)  # the point reported is the one scored
    assert stopped.nevals < polished.nevals <= stopped.nevals + 800
    stages = [row.stage for row in polished.trace]
    assert stages[:stopped.nevals] == ["local"] * stopped.nevals and set(stages[stopped.nevals:]) == {"polish"}
    assert [row.index for row in polished.trace] == list(range(1, polished.nevals + 1))
    # from an optimum the polish ends at once and keeps it
    again = polish(problem, polished, replace(cfg.fit.optimizer, polish=300))
    assert again.fun <= polished.fun
    assert polish(problem, stopped, replace(cfg.fit.optimizer, polish=0)) is stopped


def test_no_free_parameters_fits_the_linear_coefficients_only(tmp_path):
    """``fit.free: []``: one NNLS solve of the coefficients (no optimiser), cross-validation re-solves them per
    fold, a requested posterior is skipped with a note, and the fit directory is written and read back."""
    from scipy.optimize import nnls

    from clothlab.config import PosteriorConfig
    from clothlab.fit.store import load_fit

    base = _config("silk-charmeuse", "noisy")
    cfg = replace(base, fit=replace(base.fit, free=(), bounds={}, cv_folds=2),
                  output=replace(base.output, fits=tmp_path))
    result = run_fit(cfg, posterior=PosteriorConfig(walkers=8, steps=10, max_steps=10))
    problem = result.problem
    assert problem.free == () and result.params == problem.start
    assert result.optimum.nevals == 1 and [row.stage for row in result.optimum.trace] == ["nnls"]
    assert result.optimum.algorithms == {"global": None, "local": None, "mlsl_local": None}
    # the coefficients are the relative-error NNLS solution (weights 1 / measured), channel by channel (scipy)
    design, y = problem.design(problem.start, normalised=True), problem.y
    for c, channel in enumerate(problem.measurement.channels):
        expected, _ = nnls(design / y[:, [c]], np.ones(len(y)))
        for i, name in enumerate(("kd", "ks_warp", "ks_weft")):
            assert result.coefficients[name][c] == pytest.approx(expected[i], rel=1e-8, abs=1e-12), channel
    prediction = design @ np.stack([result.coefficients[n] for n in ("kd", "ks_warp", "ks_weft")])
    assert result.errors == error_percentiles(y, prediction, cfg.report.percentiles, problem.measurement.channels)
    assert result.posterior is None and any("nothing to sample" in w for w in result.warnings)
    assert result.uncertainty["stderr"] == {} and result.uncertainty["names"] == []
    cv = result.cross_validation
    assert [f["evaluations"] for f in cv["folds"]] == [1, 1] and "no free parameter" in cv["refit"]
    out = save_fit(result)
    fit = json.loads((out / "fit.json").read_text())
    assert not any(entry["free"] for entry in fit["parameters"].values())
    assert (out / "trace.csv").read_text().splitlines()[1].endswith(",nnls")
    assert not (out / "posterior.json").exists()
    report = load_fit(out).fit_report()
    assert report == result.fit_report()
    assert "free parameters   0, and 9 linear coefficients" in report and "nothing to sample" in report


def test_config_accepts_an_empty_free_list(tmp_path):
    """fabric.yaml may name no free parameter (the coefficients-only fit above)."""
    from clothlab.config import load_config as load

    text = (MEASUREMENTS / "polyester-lining" / "fabric.yaml").read_text()
    lines = [line for line in text.splitlines() if not line.strip().startswith("posterior:")]
    lines = [("  free: []" if line.strip().startswith("free:") else line) for line in lines]
    path = tmp_path / "fabric.yaml"
    path.write_text("\n".join(lines).replace("path: noisy.csv",
                                             f"path: {MEASUREMENTS / 'polyester-lining' / 'noisy.csv'}") + "\n")
    assert load(path).fit.free == ()


def test_relative_objective_from_the_nnls_residuals_equals_the_metric_path():
    """The relative-metric objective taken from the NNLS residual norms equals mean(((m - y) / y)^2) of the
    prediction (the scalar path: per-set quadrature loops, QR NNLS, metric residuals), at random points."""
    from clothlab.studies.scalar_path import scalar_objective

    problem = build_problem(load_config(ROOT / "measurements" / "cotton-denim" / "fabric.yaml"))
    rng = np.random.default_rng(2)
    values = []
    for x in rng.uniform(size=(4, len(problem.free))):
        value = problem(x)
        assert value == pytest.approx(scalar_objective(problem, x), rel=1e-12)
        assert value == pytest.approx(problem.solve(problem.from_unit(x)).objective, rel=1e-12)
        values.append(value)
    assert len(set(values)) == 4


def test_bench_before_after_figures_side_by_side():
    """The fit section's before/after figures (objective per evaluation, one short fit by each path) and the
    posterior section's log-probability paths on the same walkers, with agreeing values."""
    from clothlab.studies import full_fit
    from clothlab.studies.data import StudyData
    from clothlab.studies.posterior import likelihood_paths

    b = full_fit.before_after(True, data=StudyData(ROOT), repeats=5, max_evals=60)
    assert b["objective_s"]["scalar"] > 0 and b["objective_s"]["batched"] > 0 and b["objective_ratio"] > 0
    assert b["fits"]["scalar"]["evaluations"] > 0 and math.isfinite(b["fits"]["batched"]["objective"])
    assert "ratio" in full_fit._before_after_lines(b)[0]
    problem = build_problem(load_config(ROOT / "measurements" / "polyester-lining" / "fabric.yaml"))
    x = problem.to_unit(problem.start)
    paths = likelihood_paths(problem, np.clip(x + 1e-3 * np.random.default_rng(0).standard_normal((20, 6)), 0, 1),
                             repeats=1)
    assert paths["walkers"] == 20 and paths["max_relative_difference"] < 1e-12 and paths["ratio"] > 0
