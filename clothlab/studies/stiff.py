"""Stiff fits (part of ``clothlab check --full``): ill-conditioned IM fits, recovery of the truth and Jacobian
conditioning.

Cases: silk charmeuse (beta 7.3, kappa 2), polyester lining (filament, kappa -0.7),
a very narrow highlight (cotton-denim geometry with umax 2 deg on both yarns, beta 50) and a weak weft
under a strong warp (cotton-denim with ks_weft = ks_warp / 20).  For each: noisy data are simulated
(:func:`clothlab.simulate.gonio.simulate`, the examples' noise: 5 % log-normal + 2e-4 1/sr), then fitted with the
examples' free parameters (:func:`clothlab.simulate.examples.free_parameters`) from the default start
(:data:`clothlab.simulate.examples.START`) with the default optimiser (GN_CRS2_LM + LN_BOBYQA) and from perturbed
starts with the local polish alone (LN_BOBYQA).  At the best optimum: the Jacobian of the relative residuals
(coefficients re-solved by NNLS at every point, as in the objective) by central finite differences in the unit
box, its condition number (ratio of extreme singular values), and the nearly dependent parameter groups
(pairs whose Jacobian columns have |cosine| > COLLINEAR_COSINE, and the parameters carrying the smallest
singular vector).  Posterior correlations: a short emcee run (:func:`clothlab.fit.posterior.run_posterior`,
Gaussian likelihood with the simulated sigma, walkers started at the best optimum, a fixed step budget, checkpoint
in a temporary directory) gives the correlation matrix of the free parameters (in the sampled unit-box
coordinates) and the most strongly correlated pairs; ``fast`` settings (:data:`FAST_POSTERIOR`) for tests.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from clothlab.errors import GeometryWarning

COLLINEAR_COSINE = 0.99
FD_STEP = 1e-4  # unit-box step of the finite differences
NOISE = {"multiplicative": 0.05, "additive": 2e-4}
POSTERIOR = {"walkers": 32, "steps": 1000, "max_steps": 1000, "check_every": 100}
"""The stiff cases' posterior: 32 walkers, 1,000 steps (a fixed budget, ~40 s a case; not run to the tau rule)."""
FAST_POSTERIOR = {"walkers": 12, "steps": 60, "max_steps": 60, "check_every": 20}
STRONG_CORRELATION = 0.7
"""Pairs with |posterior correlation| above this are listed as strongly correlated (the 3 strongest always)."""


def stiff_cases() -> list[dict]:
    """The stiff problems: preset, parameter changes, coefficients (albedos, R G B)."""
    from clothlab.simulate.examples import YARN_COLOURS

    denim = YARN_COLOURS["cotton-denim"]
    return [
        {"name": "silk charmeuse (beta 7.3, kappa 2)", "preset": "silk-charmeuse", "changes": {},
         "coefficients": YARN_COLOURS["silk-charmeuse"]},
        {"name": "polyester lining (filament, kappa -0.7)", "preset": "polyester-lining", "changes": {},
         "coefficients": YARN_COLOURS["polyester-lining"]},
        {"name": "narrow highlight (umax 2 deg, beta 50)", "preset": "cotton-denim",
         "changes": {"warp.umax": 2.0, "weft.umax": 2.0, "beta": 50.0}, "coefficients": denim},
        {"name": "weak weft (ks_weft = ks_warp / 20)", "preset": "cotton-denim", "changes": {},
         "coefficients": {**denim, "ks_weft": tuple(v / 20.0 for v in denim["ks_warp"])}},
    ]


def residuals(problem, x) -> np.ndarray:
    """Relative residuals (all values, all channels) at unit-box point ``x`` (coefficients by NNLS)."""
    from clothlab.fit.metrics import metric_residuals

    solution = problem.solve(problem.from_unit(x))
    return np.ravel(metric_residuals(problem.y, solution.prediction, problem.metric))


def jacobian(problem, x, step: float = FD_STEP) -> np.ndarray:
    """(n_residuals, k) central differences in the unit box (one-sided at a bound)."""
    r0 = residuals(problem, x)
    cols = []
    for i in range(len(x)):
        lo, hi = x.copy(), x.copy()
        lo[i] = max(x[i] - step, 0.0)
        hi[i] = min(x[i] + step, 1.0)
        r_hi = residuals(problem, hi) if hi[i] != x[i] else r0
        r_lo = residuals(problem, lo) if lo[i] != x[i] else r0
        cols.append((r_hi - r_lo) / (hi[i] - lo[i]))
    return np.stack(cols, axis=1)


def conditioning(jac: np.ndarray, names) -> dict:
    """Condition number, singular values, collinear column pairs and the smallest singular vector."""
    s, vt = np.linalg.svd(jac, full_matrices=False)[1:]
    norms = np.linalg.norm(jac, axis=0)
    unit = jac / np.where(norms > 0, norms, 1.0)
    cosine = unit.T @ unit
    pairs = [(names[i], names[j], float(cosine[i, j])) for i in range(len(names)) for j in range(i + 1, len(names))
             if abs(cosine[i, j]) > COLLINEAR_COSINE]
    weakest = vt[-1]
    carrying = [names[i] for i in np.argsort(-np.abs(weakest)) if abs(weakest[i]) > 0.3]
    return {"condition": float(s[0] / s[-1]) if s[-1] > 0 else float("inf"), "singular_values": s.tolist(),
            "zero_columns": [n for n, v in zip(names, norms, strict=True) if v == 0.0],
            "collinear_pairs": pairs, "weakest_direction": dict(zip(names, weakest.tolist(), strict=True)),
            "weakest_parameters": carrying}


def _fit(problem, x0, global_algorithm, max_evals, seed):
    from clothlab.fit.optimize import minimize

    k = len(problem.free)
    return minimize(problem, x0, np.zeros(k), np.ones(k), global_algorithm=global_algorithm,
                    local_algorithm="LN_BOBYQA", max_evals=max_evals, seed=seed)


def run_case(case: dict, *, seed: int = 0, perturbed: int = 3, max_evals: int = 3000, posterior=None) -> dict:
    """Simulate, fit from the default and ``perturbed`` starts, condition the best optimum and sample a short
    posterior there (``posterior``: run_posterior settings, default :data:`POSTERIOR`)."""
    from clothlab.fit.problem import FitProblem
    from clothlab.models.irawan.model import IrawanModel
    from clothlab.simulate.examples import START, free_parameters
    from clothlab.simulate.gonio import NoiseModel, simulate
    from clothlab.weave.presets import get_preset

    started = time.perf_counter()
    model = IrawanModel(get_preset(case["preset"]))
    truth = model.resolve(case["changes"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        data = simulate(model, truth, case["coefficients"], noise=NoiseModel(**NOISE, seed=seed + 17))
    free = free_parameters(case["preset"])
    start = {**truth, **{k: START[k] for k in free}}
    problem = FitProblem(model, data, free, start)
    x_truth = problem.to_unit(truth)
    truth_objective = problem(x_truth)
    x_default = problem.to_unit(start)
    rng = np.random.default_rng(seed)
    starts = [("default (global + local)", x_default, "GN_CRS2_LM")]
    for i in range(perturbed):
        starts.append((f"perturbed {i + 1} (local)", np.clip(x_truth + rng.uniform(-0.15, 0.15, len(free)),
                                                            0.0, 1.0), None))
    fits = []
    for label, x0, global_algorithm in starts:
        result = _fit(problem, x0, global_algorithm, max_evals if global_algorithm else max_evals // 2, seed + 1)
        params = problem.from_unit(result.x)
        unit_error = np.abs(result.x - x_truth)
        fits.append({"start": label, "objective": float(result.fun), "evaluations": int(result.nevals),
                     "errors": {n: float(params[n] - truth[n]) for n in free},
                     "unit_errors": dict(zip(free, unit_error.tolist(), strict=True)),
                     "recovered": bool(unit_error.max() < 0.02), "x": result.x.tolist()})
    best = min(fits, key=lambda f: f["objective"])
    jac = jacobian(problem, np.asarray(best["x"]))
    at_truth = conditioning(jacobian(problem, x_truth), list(free))
    posterior = posterior_correlations(problem, problem.from_unit(np.asarray(best["x"])), seed=seed,
                                       **(posterior or POSTERIOR))
    return {"name": case["name"], "preset": case["preset"], "changes": case["changes"], "free": list(free),
            "truth": {n: truth[n] for n in free}, "truth_objective": float(truth_objective), "fits": fits,
            "best_start": best["start"], **conditioning(jac, list(free)),
            "at_truth": {k: at_truth[k] for k in ("condition", "collinear_pairs", "weakest_parameters")},
            "recovered_default": fits[0]["recovered"],
            "recovered_perturbed": [f["recovered"] for f in fits[1:]],
            "posterior": posterior, "strongest_correlations": posterior["strongest_text"],
            "wall_time_s": time.perf_counter() - started}


def posterior_correlations(problem, optimum: dict, *, seed: int, walkers: int, steps: int, max_steps: int,
                           check_every: int) -> dict:
    """A short emcee posterior at ``optimum`` (checkpoint in a temporary directory, removed afterwards): the
    correlation matrix of the sampled coordinates, the strongly correlated pairs (|r| > STRONG_CORRELATION, at
    least the 3 strongest) and the run's summary (steps, walkers, tau, acceptance, convergence)."""
    import tempfile
    from pathlib import Path

    from clothlab.fit.posterior import run_posterior

    with tempfile.TemporaryDirectory(prefix="clothlab-stiff-") as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", GeometryWarning)
        post = run_posterior(problem, optimum, walkers=walkers, steps=steps, max_steps=max_steps, seed=seed + 3,
                             check_every=check_every, checkpoint_path=Path(tmp) / "checkpoint.npz", progress=False)
    names = list(post.names)
    corr = post.correlation()
    corr = 0.5 * (corr + corr.T)  # exactly symmetric
    np.fill_diagonal(corr, 1.0)
    corr = np.clip(corr, -1.0, 1.0)
    pairs = sorted(((names[i], names[j], float(corr[i, j])) for i in range(len(names))
                    for j in range(i + 1, len(names))), key=lambda p: -abs(p[2]))
    strong = [p for k, p in enumerate(pairs) if abs(p[2]) > STRONG_CORRELATION or k < 3]
    pct = post.percentiles()
    return {"names": names, "correlation": corr.tolist(),
            "strongest_pairs": [{"a": a, "b": b, "r": r} for a, b, r in strong],
            "strongest_text": "; ".join(f"{a}/{b} {r:+.2f}" for a, b, r in strong),
            "intervals_95": {n: [pct[n]["p2.5"], pct[n]["p97.5"]] for n in names},
            "not_determined": post.not_determined(), "steps": post.steps, "walkers": post.walkers,
            "converged": bool(post.converged), "max_tau": float(np.max(post.tau)),
            "acceptance_mean": float(np.mean(post.acceptance)), "wall_time_s": post.wall_time,
            "coordinates": "sampled (unit-box) coordinates: log for log-scaled parameters"}


def run_stiff(seed: int = 0, *, perturbed: int = 3, max_evals: int = 3000, cases=None, figures_dir=None,
              fast: bool = False) -> dict:
    """Run every stiff case; returns {"cases": [...]} (``figures_dir`` is accepted for symmetry, unused).
    ``fast``: the short posterior of :data:`FAST_POSTERIOR` (tests)."""
    del figures_dir
    cases = cases or stiff_cases()
    posterior = FAST_POSTERIOR if fast else POSTERIOR
    return {"seed": seed, "max_evals": max_evals, "posterior_settings": dict(posterior),
            "cases": [run_case(c, seed=seed, perturbed=perturbed, max_evals=max_evals, posterior=posterior)
                      for c in cases]}


def stiff_lines(result: dict) -> list[str]:
    """The human-readable lines of a :func:`run_stiff` result."""
    out = ["", f"== stiff fits (noisy simulated data, seed {result['seed']}; recovered = every free parameter "
           "within 2 % of its box range) =="]
    for case in result["cases"]:
        pairs = ", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in case["collinear_pairs"]) or "none"
        out += ["", f"  {case['name']}: condition number of the residual Jacobian (unit box) {case['condition']:.3g} "
                f"(at the truth {case['at_truth']['condition']:.3g}); objective at the truth "
                f"{case['truth_objective']:.4e}",
                f"    weakest direction carried by: {', '.join(case['weakest_parameters']) or '-'}; collinear pairs "
                f"(|cos| > {COLLINEAR_COSINE}): {pairs}"]
        if case["zero_columns"]:
            out.append(f"    parameters with no effect at the optimum: {', '.join(case['zero_columns'])}")
        post = case["posterior"]
        out.append(f"    posterior ({post['walkers']} walkers x {post['steps']} steps, max tau {post['max_tau']:.0f}, "
                   f"{'converged' if post['converged'] else 'not converged by the tau rule'}): strongest correlations "
                   f"{post['strongest_text'] or '-'}; not determined: {', '.join(post['not_determined']) or 'none'}")
        free = case["free"]
        out.append(f"    {'start':26s} {'objective':>11s} {'ok':>3s} " + " ".join(f"{n:>11s}" for n in free))
        out.append(f"    {'truth':26s} {'':11s} {'':3s} " + " ".join(f"{case['truth'][n]:11.4g}" for n in free))
        for f in case["fits"]:
            out.append(f"    {f['start']:26s} {f['objective']:11.4e} {'yes' if f['recovered'] else 'no':>3s} "
                       + " ".join(f"{f['errors'][n]:+11.3g}" for n in free))
    return out
