"""The result of a posterior run: samples in declared units, summaries, identifiability, predictive bands.

Intervals are percentiles of the samples after burn-in and thinning.  A parameter is flagged "not determined by
these data" when its 95 % interval spans more than :data:`WIDE_FRACTION` of the prior range, when the samples
pile up at a bound, or when the optimum lies at one.  Because the linear coefficients are profiled out (re-solved
at every sample, :mod:`clothlab.fit.posterior.likelihood`), intervals are conditional on the best coefficients
at each point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clothlab.fit.optimize import BOUND_TOLERANCE
from clothlab.fit.posterior.likelihood import NOISE_RANGE, PRIOR_TEXT

WIDE_FRACTION = 0.5
"""A 95 % interval covering more than this fraction of the prior (unit-box) range: not determined."""

PILE_MARGIN, PILE_FRACTION = 0.01, 0.10
"""More than PILE_FRACTION of the samples within PILE_MARGIN of the range from a bound: piles up at it."""


@dataclass(repr=False)
class PosteriorResult:
    """Posterior samples (after burn-in and thinning) and their summaries.

    ``samples`` (M, D) in declared units, ``unit_samples`` the same in unit-box coordinates; ``chain`` (steps,
    walkers, D) and ``log_prob`` the full chain in unit coordinates; ``tau`` (D,) integrated autocorrelation
    times [steps]; ``acceptance`` (walkers,) acceptance fractions.
    """

    problem: object
    names: list
    units: list
    samples: np.ndarray
    unit_samples: np.ndarray
    chain: np.ndarray
    log_prob: np.ndarray
    tau: np.ndarray
    acceptance: np.ndarray
    burn_in: int
    thin: int
    converged: bool
    steps: int
    walkers: int
    wall_time: float
    seed: int
    noise: str
    likelihood: str
    optimum: dict
    optimum_unit: np.ndarray
    min_steps: int
    max_steps: int
    tol_factor: float
    check_every: int
    stop_reason: str | None
    resumed_from: int
    moves: str = "emcee default (stretch move, a = 2)"
    warnings: list = field(default_factory=list)
    _like: object = None
    convergence_rule: str = ""
    start: str = "ball"  # the walkers' start: "laplace" (the Laplace approximation) or "ball"

    def __repr__(self) -> str:
        state = "converged" if self.converged else f"not converged ({self.stop_reason})"
        return (f"<PosteriorResult {len(self.names)} sampled ({', '.join(self.names)}): {self.walkers} walkers x "
                f"{self.steps} steps, {state}, {len(self.samples)} samples>")

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per coordinate: walkers x (steps - burn-in) / tau."""
        return self.walkers * (self.steps - self.burn_in) / self.tau

    def percentiles(self) -> dict:
        """name -> {median, p16, p84, p2.5, p97.5} in declared units."""
        q = np.percentile(self.samples, [50, 16, 84, 2.5, 97.5], axis=0)
        return {name: dict(zip(("median", "p16", "p84", "p2.5", "p97.5"), map(float, q[:, j]), strict=True))
                for j, name in enumerate(self.names)}

    def correlation(self) -> np.ndarray:
        """(D, D) correlation of the sampled coordinates (linear in the transform: log for log-scaled)."""
        return np.corrcoef(self.unit_samples, rowvar=False).reshape(len(self.names), len(self.names))

    def identifiability(self) -> dict:
        """name -> list of reasons it is "not determined by these data" (empty when it is determined).

        Reasons: the 95 % interval covers more than WIDE_FRACTION of the prior range (unit-box coordinates);
        more than PILE_FRACTION of the samples lie within PILE_MARGIN of the range from a bound; the optimum
        lies at a bound (within BOUND_TOLERANCE of the range, as the optimiser flags it).
        """
        u = self.unit_samples
        lo95, hi95 = np.percentile(u, [2.5, 97.5], axis=0)
        out = {}
        for j, name in enumerate(self.names):
            reasons = []
            if hi95[j] - lo95[j] > WIDE_FRACTION:
                reasons.append(f"95 % interval spans {100 * (hi95[j] - lo95[j]):.0f} % of the allowed range")
            for side, near in (("lower", u[:, j] < PILE_MARGIN), ("upper", u[:, j] > 1.0 - PILE_MARGIN)):
                if np.mean(near) > PILE_FRACTION:
                    reasons.append(f"posterior piles up at the {side} bound ({100 * np.mean(near):.0f} % of "
                                   f"samples within {100 * PILE_MARGIN:g} % of the range)")
            x = self.optimum_unit[j]
            if j < len(self.problem.free) and (x <= BOUND_TOLERANCE or x >= 1.0 - BOUND_TOLERANCE):
                reasons.append(f"optimum at the {'lower' if x <= BOUND_TOLERANCE else 'upper'} bound")
            out[name] = reasons
        return out

    def not_determined(self) -> list:
        return [name for name, reasons in self.identifiability().items() if reasons]

    def _bounds(self, j: int) -> tuple[float, float]:
        if j < len(self.problem.free):
            return float(self.problem.lower[j]), float(self.problem.upper[j])
        return NOISE_RANGE

    def predictive_bands(self, wi, wo, *, draws: int = 200, percentiles=(5, 50, 95), seed: int = 0) -> dict:
        """Posterior-predictive bands of the model (noise excluded) at directions (wi, wo) (M, 3) each.

        ``draws`` posterior samples (drawn with ``seed``) are evaluated, each with its profiled coefficients;
        returns {"p5": (M, C), "p50": ..., "p95": ...} in 1/sr and "draws".
        """
        rng = np.random.default_rng(seed)
        pick = rng.choice(len(self.unit_samples), size=min(draws, len(self.unit_samples)), replace=False)
        params = [self.problem.from_unit(x[:len(self.problem.free)]) for x in self.unit_samples[pick]]
        wi, wo = np.atleast_2d(wi), np.atleast_2d(wo)
        if wi.shape != wo.shape or wi.shape[1] != 3:
            raise ValueError(f"wi and wo must both have shape (M, 3), got {wi.shape} and {wo.shape}")
        values = []
        for start in range(0, len(params), 32):
            values.append(self._like.solve_many(params[start:start + 32], wi, wo)[1])
        q = np.percentile(np.concatenate(values), percentiles, axis=0)
        out = {f"p{p:g}": q[i] for i, p in enumerate(percentiles)}
        out["draws"] = len(params)
        return out

    def to_json(self) -> dict:
        """JSON-ready summary (posterior.json)."""
        pct = self.percentiles()
        ident = self.identifiability()
        truth = (self.problem.measurement.provenance or {}).get("parameters", {}) \
            if (self.problem.measurement.provenance or {}).get("simulated") else {}
        params = {}
        for j, name in enumerate(self.names):
            lo, hi = self._bounds(j)
            entry = {"unit": self.units[j], **pct[name], "lower": lo, "upper": hi,
                     "optimum": float(self.optimum[name]) if name in self.optimum
                     else float(self._like.noise_scale(self.optimum_unit[j])),
                     "tau": float(self.tau[j]), "ess": float(self.ess[j]),
                     "determined": not ident[name], "reasons": ident[name]}
            if name in truth:
                entry["truth"] = float(truth[name])
                entry["truth_in_95"] = bool(pct[name]["p2.5"] <= truth[name] <= pct[name]["p97.5"])
            params[name] = entry
        corr = self.correlation()
        warn = list(self.warnings)
        for name, reasons in ident.items():
            if reasons:
                warn.append(f"{name}: not determined by these data ({'; '.join(reasons)})")
        return {
            "method": "emcee EnsembleSampler (vectorised log-probability)",
            "moves": self.moves,
            "start": self.start,
            "prior": PRIOR_TEXT,
            "likelihood": self.likelihood,
            "noise_model": self.noise,
            "coefficients": ("profiled out: kd, ks re-solved by weighted NNLS at every sample (not sampled); "
                             "intervals are conditional on the best coefficients at each point"),
            "parameters": params,
            "correlation": {"names": list(self.names), "matrix": _finite(corr),
                            "coordinates": "sampled (unit-box) coordinates: log for log-scaled parameters"},
            "not_determined": [n for n, r in ident.items() if r],
            "identifiability_rule": (f"not determined by these data: 95 % interval wider than {WIDE_FRACTION:.0%} "
                                     f"of the prior range (unit-box coordinates), or > {PILE_FRACTION:.0%} of samples "
                                     f"within {PILE_MARGIN:.0%} of the range from a bound, or optimum at a bound"),
            "convergence": {
                "converged": self.converged, "stop_reason": self.stop_reason,
                "rule": self.convergence_rule,
                "steps": self.steps, "walkers": self.walkers, "burn_in": self.burn_in, "thin": self.thin,
                "samples": int(len(self.samples)), "tau": dict(zip(self.names, map(float, self.tau), strict=True)),
                "ess": dict(zip(self.names, map(float, self.ess), strict=True)),
                "acceptance_fraction": {"mean": float(np.mean(self.acceptance)),
                                        "min": float(np.min(self.acceptance)),
                                        "max": float(np.max(self.acceptance))},
                "resumed_from_step": self.resumed_from,
            },
            "seed": self.seed,
            "wall_time_s": self.wall_time,
            "wall_time_note": "sampling seconds summed over all sessions of a resumed run",
            "warnings": warn,
        }

    def corner_figure(self, truths=None):
        """Corner plot (corner.corner) of the samples in declared units; truths default to the generating
        values of simulated data, if recorded."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import corner

        if truths is None:
            prov = self.problem.measurement.provenance or {}
            known = prov.get("parameters", {}) if prov.get("simulated") else {}
            truths = [known.get(n) for n in self.names] if any(n in known for n in self.names) else None
        labels = [f"{n} [{u}]" if u and not u.startswith("1 ") else n for n, u in zip(self.names, self.units,
                                                                                      strict=True)]
        return corner.corner(self.samples, labels=labels, truths=truths, quantiles=[0.16, 0.5, 0.84],
                             show_titles=True, title_fmt=".3g")


def _finite(matrix: np.ndarray) -> list:
    return [[float(v) if math.isfinite(v) else None for v in row] for row in np.asarray(matrix)]
